"""io.ptm: PTM LRGB files read back by a reader written from the HP Labs format document and
RTIViewer's loader, and by the package's own reader (facette.io.ptm.read_ptm)."""

import numpy as np
import pytest

from facette.errors import BadInputError
from facette.io.ptm import (column_range, ptm_rgb_bytes, quantize_scale_bias, read_ptm as read_ptm_pkg, write_ptm_lrgb,
                            write_ptm_lrgb_rows, write_ptm_rgb_rows)
from facette.recon import display_ptm, fit_ptm_lrgb, ptm_basis
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
from rti_spec_readers import (RTI_REFERENCE, asymmetric_scene, check_upright, needs_reference, ptm_colour,
                              ptm_rgb_colour, read_ptm, read_ptm_rgb)

REFERENCE = RTI_REFERENCE / "ptm" / "tablet1.ptm"


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
    # byte units: L = 1 (full brightness) is stored as 255, what RTIViewer and Relight take
    assert np.all(np.abs(back["coeffs"] - 255 * coeffs) <= back["scale"] / 2 + 1e-9)
    assert back["coeffs"][0, 0, 0] == pytest.approx(510.0, abs=back["scale"][0])   # top row stays on top
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
        got = fit.white * ptm_colour(ptm, d, rtiviewer=False)
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


@pytest.mark.parametrize("encoding", ["srgb", "linear"])
def test_ptm_of_an_asymmetric_scene_shows_upright_and_lit_from_the_right_side(tmp_path, encoding):
    """Read as RTIViewer reads it (integer coefficients, L · RGB / 255): the top of the picture
    is the top of the photographs, light from the right lights the right side, not black."""
    imgs, lights, dome, centre = asymmetric_scene()
    fit = fit_ptm_lrgb(imgs, lights, encoding=encoding)
    write_ptm_lrgb(tmp_path / "s.ptm", fit.coeffs, fit.rgb)
    ptm = read_ptm(tmp_path / "s.ptm")
    check_upright(lambda d: ptm_colour(ptm, d), dome, centre)
    check_upright(lambda d: read_ptm_pkg(tmp_path / "s.ptm").relight(d, rtiviewer=True), dome, centre)
    # the constant term of a lit pixel is in byte units: around 255 · L, not around L
    assert np.median(ptm["coeffs"][dome][:, 5]) > 100


def test_package_reader_gives_what_was_fitted_within_the_quantisation(tmp_path):
    imgs, lights, dome, _ = asymmetric_scene()
    fit = fit_ptm_lrgb(imgs, lights, encoding="srgb")
    write_ptm_lrgb(tmp_path / "s.ptm", fit.coeffs, fit.rgb)
    back = read_ptm_pkg(tmp_path / "s.ptm")
    assert (back.width, back.height, back.format) == (64, 48, "PTM_FORMAT_LRGB")
    for d in lights[::3]:
        want = display_ptm(fit, d)
        assert np.abs(back.relight(d) - want)[dome].max() < 0.03            # Relight: float coefficients
        assert np.abs(back.relight(d, rtiviewer=True) - want)[dome].mean() < 0.02   # RTIViewer: truncated


def test_reader_refuses_other_formats_with_a_clear_error(tmp_path):
    (tmp_path / "lum.ptm").write_bytes(b"PTM_1.2\nPTM_FORMAT_LUM\n2\n2\n1 1 1 1 1 1\n0 0 0 0 0 0\n")
    with pytest.raises(BadInputError, match="PTM_FORMAT_LUM is not read"):
        read_ptm_pkg(tmp_path / "lum.ptm")
    (tmp_path / "x.ptm").write_bytes(b"P6\n2 2\n255\n")
    with pytest.raises(BadInputError, match="not a PTM file"):
        read_ptm_pkg(tmp_path / "x.ptm")


@needs_reference(REFERENCE, "HP's sample PTM is")
def test_hp_sample_ptm_decodes_in_byte_units_and_lit_from_the_right():
    """tablet1.ptm (PTM_FORMAT_JPEG_LRGB, HP's encoder): constant terms reach 510 (2 · 255),
    and on the tablet, brighter towards the light: a3 (the lu term) grows to the right,
    a4 (lv) towards the top."""
    ptm = read_ptm_pkg(REFERENCE)
    assert (ptm.width, ptm.height) == (512, 512)
    assert ptm.coeffs[..., 5].max() > 255
    lit = ptm.relight([0, 0, 1]).mean(-1) > 0.15
    yy, xx = np.mgrid[0:512, 0:512]
    assert np.corrcoef(ptm.coeffs[..., 3][lit], xx[lit])[0, 1] > 0.2
    assert np.corrcoef(ptm.coeffs[..., 4][lit], -yy[lit])[0, 1] > 0.2


def test_rows_form_writes_the_same_bytes_asking_bottom_band_first(tmp_path):
    rng = np.random.default_rng(3)
    h, w = 150, 13                                          # 3 writer bands of 64 rows, the last short
    coeffs = rng.normal(0, 0.3, (h, w, 6)).astype(np.float32)
    rgb = rng.uniform(0, 1, (h, w, 3))
    whole = write_ptm_lrgb(tmp_path / "a.ptm", coeffs, rgb)
    asked = []

    def rows(r0, r1):
        asked.append((r0, r1))
        return coeffs[r0:r1]
    banded = write_ptm_lrgb_rows(tmp_path / "b.ptm", w, h, column_range(coeffs.reshape(-1, 6)), rows,
                                 lambda r0, r1: ptm_rgb_bytes(rgb[r0:r1]))       # colours as bytes
    assert banded == whole and (tmp_path / "a.ptm").read_bytes() == (tmp_path / "b.ptm").read_bytes()
    assert asked == [(86, 150), (22, 86), (0, 22)]


def test_rows_form_refuses_a_range_that_is_not_finite(tmp_path):
    with pytest.raises(ValueError, match="finite"):
        write_ptm_lrgb_rows(tmp_path / "a.ptm", 2, 2, (np.full(6, np.nan), np.zeros(6)),
                            lambda r0, r1: np.zeros((r1 - r0, 2, 6)), lambda r0, r1: np.zeros((r1 - r0, 2, 3)))
    assert not any(tmp_path.iterdir())


def test_rgb_format_is_shown_by_rtiviewers_rules_as_written(tmp_path):
    """PTM_FORMAT_RGB: each channel its own polynomial; read by a reader written from RTIViewer's
    RGBPtm loader (red, green, blue planes, bottom row first, one scale and bias per term), each
    channel at every light within the quantisation (half a step per term) and RTIViewer's
    truncation (one byte unit per term) of what was written; upright and per channel (a red
    left half, a blue right half)."""
    rng = np.random.default_rng(5)
    h, w = 150, 9                                     # 3 writer bands of 64 rows, the last short
    coeffs = rng.normal(0, 0.2, (h, w, 3, 6)).astype(np.float32)
    coeffs[..., 5] += 0.5
    coeffs[:, : w // 2, 0, 5] += 0.4                  # red on the left, blue on the right
    coeffs[:, w // 2:, 2, 5] += 0.4
    coeffs[: h // 3, :, 1, 3] += 0.3                  # green grows with lu in the top third
    asked = []

    def rows(r0, r1):
        asked.append((r0, r1))
        return coeffs[r0:r1]
    head = write_ptm_rgb_rows(tmp_path / "a.ptm", w, h, column_range(coeffs.reshape(-1, 6)), rows)
    assert asked == [(86, 150), (22, 86), (0, 22)] * 3            # red, green, blue: bottom band first
    spec = read_ptm_rgb(tmp_path / "a.ptm")
    assert np.allclose(spec["scale"], head["scale"]) and list(spec["bias"]) == head["bias"]
    step = np.asarray(head["scale"])
    for d in thesis_light_directions()[::4]:
        want = np.einsum("hwct,t->hwc", coeffs.astype(np.float64), ptm_basis(d)) * 255
        tol = (np.abs(ptm_basis(d)) * (step / 2 + 1)).sum() + 1e-6
        got = ptm_rgb_colour(spec, d) * 255
        inside = (want > tol) & (want < 255 - tol)
        assert inside.mean() > 0.5 and np.abs(got - want)[inside].max() <= tol
        pkg = read_ptm_pkg(tmp_path / "a.ptm")                   # the package's reader: the same picture
        assert pkg.format == "PTM_FORMAT_RGB" and pkg.rgb is None
        np.testing.assert_allclose(pkg.relight(d, rtiviewer=True), ptm_rgb_colour(spec, d), atol=1e-12)
    top = ptm_rgb_colour(spec, [0, 0, 1])
    assert top[:, : w // 2, 0].mean() > top[:, : w // 2, 2].mean() + 0.3
    assert top[:, w // 2:, 2].mean() > top[:, w // 2:, 0].mean() + 0.3
    right, left = ptm_rgb_colour(spec, [0.7, 0, 0.714]), ptm_rgb_colour(spec, [-0.7, 0, 0.714])
    assert (right - left)[: h // 3, :, 1].mean() > 0.3 > abs((right - left)[h // 2:, :, 1].mean())
