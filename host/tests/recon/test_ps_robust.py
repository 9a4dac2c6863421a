"""Robust photometric stereo (RPCA, Wu et al. 2010; per-pixel rank trimming): accuracy on a
glossy sphere with highlights and shadows, shapes, and edge values."""
import numpy as np
import pytest

from facette.methods import photometric_stereo
from facette.recon import near_light_directions, ps_rank_trimmed, ps_rpca_wu2010, ps_woodham1980
from facette.recon._ps_robust import _trim_window, rpca_inexact_alm
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions

L12 = thesis_light_directions()
ALBEDO = np.array([0.6, 0.5, 0.4])
ROBUST = ["rpca_wu2010", "rank_trimmed"]


def cone_lights(m=48, max_theta_deg=50.0, seed=0):
    """m unit directions spread over a cone around the view axis (a DiLiGenT-like dome)."""
    k = np.arange(m) + 0.5
    theta = np.radians(max_theta_deg) * np.sqrt(k / m)
    phi = k * np.pi * (3 - np.sqrt(5))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


L48 = cone_lights()


def plane_images(normal, lights=L12, h=5, w=6):
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    shade = np.maximum(lights @ n, 0)
    imgs = (ALBEDO / np.pi)[None, :] * shade[:, None]
    return np.broadcast_to(imgs[:, None, None, :], (len(lights), h, w, 3)).astype(np.float32).copy(), n


@pytest.mark.parametrize("method", ROBUST)
@pytest.mark.parametrize("lights", [L12, L48], ids=["12 lights", "48 lights"])
def test_lambertian_plane_gives_its_normal_and_albedo(method, lights):
    imgs, n = plane_images([0.2, -0.1, 1.0], lights)
    r = photometric_stereo(imgs, lights, method=method)
    assert r.valid.all() and r.method == method
    assert r.normal.shape == (5, 6, 3) and r.albedo.shape == (5, 6, 3)
    assert r.shadow.shape == r.specular.shape == (5, 6, len(lights))
    assert np.max(angular_error_deg(r.normal, n)) < 0.05
    np.testing.assert_allclose(r.albedo, np.broadcast_to(ALBEDO, r.albedo.shape), rtol=2e-3)


@pytest.mark.parametrize("method", ROBUST)
@pytest.mark.parametrize("lights", [L12, L48], ids=["12 lights", "48 lights"])
def test_glossy_sphere_with_highlights_and_shadows_robust_beats_least_squares(method, lights):
    """The object alone (mask = the sphere, as DiLiGenT's masks): with the flat background in,
    RPCA's nuclear norm favours the plane's one normal and the sphere comes out biased."""
    sc = sphere_on_plane(72, 72)
    imgs = render(sc, lights, "glossy", ks=5.0, noise=0.005, rng=np.random.default_rng(3))
    ls = ps_woodham1980(imgs, lights, mask=sc.sphere)
    rb = photometric_stereo(imgs, lights, method=method, mask=sc.sphere)
    e_ls = angular_error_deg(ls.normal, sc.normals, sc.sphere).mean()
    e_rb = angular_error_deg(rb.normal, sc.normals, sc.sphere).mean()
    assert e_rb < 0.7 * e_ls, (e_rb, e_ls)
    assert rb.specular[sc.sphere].any()          # highlights were left out somewhere


def test_rank_trimmed_leaves_out_the_highlight_and_the_shadow():
    imgs, n = plane_images([0.0, 0.0, 1.0], L48, h=1, w=1)
    imgs[5] *= 20                                # a specular spike
    imgs[9] = 0                                  # a cast shadow
    r = ps_rank_trimmed(imgs, L48)
    assert r.specular[0, 0, 5] and r.shadow[0, 0, 9]
    assert angular_error_deg(r.normal, n).max() < 0.05


def test_trim_window_keeps_the_middle_ranks_and_at_least_three():
    key = np.array([[5.0], [1.0], [3.0], [4.0], [2.0], [9.0], [7.0], [6.0], [8.0], [0.0]])
    ok = np.ones_like(key, bool)
    kept = _trim_window(key, ok, 0.3)[:, 0]      # ranks 3..6 of 0..9 -> values 3, 4, 5, 6
    np.testing.assert_array_equal(np.sort(key[kept, 0]), [3, 4, 5, 6])
    kept = _trim_window(key[:4], ok[:4], 0.45)[:, 0]   # window of one: the middle three instead
    assert kept.sum() == 3 and not kept[0]             # the brightest (5) is the one dropped
    ok[5] = False                                # a missing value ranks top and is never kept
    assert not _trim_window(key, ok, 0.0)[5, 0]


def test_rpca_recovers_a_rank_3_matrix_under_sparse_errors():
    rng = np.random.default_rng(0)
    a = (L48 @ rng.normal(size=(3, 400))).astype(np.float32)
    d = a.copy()
    spikes = rng.random(d.shape) < 0.05
    d[spikes] += 5.0
    observed = rng.random(d.shape) > 0.1
    rec, info = rpca_inexact_alm(d, observed)
    assert info["error"] < 1e-5 and info["rank"] == 3
    assert np.abs(rec - a).max() < 1e-2 * np.abs(a).max()


@pytest.mark.parametrize("method", ROBUST)
def test_black_and_saturated_pixels_are_invalid_and_finite(method):
    imgs, n = plane_images([0.1, 0.2, 1.0], L48)
    imgs[:, 0, 0] = 0.0                          # black under every light
    imgs[:, 0, 1] = np.nan                       # saturated (missing) under every light
    imgs[:, 0, 2] = 1.0                          # every value at the saturation level
    imgs[:-2, 0, 3] = np.inf                     # only two usable values left
    r = photometric_stereo(imgs, L48, method=method, saturation=1.0)
    bad = np.zeros((5, 6), bool)
    bad[0, :4] = True
    np.testing.assert_array_equal(r.valid, ~bad)
    for arr in (r.normal, r.albedo, r.residual):
        assert np.all(np.isfinite(arr))
    assert np.all(r.normal[bad] == 0) and np.all(r.albedo[bad] == 0)
    assert angular_error_deg(r.normal, n, ~bad).max() < 0.05


@pytest.mark.parametrize("method, engine", [("woodham1980", None), ("rank_trimmed", "auto"),
                                            ("rank_trimmed", "arrays"), ("rpca_wu2010", None)])
def test_a_value_missing_in_one_channel_alone_leaves_that_channel_s_albedo_finite(method, engine):
    """Red saturated under two lights where green is not (DiLiGenT reading's highlights): the
    normal comes from green, and red's albedo from red's own usable lights, not NaN."""
    imgs, n = plane_images([0.1, 0.2, 1.0], L12)
    imgs[[2, 5], 1, 1, 0] = np.nan
    r = photometric_stereo(imgs, L12, method=method, options={"engine": engine} if engine else None)
    assert r.valid.all() and np.all(np.isfinite(r.albedo))
    np.testing.assert_allclose(r.albedo[1, 1], ALBEDO, rtol=2e-3)
    assert angular_error_deg(r.normal, n).max() < 0.05


@pytest.mark.parametrize("method", ROBUST)
def test_a_pixel_shadowed_under_every_light_gives_a_finite_unit_normal(method):
    """Only noise is left: the normal is finite and unit (meaningless, documented), never NaN."""
    imgs, _ = plane_images([0.1, 0.2, 1.0], L48)
    imgs[:, 1, 1] = 1e-6 * np.random.default_rng(0).random((len(L48), 3))
    r = photometric_stereo(imgs, L48, method=method)
    assert np.all(np.isfinite(r.normal)) and np.all(np.isfinite(r.albedo))
    if r.valid[1, 1]:
        assert abs(np.linalg.norm(r.normal[1, 1]) - 1) < 1e-4


@pytest.mark.parametrize("method", ROBUST)
def test_a_single_usable_light_leaves_the_pixel_invalid(method):
    imgs, n = plane_images([0.0, 0.1, 1.0], L12)
    imgs[1:, 2, 2] = np.nan
    r = photometric_stereo(imgs, L12, method=method)
    assert not r.valid[2, 2] and np.all(r.normal[2, 2] == 0)
    assert r.valid.sum() == r.valid.size - 1


@pytest.mark.parametrize("method", ROBUST)
def test_three_lights_is_a_clear_error(method):
    imgs, _ = plane_images([0, 0, 1.0], L12[:3])
    with pytest.raises(ValueError, match="at least 4 lights"):
        photometric_stereo(imgs, L12[:3], method=method)


@pytest.mark.parametrize("method", ROBUST)
def test_bad_light_directions_are_a_clear_error(method):
    imgs, _ = plane_images([0, 0, 1.0])
    bad = L12.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        photometric_stereo(imgs, bad, method=method)


def test_four_lights_work():
    imgs, n = plane_images([0.2, 0.1, 1.0], L12[::3])
    for method in ROBUST:
        r = photometric_stereo(imgs, L12[::3], method=method)
        assert r.valid.all() and angular_error_deg(r.normal, n).max() < 0.05


def test_rank_trimmed_takes_per_pixel_light_directions_and_rpca_refuses_them():
    pos = np.array([[300 * np.sin(np.radians(30)) * np.cos(p), 300 * np.sin(np.radians(30)) * np.sin(p),
                     300 * np.cos(np.radians(30))] for p in np.radians(np.arange(0, 360, 30))])
    dirs, _ = near_light_directions(pos, (4, 5), 1.0)
    n = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    imgs = np.maximum(np.einsum("hwmi,i->mhw", dirs, n), 0).astype(np.float32)
    r = ps_rank_trimmed(imgs, dirs)
    assert r.valid.all() and angular_error_deg(r.normal, n).max() < 0.05
    with pytest.raises(ValueError, match="distant lights"):
        ps_rpca_wu2010(imgs, dirs)


def test_rank_trimmed_argument_errors_and_empty_mask():
    imgs, _ = plane_images([0, 0, 1.0])
    with pytest.raises(ValueError, match="trim"):
        ps_rank_trimmed(imgs, L12, trim=0.5)
    with pytest.raises(ValueError, match="rounds"):
        ps_rank_trimmed(imgs, L12, rounds=-1)
    with pytest.raises(ValueError, match="t_shadow"):
        ps_rpca_wu2010(imgs, L12, t_shadow=1.0)
    for method in ROBUST:
        r = photometric_stereo(imgs, L12, method=method, mask=np.zeros((5, 6), bool))
        assert not r.valid.any() and np.all(r.normal == 0)


def test_flat_satin_plate_under_the_symmetric_rig_is_not_tilted_by_noise():
    """Both rings of the rig see a plate facing the camera at one angle each; a broad lobe makes
    the inner ring brighter. Widening the windows by 3 x noise keeps a ring together."""
    h_dirs = L12 + [0, 0, 1]
    h_dirs /= np.linalg.norm(h_dirs, axis=1, keepdims=True)
    lobe = 0.3 * h_dirs[:, 2] ** 40                     # n = +z: n.h per light
    clean = 0.5 / np.pi * L12[:, 2] + lobe
    rng = np.random.default_rng(2)
    imgs = (clean[:, None, None] * (1 + 0.01 * rng.standard_normal((12, 20, 20)))).astype(np.float32)
    n = np.array([0.0, 0.0, 1.0])
    e_ls = np.median(angular_error_deg(ps_woodham1980(imgs, L12).normal, n))
    e_tied = np.median(angular_error_deg(ps_rank_trimmed(imgs, L12).normal, n))
    e_split = np.median(angular_error_deg(ps_rank_trimmed(imgs, L12, noise=0).normal, n))
    assert e_tied < 2 * e_ls + 0.2 and e_tied < 0.5 * e_split, (e_ls, e_tied, e_split)


def test_trim_window_tolerance_keeps_values_tied_with_a_bound():
    key = np.array([[1.0], [2.0], [3.0], [3.02], [5.0], [6.0]])
    ok = np.ones_like(key, bool)
    assert _trim_window(key, ok, 0.2, 3)[:, 0].tolist() == [False, True, True, True, True, False]
    kept = _trim_window(key, ok, 0.4, 2)[:, 0]            # ranks 2..3: 3.0 and 3.02
    assert kept.tolist() == [False, False, True, True, False, False]
    kept = _trim_window(key[:3], ok[:3], 0.4, 1, tol=0.5)[:, 0]   # bound 2.0 widened to 1..3
    assert kept.all()


def test_t_dark_keeps_a_pixel_with_many_cast_shadows_right():
    imgs, n = plane_images([0.1, -0.1, 1.0], L12, h=1, w=1)
    imgs[[0, 1, 2, 3, 4]] = 0                      # five of twelve lights in cast shadow
    plain = ps_rank_trimmed(imgs, L12, t_dark=None)
    dark = ps_rank_trimmed(imgs, L12, t_dark=0.03)
    assert dark.valid.all() and angular_error_deg(dark.normal, n).max() < 0.05
    assert angular_error_deg(plain.normal, n).max() > 1.0    # the window holds shadows
    assert dark.shadow[0, 0, :5].all()
    with pytest.raises(ValueError, match="t_dark"):
        ps_rank_trimmed(imgs, L12, t_dark=1.0)


@pytest.mark.parametrize("lights", [L12, L48, "near"], ids=["12 lights", "48 lights", "per-pixel lights"])
@pytest.mark.parametrize("options", [{}, {"t_dark": None, "rounds": 2}, {"rounds": 0, "trim": 0.2}])
def test_the_compiled_loop_gives_the_array_code_s_result(lights, options):
    # the compiled per-pixel loop (facette.recon._ps_robust_jit) must give what the array code
    # gives, up to float32 sums (a value tied with a window's bound to the last bit may fall on the
    # other side: a few pixels in 10 000), on highlights, cast shadows, saturated and black pixels,
    # for distant and per-pixel lights
    sc = sphere_on_plane(64, 64)
    near = isinstance(lights, str)
    imgs = render(sc, L12 if near else lights, "glossy", ks=5.0, noise=0.01, rng=np.random.default_rng(4))
    if near:                  # the rig's lights a few degrees off, differently at each pixel
        tilt = np.random.default_rng(6).normal(0, 0.03, (64, 64, 1, 3))
        lights = L12[None, None] + tilt
        lights /= np.linalg.norm(lights, axis=-1, keepdims=True)
    imgs[:, 10:14, 10:14] = 0.0                              # black
    imgs[: len(lights) // 2, 20:24, 20:24] *= 0.02           # cast shadows under half the lights
    sat = np.percentile(imgs, 99.5)
    a = ps_rank_trimmed(imgs, lights, saturation=sat, **options)
    b = ps_rank_trimmed(imgs, lights, saturation=sat, engine="arrays", **options)
    assert (a.valid == b.valid).mean() > 0.999 and not a.valid[10:14, 10:14].any()
    both = a.valid & b.valid
    na, nb = a.normal[both].astype(np.float64), b.normal[both].astype(np.float64)
    ang = np.degrees(2 * np.arcsin(np.clip(np.linalg.norm(na - nb, axis=-1) / 2, 0, 1)))
    assert np.percentile(ang, 99.5) < 1e-3 and np.isfinite(a.normal).all()
    for name in ("shadow", "specular"):
        assert (getattr(a, name) == getattr(b, name)).mean() > 0.999, name
    np.testing.assert_allclose(a.albedo[both], b.albedo[both], rtol=1e-3, atol=1e-6)
    assert len(a.info["median_change_deg"]) == options.get("rounds", 1)
    with pytest.raises(ValueError, match="engine"):
        ps_rank_trimmed(imgs, L12, engine="numba")
