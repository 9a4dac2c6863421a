"""facette._data: the packaged target specifications, the committed simulated-rig profile and the
report viewer's script."""
from facette._data import package_text, sim_profile_dir, targets_dir
from facette.calib import load
from facette.calib.targets import load_target


def test_targets_and_the_sim_profile_are_found_through_the_package():
    assert {p.stem for p in targets_dir().glob("*.json")} >= {"spectralon-99", "mirror-sphere", "matte-sphere"}
    assert load_target("spectralon-99")["kind"]
    prof = load(sim_profile_dir())
    assert prof.rig == "sim-default" and len(prof.lights) == 12


def test_the_viewer_script_ships_beside_the_pipeline():
    js = package_text("facette.pipeline", "viewer.js")
    assert "webgl2" in js and "facetteViewer" in js
