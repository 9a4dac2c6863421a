"""Resolution is part of the calibration: the committed sim profile serves other simulated RAW
sizes (pixel pitch scaled, flat field resampled) and refuses one that is not the same field."""
import pytest

import facette
from facette.calib import ResolutionError
from facette.pipeline import process
from facette.sim.device_process import REPO_ROOT

PROFILE = REPO_ROOT / "calibration" / "profiles" / "sim-default"
EXPOSURES = [(1_000_000, 0), (125_000, 0), (33_333, 0)]


def _scan(tmp_path, raw_shape, name):
    # seed 0: the rig the committed profile was calibrated on (another seed moves the LEDs,
    # which the profile would not know, and the normals come out ~9 deg off)
    with facette.connect("sim", raw_shape=raw_shape, seed=0) as rig:
        truth_pitch = rig.sim.scene.pixel_pitch_mm
        sd = rig.scan(tmp_path / name, profile=PROFILE, exposures=EXPOSURES, progress=False)
    return getattr(sd, "path", tmp_path / name), truth_pitch


def test_heights_stay_right_at_another_raw_size(tmp_path):
    errs = {}
    for raw_shape in ((96, 128), (192, 256)):
        d, pitch = _scan(tmp_path, raw_shape, f"s{raw_shape[1]}")
        res = process(d, outputs=["normals", "height"])
        assert res.inputs.pixel_pitch_mm == pytest.approx(pitch, rel=3e-3)
        errs[raw_shape] = res.errors["height_rms_mm"]
        if raw_shape != (96, 128):
            assert any("pixel pitch scaled" in n for n in res.notes)
            assert any("flat field" in n and "resampled" in n for n in res.notes)
    # the same object in millimetres at both sizes: 0.12 and 0.059 mm measured; with the pitch
    # unscaled the larger scan would be twice as tall (millimetres of error)
    assert max(errs.values()) < 0.2, errs


def test_a_field_the_profile_does_not_cover_is_refused_naming_both_sizes(tmp_path):
    d, _ = _scan(tmp_path, (128, 128), "square")
    with pytest.raises(ResolutionError, match=r"256×192 px.*64×64 px"):
        process(d, outputs=["normals", "height"])
