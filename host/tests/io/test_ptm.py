"""io.ptm: PTM LRGB files read back by a reader written from the HP Labs format document."""
import numpy as np
import pytest

from facette.io.ptm import column_range, quantize_scale_bias, write_ptm_lrgb
from facette.recon import fit_ptm_lrgb, ptm_basis
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
from rti_spec_readers import ptm_colour, read_ptm


def test_values_rows_and_colours_come_back_within_half_a_step(tmp_path):
    rng = np.random.default_rng(0)
    h, w = 7, 11
    coeffs = rng.normal(0, 0.3, (h, w, 6))
    coeffs[..., 5] = rng.uniform(0, 1, (h, w))
    coeffs[0, 0] = [2.0, -1.5, 0.0, 0.0, 0.0, 0.0]          # a marker at the top-left pixel
    rgb = rng.uniform(0, 1, (h, w, 3))
    written = write_ptm_lrgb(tmp_path / "a.ptm", coeffs, rgb)
    back = read_ptm(tmp_path / "a.ptm")
    assert (back["width"], back["height"]) == (w, h)
    np.testing.assert_allclose(back["scale"], written["scale"], rtol=1e-8)
    assert list(back["bias"]) == written["bias"]
    assert np.all(np.abs(back["coeffs"] - coeffs) <= back["scale"] / 2 + 1e-12)
    assert back["coeffs"][0, 0, 0] == pytest.approx(2.0, abs=back["scale"][0])   # top row stays on top
    assert np.all(np.abs(back["rgb"] / 255.0 - rgb) <= 0.5 / 255 + 1e-12)


def test_header_is_the_documented_ascii_lines(tmp_path):
    write_ptm_lrgb(tmp_path / "a.ptm", np.zeros((2, 3, 6)), np.ones((2, 3, 3)))
    lines = (tmp_path / "a.ptm").read_bytes().split(b"\n")
    assert lines[:4] == [b"PTM_1.2", b"PTM_FORMAT_LRGB", b"3", b"2"]
    assert len(lines[4].split()) == 6 and len(lines[5].split()) == 6
    assert all(0 <= int(b) <= 255 for b in lines[5].split())


def test_scale_and_bias_cover_every_value_with_zero_on_a_byte():
    c = np.array([[-1.0, 0.0, 0.5, 0.0, 3.0, -2.0], [1.0, 0.0, 2.0, 0.0, 4.0, -1.0]])
    scale, bias = quantize_scale_bias(c)
    q = c / scale + bias
    assert np.all(q >= -0.5) and np.all(q <= 255.5)
    assert bias[1] == 0 and bias[5] == 255                  # all-zero and all-negative terms


@pytest.mark.parametrize("bad, match", [
    (dict(coeffs=np.zeros((2, 3, 5)), rgb=np.zeros((2, 3, 3))), "shape"),
    (dict(coeffs=np.zeros((2, 3, 6)), rgb=np.zeros((3, 2, 3))), "rgb must have shape"),
    (dict(coeffs=np.full((2, 3, 6), np.nan), rgb=np.zeros((2, 3, 3))), "finite"),
    (dict(coeffs=np.zeros((0, 3, 6)), rgb=np.zeros((0, 3, 3))), "shape"),
])
def test_bad_input_is_refused_and_nothing_is_written(tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        write_ptm_lrgb(tmp_path / "a.ptm", **bad)
    assert not any(tmp_path.iterdir())


def test_fitted_ptm_relights_the_images_it_was_fitted_to(tmp_path):
    """A PTM fitted to a rendered matte sphere on a plane, written, read back from the
    specification: its relighting at the scan's lights matches the images as the float fit."""
    lights = thesis_light_directions()
    sc = sphere_on_plane(40, 48)
    imgs = render(sc, lights, "matte")
    fit = fit_ptm_lrgb(imgs, lights, mask=sc.mask)
    write_ptm_lrgb(tmp_path / "s.ptm", fit.coeffs, fit.rgb)
    ptm = read_ptm(tmp_path / "s.ptm")
    num = num_float = den = 0.0
    for img, d in zip(imgs, lights):
        got = fit.white * ptm_colour(ptm, d)
        flt = fit.white * np.maximum(fit.coeffs @ ptm_basis(d), 0)[..., None] * fit.rgb
        num += ((got - img)[sc.mask] ** 2).sum()
        num_float += ((flt - img)[sc.mask] ** 2).sum()
        den += (img[sc.mask] ** 2).sum()
    err, err_float = np.sqrt(num / den), np.sqrt(num_float / den)
    assert err < 0.08                     # a biquadratic of the light misses shadows, not more
    assert err - err_float < 0.01         # 8-bit storage adds under 1 %


@pytest.mark.parametrize("n", [1, 255, 256, 1000, 70_001])
def test_column_range_is_min_and_max_over_rows(n):
    a = np.random.default_rng(n).normal(size=(n, 9)).astype(np.float32)
    lo, hi = column_range(a)
    np.testing.assert_array_equal(lo, a.min(axis=0))
    np.testing.assert_array_equal(hi, a.max(axis=0))
