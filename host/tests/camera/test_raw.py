"""RAW decode: DNGs from the simulated camera come back as linear, black-subtracted DN."""
import numpy as np
import pytest

from facette.camera.raw import RawDecodeError, bin_half_size, demosaic_bilinear, read_raw
from facette.sim.dng import write_dng
from facette.camera.sensor import SensorModel, bayer_mosaic_rggb


def _write(tmp_path, mosaic, name="f.dng", black=512, white=16383, t=0.25, iso=400):
    return write_dng(tmp_path / name, mosaic, black, white, t, iso, extra={"light": 1})


def test_half_size_values_exact(tmp_path):
    rng = np.random.default_rng(0)
    mosaic = rng.integers(512, 16000, size=(24, 30)).astype(np.uint16)
    f = read_raw(_write(tmp_path, mosaic))
    m = mosaic.astype(np.float64) - 512
    assert f.image.shape == (12, 15, 3) and f.image.dtype == np.float32
    assert np.array_equal(f.image[..., 0], m[0::2, 0::2])
    assert np.allclose(f.image[..., 1], 0.5 * (m[0::2, 1::2] + m[1::2, 0::2]))
    assert np.array_equal(f.image[..., 2], m[1::2, 1::2])
    assert np.array_equal(f.peak[..., 1], np.maximum(m[0::2, 1::2], m[1::2, 0::2]))
    assert f.n_photosites == (1, 2, 1)
    assert f.black_level == 512 and f.white_level == 16383 and f.range_dn == 16383 - 512
    assert f.exposure_time_s == pytest.approx(0.25) and f.iso == 400
    assert f.metadata == {"light": 1}
    assert f.normalized().max() <= 1.0


def test_simulated_exposure_recovers_irradiance(tmp_path):
    s = SensorModel(dark_current_e_per_s=0.0)
    irr = np.zeros((32, 32, 3))
    irr[..., 0], irr[..., 1], irr[..., 2] = 3000.0, 6000.0, 1500.0
    f = read_raw(_write(tmp_path, s.expose(irr, 1.0, 1)))
    est = f.image.reshape(-1, 3).mean(axis=0) * s.gain_e_per_dn
    assert np.allclose(est, [3000, 6000, 1500], rtol=0.01)


def test_bilinear_demosaic_constant_and_ramp():
    # Constant colour planes come back exactly; a linear ramp is interpolated exactly inside.
    h, w = 8, 10
    yy, xx = np.mgrid[0:h, 0:w]
    rgb = np.stack([10 + xx, 20 + 2 * yy, 30 + xx + yy], axis=-1).astype(np.float32)
    colors = bayer_mosaic_rggb(np.broadcast_to(np.array([0, 1, 2]), (h // 2, w // 2, 3)))
    colors = colors.copy()
    colors[1::2, 0::2] = 3
    mosaic = np.choose(np.where(colors == 3, 1, colors), [rgb[..., 0], rgb[..., 1], rgb[..., 2]])
    out = demosaic_bilinear(mosaic.astype(np.float32), colors)
    assert out.shape == (h, w, 3)
    assert np.allclose(out[1:-1, 1:-1], rgb[1:-1, 1:-1], atol=1e-4)


def test_full_size_option(tmp_path):
    mosaic = np.full((24, 26), 1512, np.uint16)
    f = read_raw(_write(tmp_path, mosaic), half_size=False)
    assert f.image.shape == (24, 26, 3)
    assert np.allclose(f.image, 1000.0) and np.allclose(f.peak, 1000.0)
    g = read_raw(_write(tmp_path, mosaic, "wb.dng"), white_balance=(2.0, 1.0, 0.5))
    assert np.allclose(g.image.reshape(-1, 3).mean(0), [2000, 1000, 500])
    with pytest.raises(ValueError, match="demosaic"):
        read_raw(tmp_path / "wb.dng", half_size=False, demosaic="ahd")


def test_bin_rejects_non_bayer():
    with pytest.raises(ValueError, match="one R, two G"):
        bin_half_size(np.zeros((4, 4)), np.zeros((4, 4), int))


def test_truncated_and_garbage_files_give_clear_errors(tmp_path):
    good = _write(tmp_path, np.full((40, 40), 600, np.uint16))
    data = good.read_bytes()
    trunc = tmp_path / "trunc.dng"
    trunc.write_bytes(data[: len(data) // 2])
    garbage = tmp_path / "garbage.dng"
    garbage.write_bytes(b"not a raw file" * 50)
    for p in (trunc, garbage):
        with pytest.raises(RawDecodeError, match=p.name) as info:
            read_raw(p)
        assert "re-shoot" in str(info.value)
    with pytest.raises(RawDecodeError, match="no RAW file"):
        read_raw(tmp_path / "missing.dng")


def _write_linear_dng(path, rgb, black=0, white=65535, exposure_s=None):
    """A linear DNG (PhotometricInterpretation LinearRaw, 3 samples per pixel): what a film
    scanner or a camera writing demosaiced RAW gives; `exposure_s` None: no ExposureTime tag
    (as a Blackmagic DNG)."""
    import tifffile
    tags = [(50706, "B", 4, (1, 4, 0, 0), True), (50707, "B", 4, (1, 1, 0, 0), True),
            (50708, "s", 0, "Test Linear", True), (50714, "H", 1, black, True), (50717, "H", 1, white, True),
            (50721, 10, 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),
            (50778, "H", 1, 21, True), (50728, 5, 3, (1, 1, 1, 1, 1, 1), True),
            (271, "s", 0, "Test", True), (272, "s", 0, "Linear", True)]
    if exposure_s:
        tags.append((33434, 5, 1, (1, int(round(1 / exposure_s))), True))
    tifffile.imwrite(path, rgb, photometric=34892, planarconfig="contig", compression=None, subfiletype=0,
                     metadata=None, extratags=tags)
    return path


def test_a_raw_that_is_not_a_mosaic_is_used_as_its_3_colour_image(tmp_path):
    from facette.camera.raw import read_raw_mosaic
    rgb = np.zeros((32, 48, 3), np.uint16)
    rgb[...] = (1000, 2000, 3000)
    rgb[4:6, 6:8] = 60000
    path = _write_linear_dng(tmp_path / "scan.dng", rgb, black=100, exposure_s=0.01)
    full = read_raw(path, half_size=False)
    assert full.image.shape == (32, 48, 3) and np.allclose(full.image[0, 0], [900, 1900, 2900])
    assert full.range_dn == 65435 and full.exposure_time_s == pytest.approx(0.01)
    assert full.notes == ["scan.dng is not a Bayer mosaic (a linear or 3-colour RAW): its 3-colour pixels "
                          "are used as they are (its own values; no demosaicing)"]
    half = read_raw(path)
    assert half.image.shape == (16, 24, 3) and half.n_photosites == (4, 4, 4)
    assert np.allclose(half.peak[2, 3], 59900) and np.allclose(half.image[0, 0], [900, 1900, 2900])
    with pytest.raises(RawDecodeError, match="is not a Bayer mosaic .* read it with read_raw"):
        read_raw_mosaic(path)


def test_a_raw_without_exposure_time_says_so(tmp_path):
    path = _write_linear_dng(tmp_path / "bmd.dng", np.full((32, 48, 3), 500, np.uint16))
    frame = read_raw(path)
    assert frame.exposure_time_s is None
    assert "bmd.dng carries no exposure time (no ExposureTime tag)" in frame.notes[-1]
