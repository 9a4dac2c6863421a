"""io.rti: HSH .rti files read back by a reader written from RTIViewer's and Relight's loaders
(rows top first, as RTIBuilder's files), and by the package's own reader (read_hsh_rti)."""

import numpy as np
import pytest

from facette.errors import BadInputError
from facette.io.rti import hsh_weights as hsh_weights_pkg, read_hsh_rti, write_hsh_rti, write_hsh_rti_rows
from facette.recon import display_hsh, fit_hsh, hsh_basis
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
from rti_spec_readers import (RTI_REFERENCE, asymmetric_scene, check_upright, hsh_colour, hsh_weights,
                              needs_reference, read_hsh)

REFERENCE = RTI_REFERENCE / "hsh"


@pytest.mark.parametrize("terms", [4, 9])
def test_values_and_row_order_come_back_within_half_a_step(tmp_path, terms):
    rng = np.random.default_rng(1)
    h, w = 5, 9
    coeffs = rng.normal(0, 0.2, (h, w, 3, terms))
    coeffs[0, 0, 1, 0] = 3.0                            # a marker: top-left pixel, green, term 0
    written = write_hsh_rti(tmp_path / "a.rti", coeffs)
    back = read_hsh(tmp_path / "a.rti")
    assert (back["width"], back["height"], back["terms"]) == (w, h, terms)
    np.testing.assert_allclose(back["scale"], written["scale"], rtol=1e-6)
    step = back["scale"] / 255.0
    assert np.all(np.abs(back["coeffs"] - coeffs) <= step / 2 + 1e-6)
    assert back["coeffs"][0, 0, 1, 0] == pytest.approx(3.0, abs=step[0])
    assert (tmp_path / "a.rti").read_bytes().startswith(b"#HSH1.2\n3\n9 5 3\n" + f"{terms} 2 1\n".encode())


def test_basis_is_rtiviewers_at_many_directions():
    rng = np.random.default_rng(2)
    d = rng.normal(size=(200, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ours = hsh_basis(d, 3)
    ref = np.array([hsh_weights(x, 9) for x in d])
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    np.testing.assert_allclose(hsh_basis(d, 2), ref[:, :4], atol=1e-12)
    np.testing.assert_allclose(hsh_weights_pkg(d, 9), ref, atol=1e-12)


@pytest.mark.parametrize("bad", [np.zeros((2, 3, 3, 5)), np.zeros((2, 3, 1, 9)),
                                 np.full((2, 3, 3, 9), np.inf)])
def test_bad_input_is_refused(tmp_path, bad):
    with pytest.raises(ValueError, match="HSH coefficients"):
        write_hsh_rti(tmp_path / "a.rti", bad)
    assert not any(tmp_path.iterdir())


def test_fitted_hsh_relights_the_images_it_was_fitted_to(tmp_path):
    lights = thesis_light_directions()
    sc = sphere_on_plane(40, 48)
    imgs = render(sc, lights, "matte")
    fit = fit_hsh(imgs, lights, order=3, mask=sc.mask)
    write_hsh_rti(tmp_path / "s.rti", fit.coeffs)
    rti = read_hsh(tmp_path / "s.rti")
    num = den = 0.0
    for img, d in zip(imgs, lights):
        got = fit.white * hsh_colour(rti, d)
        num += ((got - img)[sc.mask] ** 2).sum()
        den += (img[sc.mask] ** 2).sum()
    assert np.sqrt(num / den) < 0.05


@pytest.mark.parametrize("encoding", ["srgb", "linear"])
@pytest.mark.parametrize("order", [2, 3])
def test_hsh_of_an_asymmetric_scene_shows_upright_and_lit_from_the_right_side(tmp_path, encoding, order):
    """Read as RTIViewer and Relight read it (first row = top): the top of the picture is the
    top of the photographs, light from the right lights the right side, light from the top
    the upper side."""
    imgs, lights, dome, centre = asymmetric_scene()
    fit = fit_hsh(imgs, lights, order, encoding=encoding)
    write_hsh_rti(tmp_path / "s.rti", fit.coeffs, [f"encoding: {encoding}"])
    rti = read_hsh(tmp_path / "s.rti")
    check_upright(lambda d: hsh_colour(rti, d), dome, centre)
    back = read_hsh_rti(tmp_path / "s.rti")
    check_upright(back.relight, dome, centre)
    assert back.encoding == encoding
    for d in lights[::3]:
        assert np.abs(back.relight(d) - display_hsh(fit, d))[dome].max() < 0.03


def test_comment_lines_come_before_the_type_line(tmp_path):
    write_hsh_rti(tmp_path / "a.rti", np.zeros((2, 3, 3, 4)), ["encoding: srgb", "made by a test"])
    head = (tmp_path / "a.rti").read_bytes()
    assert head.startswith(b"#HSH1.2\n# encoding: srgb\n# made by a test\n3\n3 2 3\n4 2 1\n")
    assert read_hsh_rti(tmp_path / "a.rti").comments == ["encoding: srgb", "made by a test"]
    with pytest.raises(ValueError, match="one line"):
        write_hsh_rti(tmp_path / "b.rti", np.zeros((2, 3, 3, 4)), ["two\nlines"])


def test_reader_refuses_what_is_not_hsh(tmp_path):
    (tmp_path / "a.rti").write_bytes(b"#HSH1.2\n2\n2 2 3\n9 2 1\n")
    with pytest.raises(BadInputError, match="file type"):
        read_hsh_rti(tmp_path / "a.rti")
    (tmp_path / "b.rti").write_bytes(b"PTM_1.2\n")
    with pytest.raises(BadInputError, match="not an HSH"):
        read_hsh_rti(tmp_path / "b.rti")


@needs_reference(REFERENCE / "vase.rti", "RTIBuilder's sample files are")
@pytest.mark.parametrize("name", ["vase.rti", "vase_2ndorder.rti", "cuniform.rti"])
def test_rtibuilder_files_decode_upright(name):
    """RTIBuilder's own files, first row = top: the vase's neck and the cone's tip (narrow, at
    the top of the picture) are above its widest part, and light from +x brightens the right."""
    rti = read_hsh_rti(REFERENCE / name)
    front = rti.relight([0, 0, 1]).mean(-1)
    lit = front > 0.15
    widths = lit.sum(axis=1)
    rows = np.flatnonzero(widths > 0)
    top, bottom = rows[:len(rows) // 5], rows[-len(rows) // 5:]
    if name.startswith("cuniform"):      # a cone standing on its base: narrow at the top
        assert widths[top].mean() < 0.6 * widths[bottom].mean()
    s = np.sqrt(0.5)
    ratio = rti.relight([s, 0, s]).mean(-1) / np.maximum(rti.relight([-s, 0, s]).mean(-1), 1e-3)
    xx = np.mgrid[0:rti.height, 0:rti.width][1]
    cx = xx[lit].mean()
    assert np.median(ratio[lit & (xx > cx)]) > np.median(ratio[lit & (xx < cx)])
    ratio_y = rti.relight([0, s, s]).mean(-1) / np.maximum(rti.relight([0, -s, s]).mean(-1), 1e-3)
    yy = np.mgrid[0:rti.height, 0:rti.width][0]
    cy = yy[lit].mean()
    assert np.median(ratio_y[lit & (yy < cy)]) > np.median(ratio_y[lit & (yy > cy)])


def test_rows_form_writes_the_same_bytes_asking_top_band_first(tmp_path):
    rng = np.random.default_rng(4)
    h, w = 130, 7
    coeffs = rng.normal(0, 0.2, (h, w, 3, 9)).astype(np.float32)
    whole = write_hsh_rti(tmp_path / "a.rti", coeffs, ["c"])
    asked = []

    def rows(r0, r1):
        asked.append((r0, r1))
        return coeffs[r0:r1]
    lo, hi = coeffs.reshape(-1, 9).min(axis=0), coeffs.reshape(-1, 9).max(axis=0)
    assert write_hsh_rti_rows(tmp_path / "b.rti", w, h, (lo, hi), rows, ["c"]) == whole
    assert (tmp_path / "a.rti").read_bytes() == (tmp_path / "b.rti").read_bytes()
    assert asked == [(0, 64), (64, 128), (128, 130)]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_compiled_quantisation_writes_numpys_bytes(tmp_path, monkeypatch, dtype):
    # relight.rti and both relight.ptm formats: the compiled pass gives the bytes of numpy's float64 steps
    # (values half a step apart, signed zeros, the extremes of each term)
    from facette.io import ptm as ptm_io, rti as rti_io
    rng = np.random.default_rng(4)
    h, w = 70, 33
    hsh = (rng.standard_normal((h, w, 3, 9)) * 0.3).astype(dtype)
    hsh[1], hsh[2] = 0.0, -0.0
    hsh[3, :, :, 0] = np.linspace(-1, 1, 255 * 4 + 1)[:w * 3].reshape(w, 3)
    lrgb = (rng.standard_normal((h, w, 6)) * 0.4).astype(dtype)
    per_channel = (rng.standard_normal((h, w, 3, 6)) * 0.2).astype(dtype)
    files = {}
    for compiled in (True, False):
        monkeypatch.setattr(rti_io, "COMPILED", compiled)
        monkeypatch.setattr(ptm_io, "COMPILED", compiled)
        rti_io.write_hsh_rti(tmp_path / f"{compiled}.rti", hsh, ["c"])
        ptm_io.write_ptm_lrgb(tmp_path / f"{compiled}.ptm", lrgb, np.full((h, w, 3), 0.5))
        ptm_io.write_ptm_rgb_rows(tmp_path / f"{compiled}_rgb.ptm", w, h,
                                  ptm_io.column_range(per_channel.reshape(-1, 6)), lambda r0, r1: per_channel[r0:r1])
        files[compiled] = [(tmp_path / f"{compiled}{ext}").read_bytes() for ext in (".rti", ".ptm", "_rgb.ptm")]
    assert files[True] == files[False]
    assert len(set(files[True][0][-3 * 9 * w * h:])) > 200        # the bytes span the range
