"""pipeline.ArrivingLights: the one-button scan's lights made into `process`'s inputs as they arrive (the
scan's `on_held`) are the values `process` reads from the files, and a light changed on disk since it
was merged sends the load back to the files."""
import os

import numpy as np
import pytest

import facette
from facette._data import sim_profile_dir
from facette.calib import load
from facette.capture import load_input
from facette.pipeline import ArrivingLights, process
from facette.pipeline._channels import with_solve_channel

MEAN = np.full(3, 1 / 3, np.float32)


@pytest.fixture(scope="module")
def rig():
    r = facette.connect("sim", raw_shape=(96, 128), speed=2000)
    yield r
    r.close()


def _scan(rig, path, arriving):
    return rig.scan(path, profile=load(sim_profile_dir()), exposures=[(200_000, 0), (20_000, 0)], progress=False,
                    merge_hdr=True, hold_hdr=True, on_held=arriving)


def test_the_lights_made_as_they_arrive_are_the_files_values(rig, tmp_path):
    arriving = ArrivingLights()
    sd = _scan(rig, tmp_path / "s", arriving)
    arriving.wait()          # the scan returns as its last light is handed over, not once it is taken
    assert sd.prepared is arriving and sd.held_lights() == []      # every light taken as it came
    inp = load_input(sd)
    ref = load_input(tmp_path / "s")                                 # read from hdr/, as `facette process` does
    assert inp.images is arriving.stack and inp.images.shape == ref.images.shape
    assert np.array_equal(inp.images, ref.images, equal_nan=True)
    assert np.array_equal(inp.usable, ref.usable) and np.array_equal(inp.mask, ref.mask)
    assert inp.notes == ref.notes and inp.pixel_pitch_mm == ref.pixel_pitch_mm
    assert any("flat field" in n for n in inp.notes)                 # the profile's flat field divided out
    assert arriving.solve_stack(ref.images, MEAN, None) is None         # not these images: made again
    arriving = ArrivingLights()
    sd = _scan(rig, tmp_path / "t", arriving)
    inp = load_input(sd)
    solve = arriving.solve_stack(inp.images, MEAN, None)
    assert np.array_equal(solve, with_solve_channel(inp.images, MEAN), equal_nan=True)
    assert np.array_equal(inp.images, load_input(tmp_path / "t").images, equal_nan=True)
    assert arriving.solve_stack(inp.images, MEAN, None) is None        # handed over once
    sd.release_held_lights()
    assert sd.prepared is None


def test_a_light_changed_since_it_arrived_is_read_from_its_file(rig, tmp_path):
    arriving = ArrivingLights()
    sd = _scan(rig, tmp_path / "s", arriving)
    var = tmp_path / "s" / "hdr" / "light_01_var.exr"
    st = var.stat()
    os.utime(var, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))      # touched after the merge
    inp = load_input(sd)
    assert inp.images is not arriving.stack and arriving.images is None   # the stack dropped
    assert np.array_equal(inp.images, load_input(tmp_path / "s").images, equal_nan=True)


def test_process_of_the_scan_gives_the_normals_of_its_files(rig, tmp_path):
    sd = _scan(rig, tmp_path / "s", ArrivingLights())
    held = process(sd, outputs=["normals"])
    files = process(tmp_path / "s", outputs=["normals"])
    assert np.array_equal(held.normals, files.normals) and np.array_equal(held.mask, files.mask)
