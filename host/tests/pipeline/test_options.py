"""ProcessOptions: one definition of `process`'s options, checked once, recorded from its fields."""
from dataclasses import FrozenInstanceError, replace

import pytest

from facette.errors import BadInputError
from facette.methods import PROCESS_DEFAULT, options_for
from facette.pipeline import ProcessOptions

# process.json's options, the same keys as before ProcessOptions existed (a folder made then is
# still recognised as made with the same options), and "channels" since the normals' channels became a
# choice (the default changed from green to the mean: a folder of green normals is not this run's), and
# "light_gains" since a folder's intensities are corrected from its photographs (other normals again), and
# "ptm_format" since relight.ptm may be written per channel (another file)
RECORDED = ["method", "integration", "channels", "t_ombre", "t_spec", "t_source", "t_residual", "theta0_deg", "rti_encoding",
            "mask",
            "pixel_pitch_mm", "near_light", "mesh_step", "saturation", "fit_options", "ps_options", "hsh_order", "ptm_format",
            "interreflections", "shadows", "light_gains"]


def test_recorded_and_reported_fields_and_defaults():
    o = ProcessOptions()
    assert list(o.recorded()) == RECORDED and o.recorded()["mask"] is None
    assert list(o.reported()) == ["method", "integration", "channels", "t_ombre", "t_spec", "t_source", "t_residual",
                                  "theta0_deg", "rti_encoding", "ptm_format", "interreflections", "shadows", "light_gains"]
    assert o.channels == "mean" and o.interreflections == "auto" and o.light_gains == "auto" and o.shadows == "auto"
    assert o.method == PROCESS_DEFAULT == "li_alternating" and o.fit_options == {} and o.ps_options == {} and o.near_light
    assert replace(o, mask="m.png").recorded()["mask"] == "m.png"       # a path is recorded, an array not
    for name in RECORDED + ["ascii_ply", "allow_incomplete", "overwrite"]:
        assert f"    {name} : " in ProcessOptions.__doc__               # each field's line, from the field


def test_frozen_and_holding_its_own_copies():
    o = ProcessOptions(method="woodham1980")
    with pytest.raises(FrozenInstanceError):
        o.method = "rank_trimmed"
    fit = {"model": "li"}
    held = ProcessOptions(fit_options=fit)
    fit["model"] = "lambert"                                          # the caller's dict, changed later
    assert held.fit_options == {"model": "li"}


def test_every_check_at_construction():
    with pytest.raises(BadInputError, match="mesh_step must be >= 1"):
        ProcessOptions(mesh_step=0)
    with pytest.raises(BadInputError, match="pixel_pitch_mm must be > 0"):
        replace(ProcessOptions(), pixel_pitch_mm=-1.0)                # a variant is checked again
    with pytest.raises(ValueError, match="unknown photometric-stereo method 'magic'"):
        ProcessOptions(method="magic")
    with pytest.raises(ValueError, match="unknown photometric-stereo option.*rondus"):
        ProcessOptions(method="li_alternating", ps_options={"rondus": 2})
    with pytest.raises(ValueError, match="unknown integration method"):
        ProcessOptions(integration="nope")
    with pytest.raises(BadInputError, match="rti_encoding must be one of"):
        ProcessOptions(rti_encoding="gamma")
    with pytest.raises(ValueError, match="hsh_order"):
        ProcessOptions(hsh_order=4)
    with pytest.raises(BadInputError, match="interreflections must be True, False or 'auto', got 'yes'"):
        ProcessOptions(interreflections="yes")
    assert ProcessOptions(interreflections=1).interreflections is True      # a truthy value becomes a bool


def test_every_method_gets_its_own_options_from_the_one_bag():
    # the thresholds reach the hierarchy, and li_alternating's start when it is the hierarchy
    o = ProcessOptions(method="li_alternating", t_ombre=1.2, t_residual=0.05,
                       ps_options={"init": "hierarchical", "rounds": 2})
    kw = options_for(o.method, o.ps_bag())
    assert kw["rounds"] == 2 and kw["t_residual"] == 0.05 and "t_ombre" not in kw
    assert kw["init_options"] == {"t_ombre": 1.2, "t_spec": o.t_spec, "t_source": o.t_source, "t_residual": 0.05}
    assert options_for("hierarchical", o.ps_bag())["t_ombre"] == 1.2
    assert options_for("woodham1980", o.ps_bag(mask="m")) == {"mask": "m"}
