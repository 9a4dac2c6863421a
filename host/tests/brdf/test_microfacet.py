import numpy as np
import pytest

from facette.brdf import (distribution_d, gaussian_norm_exact, gaussian_norm_rational_tsb2014, masking_g,
                          microfacet_quadrature, sample_microfacet_normals, smith_g1)


def hemisphere_grid(n_theta=2000, n_phi=256):
    """Brute-force midpoint grid in (θ, φ) — independent of the library's own nodes."""
    th = (np.arange(n_theta) + 0.5) * (np.pi / 2) / n_theta
    ph = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    T, P = np.meshgrid(th, ph, indexing="ij")
    m = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    dw = np.sin(T) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)
    return m, dw


@pytest.mark.parametrize("dist,sigma", [("beckmann", 0.1), ("beckmann", 0.8), ("ggx", 0.1), ("ggx", 0.8),
                                        ("gaussian", 0.1), ("gaussian", 1.0), ("beckmann", (0.1, 0.4)),
                                        ("ggx", (0.5, 0.15))])
def test_distributions_are_normalised_in_projected_area(dist, sigma):
    m, dw = hemisphere_grid()
    total = np.sum(distribution_d(m, sigma, dist) * m[..., 2] * dw)
    # GGX keeps a little mass beyond the grid's last ring for wide σ; the others are exact
    assert total == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("dist,sigma", [("beckmann", 0.3), ("ggx", 0.3), ("beckmann", (0.2, 0.5)), ("ggx", (0.6, 0.2))])
def test_smith_masking_preserves_projected_area_eq_3_16(dist, sigma):
    m, dw = hemisphere_grid(1500, 256)
    d = distribution_d(m, sigma, dist)
    for theta, phi in ((0.3, 0.0), (1.0, 0.7), (1.4, 2.0)):
        u = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        um = np.maximum(0, m @ u)
        lhs = smith_g1(u, sigma, dist) * np.sum(d * um * dw)
        assert lhs == pytest.approx(u[2], rel=5e-3)


def test_gaussian_normalisation_rational_fit_is_good_except_for_small_sigma():
    for s in (0.1, 0.3, 0.6, 1.0, 2.0):
        assert gaussian_norm_rational_tsb2014(s) == pytest.approx(gaussian_norm_exact(s), rel=1.1e-3)
    # below σ ≈ 0.05 eq 3.59 tends to 2π·K2/K'0·σ² (1 % high), not to the exact 2πσ²
    assert gaussian_norm_exact(1e-4) == pytest.approx(2 * np.pi * 1e-8, rel=1e-6)
    assert gaussian_norm_rational_tsb2014(1e-4) / gaussian_norm_exact(1e-4) > 1.009


@pytest.mark.parametrize("dist,sigma", [("beckmann", 0.2), ("ggx", 0.2), ("gaussian", 0.2), ("beckmann", (0.1, 0.3))])
def test_importance_samples_follow_d_cos(dist, sigma):
    rng = np.random.default_rng(3)
    m, w = sample_microfacet_normals(rng.random(200_000), rng.random(200_000), sigma, dist)
    grid, dw = hemisphere_grid(1500, 128)
    pdf = distribution_d(grid, sigma, dist) * grid[..., 2] * dw
    for f in (lambda v: v[..., 2] ** 4, lambda v: v[..., 0] ** 2, lambda v: v[..., 1] ** 2):
        assert np.mean(f(m) * w) == pytest.approx(np.sum(f(grid) * pdf), rel=1e-2, abs=1e-4)


def test_quadrature_nodes_integrate_smooth_functions():
    for dist in ("beckmann", "ggx", "gaussian"):
        m, w = microfacet_quadrature(0.25, dist, 48, 48)
        grid, dw = hemisphere_grid(1500, 128)
        pdf = distribution_d(grid, 0.25, dist) * grid[..., 2] * dw
        assert np.sum(w * m[:, 2] ** 3) == pytest.approx(np.sum(pdf * grid[..., 2] ** 3), rel=2e-3)
    m, w = microfacet_quadrature(0.0, "beckmann")
    np.testing.assert_array_equal(m, [[0, 0, 1]])


def test_masking_is_symmetric_bounded_and_zero_for_hidden_facets():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(3, 500, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    s, o, m = v[0], v[1], v[2]
    m[:, 2] = np.abs(m[:, 2])
    for masking in ("vcavity", "smith"):
        g = masking_g(s, o, m, 0.4, "beckmann", masking)
        np.testing.assert_allclose(g, masking_g(o, s, m, 0.4, "beckmann", masking))
        assert np.all((g >= 0) & (g <= 1))
        hidden = (np.sum(s * m, -1) <= 0) | (np.sum(o * m, -1) <= 0) | (s[:, 2] <= 0) | (o[:, 2] <= 0)
        assert np.all(g[hidden] == 0)


def test_errors_say_what_is_wrong():
    with pytest.raises(ValueError, match="distribution"):
        distribution_d([0, 0, 1], 0.1, "phong")
    with pytest.raises(ValueError, match="isotropic only"):
        distribution_d([0, 0, 1], (0.1, 0.2), "gaussian")
    with pytest.raises(ValueError, match="roughness"):
        distribution_d([0, 0, 1], -0.1, "beckmann")
    with pytest.raises(ValueError, match="masking"):
        masking_g([0, 0, 1], [0, 0, 1], [0, 0, 1], 0.1, "beckmann", "heitz")
