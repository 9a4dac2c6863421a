"""`bench size --against-whole`: the reference is read whole; the comparison of two runs' files."""
import numpy as np

from facette.bench._large import write_relief_capture
from facette.bench._size_whole import normals_apart, whole_memory
from facette.io.exr import write_exr
from facette.pipeline._options import ProcessOptions
from facette.pipeline._streamed import read_in_bands


def test_the_whole_memory_makes_process_read_the_capture_whole(tmp_path):
    folder = write_relief_capture(tmp_path / "slab", 40, 24)
    memory = whole_memory(folder)
    assert memory.endswith("GB")
    assert not read_in_bands(folder, ProcessOptions(memory=memory), ["normals", "height"])
    assert read_in_bands(folder, ProcessOptions(memory="0.01GB"), ["normals", "height"])


def _results(folder, normals, height):
    folder.mkdir()
    write_exr(folder / "normal.exr", normals.astype(np.float32), channels=("X", "Y", "Z"))
    write_exr(folder / "height.exr", height.astype(np.float32)[..., None], channels=("Z",))
    return folder


def test_normals_apart_says_the_largest_and_mean_angle_and_the_heights(tmp_path):
    rng = np.random.default_rng(0)
    n = rng.normal(size=(20, 30, 3)) + (0, 0, 4)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[0, 0] = 0                                  # no normal there: left out
    tilt = np.radians(0.02)                      # one pixel turned by 0.02 deg about x
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    m = n.copy()
    m[5, 7] = rot @ n[5, 7]
    h = np.linspace(0, 10, 600).reshape(20, 30)
    a = _results(tmp_path / "a", n, h)
    b = _results(tmp_path / "b", m, h + np.where(np.arange(600).reshape(20, 30) == 42, 0.1, 0))
    worst, mean, over, count, height = normals_apart(a, b)
    assert count == 599 and over == 1
    assert abs(worst - 0.02) < 1e-3 and abs(mean - 0.02 / 599) < 1e-5
    assert abs(height - 0.1 / (10 - h[0, 1])) < 1e-6     # over the range where there are normals
