"""The LI shading terms' derivatives in (σ, n_i) (facette.brdf._shading_grad) against central
differences of facette.brdf.li_shading_terms, inside one node cell (the tables are piecewise linear
in log σ and n_i, so a difference across a node would average two cells' slopes)."""
import numpy as np
import pytest

from facette.brdf import li_shading_terms
from facette.brdf._shading_grad import li_shading_derivatives
from facette.recon.synthetic import thesis_light_directions


def _normals(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.3
    return (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("volume_model, sigma, n_i", [("tables", 0.11, 1.31), ("tables", 0.33, 1.56),
                                                      ("coupled", 0.07, 1.41), ("lambert", 0.21, 6.3)])
def test_the_derivatives_match_central_differences(volume_model, sigma, n_i):
    normals, lights = _normals(400, 0), thesis_light_directions().astype(np.float32)
    got = li_shading_derivatives(normals, lights, sigma, n_i, volume_model)
    for k, (ds, dn) in enumerate(((2e-3 * sigma, 0.0), (0.0, 2e-3))):
        ap, bp = li_shading_terms(normals, lights, sigma + ds, n_i + dn, volume_model=volume_model)
        am, bm = li_shading_terms(normals, lights, sigma - ds, n_i - dn, volume_model=volume_model)
        h = 2 * (ds + dn)
        for fd, d in (((ap.astype(float) - am) / h, got[k]), ((bp.astype(float) - bm) / h, got[2 + k])):
            scale = max(np.abs(fd).max(), 1e-6)
            assert np.abs(d - fd).max() < 0.01 * scale, (k, np.abs(d - fd).max(), scale)
    if volume_model == "lambert":
        assert not got[2].any() and not got[3].any()
    else:
        assert np.abs(got[2]).max() > 0 and np.abs(got[3]).max() > 0


def test_the_approximate_formula_has_no_derivatives_here():
    with pytest.raises(ValueError, match="derivatives"):
        li_shading_derivatives(_normals(3, 1), thesis_light_directions(), 0.1, 1.3, "approx")
