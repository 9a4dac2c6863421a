"""The large-capture generator: a DiLiGenT folder written band by band, with its truth."""
import numpy as np
import pytest

from facette.bench._large import relief_surface, write_relief_capture
from facette.io.diligent import read_diligent
from facette.methods import photometric_stereo
from facette.recon.synthetic import thesis_light_directions


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def test_bands_give_the_same_folder_as_one_band(tmp_path):
    small = write_relief_capture(tmp_path / "bands", 70, 50, band_pixels=70 * 3)   # 3 rows a band
    whole = write_relief_capture(tmp_path / "whole", 70, 50, band_pixels=10 ** 6)
    a, b = read_diligent(small), read_diligent(whole)
    np.testing.assert_array_equal(np.nan_to_num(a.images, nan=-1), np.nan_to_num(b.images, nan=-1))
    np.testing.assert_array_equal(np.load(small / "normal_gt.npy"), np.load(whole / "normal_gt.npy"))
    np.testing.assert_array_equal(np.load(small / "height_gt.npy"), np.load(whole / "height_gt.npy"))
    assert a.images.shape == (12, 50, 70, 3) and a.mask.all()
    np.testing.assert_allclose(a.light_dirs, thesis_light_directions(), atol=1e-7)


def test_least_squares_finds_the_truth_normals(tmp_path):
    folder = write_relief_capture(tmp_path / "slab", 96, 64)
    d = read_diligent(folder)
    truth = np.load(folder / "normal_gt.npy")
    assert truth.shape == (64, 96, 3) and truth.dtype == np.float32
    ps = photometric_stereo(d.images, d.light_dirs, method="woodham1980", mask=d.mask)
    err = _angle_deg(ps.normal, truth)
    assert 2.0 < err.mean() < 6.0           # the highlight (5.0 deg measured): least squares takes it in
    robust = photometric_stereo(d.images, d.light_dirs, method="st14", mask=d.mask)
    assert _angle_deg(robust.normal, truth).mean() < 1.0     # 0.68 measured: a model with the lobe
    tilt = np.degrees(np.arccos(truth[..., 2]))
    assert 35 < tilt.max() < 55             # a relief, not a plane


def test_normals_are_the_heights_slopes():
    rows, cols = np.arange(200, 260), np.arange(300, 380)
    z, n = relief_surface(rows, cols, 5000)
    # y up, rows down: dz/dy = -dz/drow; normal ~ (-dz/dx, -dz/dy, 1)
    dzdx = np.gradient(z, axis=1)
    dzdy = -np.gradient(z, axis=0)
    np.testing.assert_allclose((-n[..., 0] / n[..., 2])[1:-1, 1:-1], dzdx[1:-1, 1:-1], rtol=1e-3, atol=1e-4)
    np.testing.assert_allclose((-n[..., 1] / n[..., 2])[1:-1, 1:-1], dzdy[1:-1, 1:-1], rtol=1e-3, atol=1e-4)


def test_too_small_is_refused(tmp_path):
    with pytest.raises(ValueError, match="at least 8x8"):
        write_relief_capture(tmp_path, 4, 100)
