"""facette._data: the packaged target specifications and the committed simulated-rig profile."""
from facette._data import sim_profile_dir, targets_dir
from facette.calib import load
from facette.calib.targets import load_target


def test_targets_and_the_sim_profile_are_found_through_the_package():
    assert {p.stem for p in targets_dir().glob("*.json")} >= {"spectralon-99", "mirror-sphere", "matte-sphere"}
    assert load_target("spectralon-99")["kind"]
    prof = load(sim_profile_dir())
    assert prof.rig == "sim-default" and len(prof.lights) == 12
