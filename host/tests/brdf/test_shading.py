"""li_shading_terms: the LI model's image values from dot products, against the reference
evaluation on local-frame vectors (li_specular, volume_integral_approx)."""
import numpy as np
import pytest

from facette.brdf import (li_kappa, li_kd_from_kappa, li_shading_terms, li_specular,
                          volume_integral_approx)


def _random_normals(n, rng):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.2
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _reference(normals, lights, sigma, n_i):
    z = normals
    x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    sl = np.stack([lights @ x.T, lights @ y.T, lights @ z.T], -1).transpose(1, 0, 2)
    v = np.array([0.0, 0.0, 1.0])
    vl = np.broadcast_to(np.stack([x @ v, y @ v, z @ v], -1)[:, None, :], sl.shape)
    up = (sl[..., 2] > 0) & (vl[..., 2] > 0)
    a = np.where(up, li_specular(sl, vl, sigma, n_i) * sl[..., 2], 0)
    b = np.where(up, volume_integral_approx(sl, vl, sigma, n_i) * sl[..., 2], 0)
    return a, b, up


@pytest.mark.parametrize("sigma,n_i", [(0.1, 1.3), (0.05, 1.26), (0.3, 1.5), (0.2, 1.0)])
def test_matches_reference_evaluation(sigma, n_i):
    rng = np.random.default_rng(1)
    normals = _random_normals(3000, rng)
    lights = _random_normals(12, rng)
    a, b = li_shading_terms(normals, lights, sigma, n_i)
    ar, br, up = _reference(normals, lights, sigma, n_i)
    assert a.shape == b.shape == (3000, 12) and a.dtype == np.float32
    assert np.max(np.abs(a - ar)[up]) <= 2e-4 * max(ar.max(), 1e-9) + 1e-6
    assert np.max(np.abs(b - br)[up]) < 1e-5
    assert np.all(a[~up] == 0) and np.all(b[~up] == 0)


def test_per_pixel_lights_equal_global_ones():
    rng = np.random.default_rng(2)
    normals = _random_normals(50, rng)
    lights = _random_normals(8, rng)
    a, b = li_shading_terms(normals, lights, 0.1, 1.3)
    a2, b2 = li_shading_terms(normals, np.broadcast_to(lights, (50, 8, 3)), 0.1, 1.3)
    np.testing.assert_allclose(a, a2, rtol=1e-5, atol=1e-5 * a.max())   # the lobe's cut-off may flip
    np.testing.assert_allclose(b, b2, rtol=1e-5, atol=1e-7)


def test_edges_flat_facet_and_no_interface():
    normals = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    lights = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, np.sqrt(0.75)]])
    a, b = li_shading_terms(normals, lights, 0.0, 1.3)          # σ = 0: a Dirac lobe, no value
    assert np.all(a == 0) and np.all(np.isfinite(b)) and np.all(b > 0)
    a, b = li_shading_terms(normals, lights, 1e-3, 1.0)         # n_i = 1, σ → 0: Lambert's shape
    ratio = b / np.clip(normals @ lights.T, 1e-9, None)
    # (the approximate formula's T̄ factors give 0.963 rather than 1 at this edge of its fit box)
    np.testing.assert_allclose(ratio, ratio.mean(), rtol=1e-3)
    assert 0.9 < ratio.mean() <= 1.0
    assert np.all(a == 0)


def test_kappa_round_trip_and_bad_arguments():
    kd = np.linspace(0, 1, 11)
    np.testing.assert_allclose(li_kd_from_kappa(li_kappa(kd, 1.4), 1.4), kd, atol=1e-6)
    with pytest.raises(ValueError, match="roughness"):
        li_shading_terms(np.array([[0, 0, 1.0]]), np.array([[0, 0, 1.0]]), -0.1, 1.3)
    with pytest.raises(ValueError, match="n_i"):
        li_shading_terms(np.array([[0, 0, 1.0]]), np.array([[0, 0, 1.0]]), 0.1, 0.5)
    with pytest.raises(ValueError, match="lights"):
        li_shading_terms(np.array([[0, 0, 1.0]]), np.ones((2, 4)), 0.1, 1.3)


@pytest.mark.parametrize("sigma,n_i", [(0.1, 1.3), (0.2, 1.5), (0.0437, 1.2113)])
def test_tables_model_follows_the_volume_integral(sigma, n_i):
    # volume_model="tables": B = (n·s) I with I eq 3.15 itself (quadrature), not the formula,
    # also between the (σ, n_i) nodes; the formula is several % off the integral
    from facette.brdf import volume_integral_quadrature
    rng = np.random.default_rng(3)
    normals = _random_normals(2000, rng)
    lights = _random_normals(6, rng)
    _, b = li_shading_terms(normals, lights, sigma, n_i, volume_model="tables")
    _, b_approx = li_shading_terms(normals, lights, sigma, n_i)
    z = normals
    x = np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    sl = np.stack([lights @ x.T, lights @ y.T, lights @ z.T], -1).transpose(1, 0, 2)
    vl = np.broadcast_to(np.stack([x[:, 2], y[:, 2], z[:, 2]], -1)[:, None, :], sl.shape)
    sel = (sl[..., 2] > 0.1) & (vl[..., 2] > 0.1)          # above 6° elevation
    ref = volume_integral_quadrature(sl[sel], vl[sel], sigma, n_i) * sl[sel][:, 2]
    err = np.abs(b[sel] / ref - 1)
    err_approx = np.abs(b_approx[sel] / ref - 1)
    assert np.median(err) < 2e-3 and np.percentile(err, 99) < 0.03, (np.median(err), np.percentile(err, 99))
    assert np.median(err_approx) > 10 * np.median(err)
    assert np.all(b[~((sl[..., 2] > 0) & (vl[..., 2] > 0))] == 0)


def test_tables_model_is_continuous_in_sigma_and_n_i():
    # a fit's finite differences must see the model, not the node grid: tiny parameter steps
    # give tiny, proportionate changes, and n_i = 1, σ → 0 is Lambert exactly
    normals = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.8, 0.6]])
    lights = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, np.sqrt(0.75)], [-0.3, 0.4, np.sqrt(0.75)]])
    vals = [li_shading_terms(normals, lights, s, 1.3, volume_model="tables")[1]
            for s in np.linspace(0.1, 0.1005, 6)]
    steps = np.abs(np.diff(vals, axis=0))
    assert np.all(steps < 1e-4) and np.all(np.isfinite(vals))
    assert steps.max() < 3 * max(steps.mean(), 1e-12)       # no jump where a node is crossed
    _, b = li_shading_terms(normals, lights, 1e-3, 1.0, volume_model="tables")
    np.testing.assert_allclose(b / np.clip(normals @ lights.T, 1e-9, None), 1.0, rtol=1e-5)
    with pytest.raises(ValueError, match="volume_model"):
        li_shading_terms(normals, lights, 0.1, 1.3, volume_model="exact")


def test_factored_table_build_equals_the_quadrature():
    # build_volume_table with Smith masking sums the same nodes as volume_integral_quadrature
    from facette.brdf import build_volume_table, volume_integral_quadrature
    from facette.brdf._volume import tabulate_isotropic
    for sigma, n_i in ((0.1, 1.3), (0.4, 1.7)):
        fast = build_volume_table(sigma, n_i, "beckmann", "smith", 10.0, 12, 16, 2)
        ref = tabulate_isotropic(lambda s, o: volume_integral_quadrature(s, o, sigma, n_i, "beckmann", "smith", 12, 16),
                                 10.0, None, 2)
        np.testing.assert_allclose(fast.values, ref.values, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("sigma,n_i", [(0.1, 1.3), (0.3, 1.5), (0.02, 1.05)])
def test_compiled_tables_volume_equals_the_table_interpolated_from_the_angles(sigma, n_i):
    # li_shading_terms' tables volume part runs compiled (facette.brdf._volume_jit); the array form
    # is VolumeTable.at_angles on the angles from the dot products: equal to float32 rounding, on
    # the edges too (normal at the view, light at the normal, behind, grazing)
    from facette.brdf._volume import volume_table_at
    rng = np.random.default_rng(3)
    n = rng.normal(size=(3000, 3))
    n[:, 2] = np.abs(n[:, 2]) * 0.8 - 0.1                 # some facing away from the camera
    n[:3] = [[0, 0, 1], [1, 0, 1e-7], [0.6, 0, 0.8]]
    n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
    s = _random_normals(40, rng)
    s[0], s[1] = [0, 0, 1], [0.6, 0, 0.8]                 # along the view; along the third normal
    s = s.astype(np.float32)
    _, b = li_shading_terms(n, s, sigma, n_i, volume_model="tables")
    cs, co = n @ s.T, n[:, 2:3]
    cs_c, co_c = np.clip(cs, 0, 1), np.clip(co, 0, 1)
    sin_s, sin_o = np.sqrt(1 - cs_c ** 2), np.sqrt(1 - co_c ** 2)
    both = (sin_s > 1e-6) & (sin_o > 1e-6)
    cphi = np.where(both, np.clip((s[None, :, 2] - cs_c * co_c) / np.where(both, sin_s * sin_o, 1), -1, 1), 1)
    vol = volume_table_at(sigma, n_i).at_angles(np.arccos(cs_c), np.arccos(co_c), np.arccos(cphi))
    ref = np.where((cs > 0) & (co > 0), cs_c * vol, 0)
    assert b.dtype == np.float32 and np.all(b[(cs <= 0) | (co <= 0)] == 0)
    np.testing.assert_allclose(b, ref, rtol=5e-5, atol=1e-7)
    # per-pixel lights (near lights): the same values
    _, b_pp = li_shading_terms(n, np.broadcast_to(s, (len(n),) + s.shape).copy(), sigma, n_i, volume_model="tables")
    np.testing.assert_allclose(b_pp, b, rtol=1e-5, atol=1e-6)     # n·s by einsum there: float32 rounding
