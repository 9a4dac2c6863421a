"""The relighting model fitted from a band reader (recon._relight_fit): any band height gives the
whole images' model, the cast shadows' bands are the whole map's rows, the white is chosen."""
import numpy as np
import pytest

from facette.recon import fit_relight_bands, fit_relight_model, integrate
from facette.recon._relight_fit import WHITE_PERCENTILE, _Shadows
from facette.recon._relight_model import cast_shadow
from facette.recon.synthetic import render, sphere_on_plane


@pytest.fixture(scope="module")
def capture():
    sc = sphere_on_plane(30, 38, radius=11)
    rng = np.random.default_rng(4)
    d = rng.normal(size=(16, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.6
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    lin = render(sc, d, material="satin", albedo=(0.7, 0.5, 0.3)).astype(np.float32)
    lin /= np.percentile(lin, 99.5)
    lin[3, 5:8, 10:14] = np.nan                       # unknown values (clipped photographs)
    return sc, d, lin, integrate(sc.normals, mask=sc.mask)


def _reader(lin, calls):
    def read(r0, r1):
        calls.append((r0, r1))
        return lin[:, r0:r1].copy(), None
    return read


@pytest.mark.parametrize("rows", [1, 4, 13])
def test_bands_give_the_whole_images_model(capture, rows):
    sc, d, lin, h = capture
    whole = fit_relight_model(lin, d, sc.mask, sc.normals, heights=h, shadows=True)
    calls = []
    banded = fit_relight_bands(_reader(lin, calls), d, sc.mask, sc.normals, heights=h, shadows=True, rows=rows)
    assert max(r1 - r0 for r0, r1 in calls) <= rows and len(calls) >= 3 * (sc.mask.shape[0] // rows)
    assert banded.shininess == whole.shininess and banded.white == whole.white
    for name in ("rho", "spec", "amb"):     # per pixel: the same bytes
        np.testing.assert_array_equal(getattr(banded, name), getattr(whole, name))
    # the gram summed in another order: its eigenvectors, so the planes, within float error
    assert banded.planes.shape == whole.planes.shape and banded.planes.shape[-1] > 0
    for light in d[:4]:
        diff = np.abs(banded.display(light) - whole.display(light))
        assert diff.max() < 2e-3, diff.max()


def test_a_spilled_fit_is_the_fit_in_memory_and_its_file_the_same(capture, tmp_path, monkeypatch):
    """spill=True: the normals, maps and planes in temporary files (memmaps), the same values; the file
    written a few rows at a time from them reads back as np.savez's of the fit in memory."""
    from facette.recon import _relight_model, load_relight_model, save_relight_model
    from facette.recon import _relight_fit
    sc, d, lin, h = capture
    monkeypatch.setattr(_relight_fit, "CLEAN_PIXELS", 100)          # the normals cleaned 2 rows at a time
    normals = sc.normals.astype(np.float32)
    normals[4, 20] = np.nan                                          # a pixel without a normal
    mem = fit_relight_bands(_reader(lin, []), d, sc.mask, normals, heights=h, shadows=True, rows=6)
    disk = fit_relight_bands(_reader(lin, []), d, sc.mask, normals, heights=h, shadows=True, rows=6, spill=True)
    assert not mem.mask[4, 20] and mem.mask.sum() == sc.mask.sum() - 1
    for name in ("normals", "mask", "rho", "spec", "amb", "planes"):
        a, b = getattr(mem, name), getattr(disk, name)
        assert isinstance(b, np.memmap) == (name != "mask") and not isinstance(a, np.memmap), name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert disk.planes.shape[-1] > 0 and disk.loo_error == mem.loo_error
    monkeypatch.setattr(_relight_model, "WRITE_BYTES", 1000)         # a few rows at a time
    save_relight_model(tmp_path / "disk.npz", disk)
    with open(tmp_path / "mem.npz", "wb") as fh:                     # numpy's own writer of the same arrays
        np.savez(fh, format=np.array("facette relight model 1"), shininess=mem.shininess, epsilon=mem.epsilon,
                 white=mem.white, softness=mem.softness, spacing=mem.spacing, reach=mem.reach,
                 **{k: getattr(mem, k) for k in _relight_model._ARRAYS if getattr(mem, k) is not None})
    with np.load(tmp_path / "disk.npz") as a, np.load(tmp_path / "mem.npz") as b:
        assert sorted(a.files) == sorted(b.files) and "planes" in a.files
        for k in a.files:
            assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    back = load_relight_model(tmp_path / "disk.npz")
    np.testing.assert_array_equal(back.display(d[2]), mem.display(d[2]))
    part = disk.first_planes(2)                                      # a view that is not C-contiguous
    save_relight_model(tmp_path / "part.npz", part)
    np.testing.assert_array_equal(load_relight_model(tmp_path / "part.npz").planes, part.planes)


def test_white_none_is_the_percentile_of_the_brightest_channel(capture):
    sc, d, lin, _ = capture
    model = fit_relight_bands(_reader(lin * 3.0, []), d, sc.mask, sc.normals, white=None, rows=7)
    top = np.max(lin[:, sc.mask] * 3.0, axis=-1)
    expect = np.percentile(top[np.isfinite(top) & (top > 0)], WHITE_PERCENTILE)
    assert model.white == pytest.approx(expect, rel=1e-6)


@pytest.mark.parametrize("max_pixels", [1 << 20, 300])
def test_shadow_rows_are_the_whole_maps(capture, max_pixels):
    sc, d, _, h = capture
    heights = np.where(sc.mask, h, np.nan)
    shadows = _Shadows(heights, d[:3], max_pixels=max_pixels)
    for k, light in enumerate(d[:3]):
        whole = np.round(cast_shadow(heights, light, max_pixels=max_pixels) * 255).astype(np.uint8)
        for r0, r1 in ((0, 5), (5, 17), (17, whole.shape[0])):
            np.testing.assert_array_equal(shadows.rows(r0, r1)[k], whole[r0:r1])
        r, c = np.nonzero(sc.mask)
        np.testing.assert_array_equal(shadows.at(r, c)[k], whole[r, c])


def test_no_object_pixel_fits_nothing_and_says_so(capture):
    sc, d, lin, _ = capture
    calls = []
    model = fit_relight_bands(_reader(lin, calls), d, np.zeros_like(sc.mask), sc.normals)
    assert not calls and "nothing fitted" in model.notes[0] and model.display(d[0]).max() == 0
