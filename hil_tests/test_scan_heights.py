"""Heights against the simulator's truth do not depend on the resolution beyond the sampling:
a scan of the same object at two simulated RAW sizes, through the device, the committed
profile and the default processing, gives the same height error in pixel pitches."""
import numpy as np

import facette
from facette.pipeline import process
from facette.sim.device_process import REPO_ROOT

PROFILE = REPO_ROOT / "calibration" / "profiles" / "sim-default"
EXPOSURES = [(1_000_000, 0), (125_000, 0), (33_333, 0)]


def _height_error_pitches(tmp_path, raw_shape):
    # seed 0: the simulated LEDs the committed profile was calibrated on
    with facette.connect("sim", raw_shape=raw_shape, seed=0) as rig:
        sd = rig.scan(tmp_path / f"s{raw_shape[1]}", profile=PROFILE, exposures=EXPOSURES,
                      progress=False)
    res = process(getattr(sd, "path", tmp_path / f"s{raw_shape[1]}"), outputs=["normals", "height"])
    return res.errors["height_rms_mm"] / res.inputs.pixel_pitch_mm


def test_height_error_in_pitches_is_the_same_at_two_raw_sizes(tmp_path):
    # What is left is the aliasing of the fossil's sub-pixel detail, a fixed fraction of a
    # pixel, plus noise and the profile's light errors: 0.063 and 0.050 pitches measured at
    # 256x192 and 512x384 RAW with this bracket (0.056 and 0.053 while the simulated dome's rim
    # shadowed itself; 0.058 and 0.054 before the table's lean was taken from the table alone;
    # 0.062 and 0.070 with the profile measured at
    # 128x96 RAW and Frankot-Chellappa; 0.59 and 0.64 when the simulator's normals were not
    # those of its heights). The bound of 0.1 pitch fails on that; 25 % is twice the 12 % the
    # two sizes once differed by.
    small = _height_error_pitches(tmp_path, (192, 256))
    large = _height_error_pitches(tmp_path, (384, 512))
    assert small < 0.1 and large < 0.1
    assert abs(small - large) < 0.25 * max(small, large), (small, large)
