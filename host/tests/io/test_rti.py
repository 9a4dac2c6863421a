"""io.rti: HSH .rti files read back by a reader written from RTIViewer's published layout and basis."""
import numpy as np
import pytest

from facette.io.rti import write_hsh_rti
from facette.recon import fit_hsh, hsh_basis
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
from rti_spec_readers import hsh_colour, hsh_weights, read_hsh


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
