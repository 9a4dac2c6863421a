import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import facette.brdf as B


def direction(theta, phi=0.0):
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


S = direction(0.6)
O = np.stack([direction(t, p) for t in (0.0, 0.4, 0.9, 1.3) for p in (0.0, 1.5, 3.0)])


def test_get_returns_each_model_and_rejects_unknown_names():
    for name in ("lambert", "oren_nayar", "cook_torrance", "li"):
        assert callable(B.get(name))
    with pytest.raises(ValueError, match="unknown BRDF model"):
        B.get("phong")


@pytest.mark.parametrize("volume", ["quadrature", "monte_carlo", "table"])
def test_li_with_n_1_and_sigma_0_is_lambert(volume):
    np.testing.assert_allclose(B.brdf_li(S, O, 0.7, 0.0, 1.0, volume=volume), 0.7 / np.pi, rtol=1e-12)
    np.testing.assert_allclose(B.brdf_li(S, O, 0.7, 0.0, 1.0, volume=volume), B.lambert(S, O, 0.7), rtol=1e-12)


def test_li_with_kd_0_is_the_specular_microfacet_model():
    for dist, masking in (("beckmann", "smith"), ("ggx", "smith"), ("gaussian", "vcavity")):
        li = B.brdf_li(S, O, 0.0, 0.2, 1.5, dist, masking)
        ct = B.cook_torrance1982(S, O, 0.0, 0.2, 1.5, dist, masking)
        np.testing.assert_allclose(li, ct, rtol=1e-12)
        assert li.max() > 0


def test_li_with_n_1_is_lambertian_microfacets_close_to_oren_nayar():
    # Gaussian + V-cavity single bounce vs the Oren–Nayar qualitative model without L2
    f = B.brdf_li(S, O, 0.8, 0.3, 1.0, "gaussian", "vcavity", interreflection=False)
    on = B.oren_nayar1994(S, O, 0.8, 0.3, interreflection=False)
    # the qualitative model is itself an approximation of this integral (±15 % at grazing)
    np.testing.assert_allclose(f, on, rtol=0.15)
    np.testing.assert_allclose(f[:3], on[:3], rtol=0.03)


def test_per_channel_kd_gives_a_channel_axis_and_matches_scalar_calls():
    kd = [0.2, 0.5, 0.9]
    for name, params in (("lambert", {}), ("oren_nayar", {"sigma": 0.3}),
                         ("cook_torrance", {"sigma": 0.2, "n_i": 1.4}), ("li", {"sigma": 0.2, "n_i": 1.4})):
        f = B.get(name)
        out = f(S, O, kd=kd, **params)
        assert out.shape == (len(O), 3)
        for c, k in enumerate(kd):
            np.testing.assert_allclose(out[:, c], f(S, O, kd=k, **params), rtol=1e-12)


def test_broadcasting_and_horizon():
    s = np.broadcast_to(S, (2, 1, 3))
    o = O.reshape(1, -1, 3)
    assert B.brdf_li(s, o, 0.5, 0.2, 1.3).shape == (2, len(O))
    below = direction(1.8)
    for name, params in (("lambert", {}), ("oren_nayar", {"sigma": 0.3}),
                         ("cook_torrance", {"sigma": 0.2, "n_i": 1.4}), ("li", {"sigma": 0.2, "n_i": 1.4})):
        assert B.get(name)(S, below, kd=0.5, **params) == 0
        assert B.get(name)(below, S, kd=0.5, **params) == 0


@pytest.mark.parametrize("dist,masking", [("beckmann", "smith"), ("ggx", "smith"), ("gaussian", "vcavity"),
                                          ("beckmann", "vcavity")])
def test_volume_evaluations_agree_with_the_quadrature_reference(dist, masking):
    ref = B.volume_integral_quadrature(S, O, 0.25, 1.3, dist, masking, n_theta=128, n_phi=128)
    q = B.volume_integral_quadrature(S, O, 0.25, 1.3, dist, masking)
    mc = B.volume_integral_monte_carlo(S, O, 0.25, 1.3, dist, masking, n_samples=4096, rng=1)
    tb = B.volume_integral_table(S, O, 0.25, 1.3, dist, masking, step_deg=10.0)
    np.testing.assert_allclose(q, ref, rtol=5e-3)
    np.testing.assert_allclose(mc, ref, rtol=0.05)
    np.testing.assert_allclose(tb, ref, rtol=0.05)


def test_monte_carlo_error_follows_the_inverse_square_root_law():
    ref = B.volume_integral_quadrature(S, O, 0.3, 1.3, n_theta=96, n_phi=96)
    errs = []
    for n in (64, 4096):
        runs = np.stack([B.volume_integral_monte_carlo(S, O, 0.3, 1.3, n_samples=n, rng=r) for r in range(8)])
        errs.append(np.sqrt(np.mean((runs - ref) ** 2)))
    assert 4 < errs[0] / errs[1] < 16  # √64 = 8


@pytest.mark.parametrize("dist", ["beckmann", "gaussian"])
def test_approx_formula_tracks_the_reference_inside_its_domain(dist):
    o = np.stack([direction(t, p) for t in (0.0, 0.3, 0.6) for p in (0.0, 3.0)])
    ref = B.volume_integral_quadrature(direction(0.4), o, 0.1, 1.2, dist, "vcavity")
    ap = B.volume_integral_approx(direction(0.4), o, 0.1, 1.2, dist)
    np.testing.assert_allclose(ap, ref, rtol=0.1)


def test_interreflection_is_close_to_the_oren_nayar_two_bounce_term():
    s = direction(0.8)
    o = np.stack([direction(t, np.pi) for t in (0.2, 0.6, 1.0)])
    j = B.interreflection_integral_vcavity(s, o, 0.3, 1.0, "gaussian", n_paths=20000, rng=2)
    beta = np.minimum(0.8, np.array([0.2, 0.6, 1.0]))
    on_l2 = 0.17 * 0.09 / (0.09 + 0.13) * (1 + (2 * beta / np.pi) ** 2)  # cos Δφ = −1
    np.testing.assert_allclose(j / np.pi, on_l2, rtol=0.2)
    assert np.all(B.interreflection_integral_vcavity(s, o, 0.0, 1.3) == 0)


def test_interreflection_is_used_only_where_it_matters():
    base = B.brdf_li(S, O, 0.8, 0.1, 1.2, "beckmann", "vcavity")
    assert np.array_equal(base, B.brdf_li(S, O, 0.8, 0.1, 1.2, "beckmann", "vcavity", interreflection=False))
    rough = B.brdf_li(S, O, 0.8, 0.4, 1.2, "beckmann", "vcavity")
    single = B.brdf_li(S, O, 0.8, 0.4, 1.2, "beckmann", "vcavity", interreflection=False)
    assert np.all(rough >= single) and np.mean(rough / single) > 1.03


def test_bad_arguments_raise_clear_errors():
    with pytest.raises(ValueError, match="K_d"):
        B.brdf_li(S, O, 1.5, 0.1, 1.3)
    with pytest.raises(ValueError, match="diverges"):
        B.brdf_li(S, O, 0.5, 0.1, 1.3, "gaussian", "smith")
    with pytest.raises(ValueError, match="volume"):
        B.brdf_li(S, O, 0.5, 0.1, 1.3, volume="magic")
    with pytest.raises(ValueError, match="3-vectors"):
        B.lambert(np.zeros(2), O, 0.5)
    with pytest.raises(ValueError, match="non-zero"):
        B.lambert(np.zeros(3), O, 0.5)
    with pytest.raises(ValueError, match="isotropic"):
        B.brdf_li(S, O, 0.5, (0.1, 0.3), 1.3, volume="table")
    with pytest.raises(ValueError, match="approx"):
        B.brdf_li(S, O, 0.5, 0.1, 1.3, "ggx", volume="approx")


def test_sub_resolution_roughness_is_a_flat_surface():
    # σ = 5e-324 once gave NaN (1/(π σ²) overflows); below SIGMA_FLAT the surface is flat
    for sg in (5e-324, 1e-200, B.SIGMA_FLAT / 2):
        f = B.brdf_li(S, O, 0.5, sg, 1.3)
        np.testing.assert_array_equal(f, B.brdf_li(S, O, 0.5, 0.0, 1.3))
    assert np.all(np.isfinite(B.brdf_li(S, O, 0.5, 2 * B.SIGMA_FLAT, 1.3)))


def test_interreflection_table_matches_the_simulation():
    s = direction(0.7)
    o = np.stack([direction(t, np.pi) for t in (0.15, 0.5, 0.8)])
    tab = B.build_interreflection_table(0.4, 1.3, "beckmann", 15.0, n_paths=4096)
    sim = B.interreflection_integral_vcavity(s, o, 0.4, 1.3, "beckmann", n_paths=40000, rng=3)
    np.testing.assert_allclose(tab(s, o), sim, rtol=0.12)
    # with volume="table" the LI model reads J from such a table: same BRDF within the MC noise
    f_tab = B.brdf_li(s, o, 0.7, 0.4, 1.3, "beckmann", "vcavity", volume="table", step_deg=15.0)
    f_ref = B.brdf_li(s, o, 0.7, 0.4, 1.3, "beckmann", "vcavity")
    np.testing.assert_allclose(f_tab, f_ref, rtol=0.03)


def test_interreflections_return_lost_energy_without_creating_any():
    # white (K_d = 1) Lambertian facets without interface: single bounce loses what the cavity
    # blocks; the two-bounce term gives most of it back at σ = 0.3 and never more than all
    x, wx = np.polynomial.legendre.leggauss(12)
    xi1 = 0.5 * (x + 1)
    phi = 2 * np.pi * (np.arange(24) + 0.5) / 24
    r = np.sqrt(xi1)[:, None]
    oo = np.stack([r * np.cos(phi), r * np.sin(phi), np.broadcast_to(np.sqrt(1 - xi1)[:, None], (12, 24))],
                  -1).reshape(-1, 3)
    wo = (np.pi * 0.5 * wx[:, None] / 24 * np.ones((1, 24))).reshape(-1)
    for sg, n, gain in ((0.3, 1.0, 0.6), (1.0, 1.0, 0.4), (1.0, 1.5, None), (0.6, 2.5, None)):
        s = direction(0.5)
        single = B.brdf_li(s, oo, 1.0, sg, n, "beckmann", "vcavity", interreflection=False, n_theta=24, n_phi=24)
        j = B.interreflection_vcavity(s, oo, 1.0, sg, n, "beckmann", n_paths=3000)
        a1, a2 = single @ wo, (single + j) @ wo
        assert a2 <= 1.0 + 2e-3
        if gain is not None:  # n_i = 1, K_d = 1: no absorption anywhere, the exact albedo is 1
            assert (a2 - a1) > gain * (1.0 - a1)


def test_grazing_refined_table_is_more_accurate_near_grazing():
    rng = np.random.default_rng(5)
    th = rng.uniform(np.radians(76), np.radians(88), (2, 150))
    ph = rng.uniform(0, 2 * np.pi, 150)
    s = np.stack([np.sin(th[0]), 0 * ph, np.cos(th[0])], -1)
    o = np.stack([np.sin(th[1]) * np.cos(ph), np.sin(th[1]) * np.sin(ph), np.cos(th[1])], -1)
    ref = B.volume_integral_quadrature(s, o, 0.4, 1.5, "beckmann", "smith", n_theta=64, n_phi=64)
    errs = [np.max(np.abs(B.build_volume_table(0.4, 1.5, "beckmann", "smith", 10.0, 24, 32, r)(s, o) - ref) / ref)
            for r in (1, 4)]
    assert errs[1] < errs[0] / 3
    theta = B.build_volume_table(0.4, 1.5, "beckmann", "smith", 10.0, 24, 32, 4).theta
    np.testing.assert_allclose(np.degrees(theta[-4:]), [82.5, 85.0, 87.5, 90.0])


def test_mixed_specular_volume_paths():
    s = direction(0.8)
    o = np.stack([direction(t, np.pi) for t in (0.2, 0.7, 1.2)])
    assert np.all(B.interreflection_mixed_integral_vcavity(s, o, 0.5, 1.0) == 0)  # no interface, no mirror
    j1 = B.interreflection_mixed_integral_vcavity(s, o, 0.5, 1.5, n_paths=4000, rng=4)
    back = B.interreflection_mixed_integral_vcavity(o, s, 0.5, 1.5, n_paths=4000, rng=4)
    assert np.all(j1 > 0)
    np.testing.assert_allclose(j1, back, rtol=1e-12)  # reciprocal by construction
    # with an interface the term is linear in κ; at K_d = 0.5, n_i = 1.5 it rivals the volume–volume one
    k = B.li_kd_factor(0.5, 1.5)
    jvv = B.interreflection_integral_vcavity(s, o, 0.5, 1.5, n_paths=4000, rng=4)
    assert 0.2 < np.mean(k * j1) / np.mean(k * k * jvv) < 5


def test_approx_formula_is_clipped_where_it_would_go_negative():
    # b(σ = 0) = −1.252/57.04 < 0 makes T̄ < 0 at grazing: the raw formula is negative there
    s, o = direction(np.radians(89.9)), direction(0.5, np.pi)
    a, b, c = B._volume.approx_coefficients(0.0, 1.5, "beckmann")
    assert b < 0
    assert B.volume_integral_approx(s, o, 0.0, 1.5, "beckmann") == 0.0
    assert B.volume_integral_approx(direction(0.3), direction(0.4, 1.0), 0.0, 1.5, "beckmann") > 0


# -- laws of the LI model as property tests: reciprocity, energy, positivity, finiteness at edges
CONFIGS = [("beckmann", "smith"), ("ggx", "smith"), ("beckmann", "vcavity"), ("gaussian", "vcavity")]
angle = st.floats(0.0, np.radians(89.9))
azimuth = st.floats(0.0, 2 * np.pi)
sigma = st.floats(0.0, 2.0)
n_i = st.floats(1.0, 2.5)
kd = st.floats(0.0, 1.0)
config = st.sampled_from(CONFIGS)


@settings(max_examples=40, deadline=None)
@given(angle, angle, azimuth, sigma, n_i, kd, config)
def test_reciprocity_and_non_negativity(ts, to, phi, sg, n, k, cfg):
    s, o = direction(ts), direction(to, phi)
    f = B.brdf_li(s, o, k, sg, n, *cfg, interreflection=False, n_theta=24, n_phi=24)
    g = B.brdf_li(o, s, k, sg, n, *cfg, interreflection=False, n_theta=24, n_phi=24)
    assert np.isfinite(f) and f >= 0
    assert f == pytest.approx(g, rel=1e-9, abs=1e-12)


@settings(max_examples=15, deadline=None)
@given(angle, sigma, n_i, config)
def test_directional_albedo_is_at_most_one(ts, sg, n, cfg):
    # K_d = 1 is the worst case; the albedo quadrature itself is good to ~1e-3
    rho = B.directional_albedo(direction(ts), 1.0, sg, n, *cfg, n_theta=24, n_phi=24)
    assert 0 <= rho <= 1 + 2e-3


EDGE_SIGMA = [0.0, 1e-6, 2.0]
EDGE_N = [1.0, 1 + 1e-9, 2.5]


@pytest.mark.parametrize("cfg", CONFIGS)
@pytest.mark.parametrize("sg", EDGE_SIGMA)
@pytest.mark.parametrize("n", EDGE_N)
def test_finite_at_the_edges_of_the_parameter_box(cfg, sg, n):
    thetas = [0.0, 0.7, np.radians(89.999), np.pi / 2 - 1e-9]
    s = np.stack([direction(t) for t in thetas])[:, None, :]
    o = np.stack([direction(t, p) for t in thetas for p in (0.0, np.pi)])[None, :, :]
    for k in (0.0, 1.0):
        for volume in ("quadrature", "monte_carlo"):
            f = B.brdf_li(s, o, k, sg, n, *cfg, volume=volume, n_samples=32) if volume == "monte_carlo" \
                else B.brdf_li(s, o, k, sg, n, *cfg, n_theta=16, n_phi=16)
            assert np.all(np.isfinite(f)) and np.all(f >= 0), (volume, k)
        if cfg[0] != "ggx":
            fa = B.brdf_li(s, o, [0.0, 1.0], sg, n, *cfg, volume="approx")
            assert np.all(np.isfinite(fa))


def test_finite_for_the_table_at_the_edges():
    s = direction(np.pi / 2 - 1e-9)
    o = np.stack([direction(t) for t in (0.0, np.pi / 2 - 1e-9)])
    for sg in (0.0, 1e-6, 2.0):
        f = B.brdf_li(s, o, 1.0, sg, 1 + 1e-9, volume="table", step_deg=15.0)
        assert np.all(np.isfinite(f))


@settings(max_examples=40, deadline=None)
@given(angle, angle, azimuth, sigma, n_i, kd, st.sampled_from(["beckmann", "gaussian"]))
def test_approx_formula_is_reciprocal_finite_and_non_negative(ts, to, phi, sg, n, k, dist):
    s, o = direction(ts), direction(to, phi)
    f = B.brdf_li(s, o, k, sg, n, dist, "vcavity", volume="approx")
    g = B.brdf_li(o, s, k, sg, n, dist, "vcavity", volume="approx")
    assert np.isfinite(f) and f == pytest.approx(g, rel=1e-9, abs=1e-12)
    assert f >= 0  # eq 3.49–3.57 dips below 0 outside its fit box (σ → 0, σ ≈ 2): clipped


@pytest.mark.parametrize("sigma", [1e-3, 0.05, 0.3, 2.0])
@pytest.mark.parametrize("n_i", [1.0, 1.0001, 1.5, 3.0])
def test_compiled_beckmann_smith_lobe_equals_the_array_form(sigma, n_i):
    """li_specular's compiled path (Beckmann, Smith) against its numpy form, on directions below,
    at and above the horizon, normal and grazing, and a half vector of zero length."""
    from facette.brdf._models import _li_specular_arrays, prepare_directions
    rng = np.random.default_rng(3)
    s, o = rng.normal(size=(4000, 3)), rng.normal(size=(4000, 3))
    s[:3], o[:3] = [0, 0, 1], [[0, 0, 1], [1, 0, 0], [1, 0, 1e-9]]
    s[3], o[3] = [1, 0, 1e-9], [-1, 0, 1e-9]
    su, ou = prepare_directions(s, o)
    got = B.li_specular(s.reshape(40, 100, 3), o.reshape(40, 100, 3), sigma, n_i).ravel()
    ref = _li_specular_arrays(su, ou, sigma, n_i, "beckmann", "smith")
    assert np.isfinite(got).all()
    assert np.array_equal(got > 0, ref > 0)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=0)
    # prepared=True (the BRDF fit's directions, normalised once): the same values, bit for bit
    np.testing.assert_array_equal(B.li_specular(su, ou, sigma, n_i, prepared=True), got)


@pytest.mark.parametrize("sigma", [0.01, 0.1, 0.3, 1.0, 2.0])
def test_the_compiled_smith_g1_skips_its_exp_and_erfc_only_where_they_give_one(sigma):
    """smith_g1_beckmann returns 1.0 without exp and erfc above a = G1_ONE_ABOVE: there the full
    formula gives 1.0 to the last bit too; so does the tabulated G_1, with a derivative of 0."""
    import math
    from facette.brdf._lobe_jit import G1_ONE_ABOVE, SMITH_G1_TABLE, smith_g1_beckmann, smith_g1_dlog_tabulated
    for c in np.linspace(1e-4, 1 - 1e-9, 3001):
        sn = math.sqrt(1 - c * c)
        a = c / (sigma * sn)
        full = 1.0 / (1.0 + 0.5 * (math.exp(-a * a) / (a * math.sqrt(math.pi)) - math.erfc(a)))
        assert smith_g1_beckmann(c, sigma) == full
        if a > G1_ONE_ABOVE:
            assert full == 1.0 and smith_g1_dlog_tabulated(c, sigma, SMITH_G1_TABLE) == (1.0, 0.0)


@pytest.mark.parametrize("sigma", [0.005, 0.05, 0.3, 2.0])
def test_the_tabulated_smith_g1_is_the_formula(sigma):
    """The per-pixel solve's G_1 comes from a table over a = c / (σ sin θ): within 1e-7 of the
    formula, from grazing to the normal; d ln G_1 / dc (the tabulated G_1's own) within 1e-3 of
    the formula's G_1 e^(−a²) σ / (2√π c² sin θ), on the scale a / (c sin² θ) of d ln G_1 / dc."""
    import math
    from facette.brdf._lobe_jit import SMITH_G1_TABLE, smith_g1_beckmann, smith_g1_dlog_tabulated
    for c in np.concatenate([np.geomspace(1e-6, 1e-2, 200), np.linspace(1e-2, 1 - 1e-9, 20001),
                             1 - np.geomspace(1e-9, 1e-2, 200)]):
        sn = math.sqrt(1 - c * c)
        a = c / (sigma * sn)
        g, dlog = smith_g1_dlog_tabulated(c, sigma, SMITH_G1_TABLE)
        want = smith_g1_beckmann(c, sigma)
        assert abs(g - want) <= 1e-7 * want
        exact = want * math.exp(-a * a) * sigma / (2 * math.sqrt(math.pi) * c * c * sn) if a < 6 else 0.0
        assert abs(dlog - exact) <= 1e-3 * a / (c * sn * sn)
    assert smith_g1_dlog_tabulated(0.0, sigma, SMITH_G1_TABLE) == (0.0, 0.0)
    assert smith_g1_dlog_tabulated(1.0, sigma, SMITH_G1_TABLE) == (1.0, 0.0)
