"""recon._rti: PTM and HSH relighting functions fitted per pixel."""
import numpy as np
import pytest

from facette.recon import (fit_hsh, fit_ptm_lrgb, fit_relight_error, hsh_basis, near_light_directions,
                           ptm_basis, relight_error, relight_hsh, relight_ptm)
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()


def _random_lights(m, seed=0):
    rng = np.random.default_rng(seed)
    th, ph = rng.uniform(0.1, 1.3, m), rng.uniform(0, 2 * np.pi, m)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)


def test_ptm_basis_values():
    np.testing.assert_allclose(ptm_basis([0.6, -0.8, 0.0]), [0.36, 0.64, -0.48, 0.6, -0.8, 1.0])
    assert ptm_basis(np.zeros((4, 5, 3))).shape == (4, 5, 6)
    with pytest.raises(ValueError, match="shape"):
        ptm_basis([1.0, 0.0])


def test_hsh_basis_is_orthonormal_on_the_hemisphere():
    """Gautron et al. 2004: the HSH are orthonormal over the upper hemisphere."""
    n = 400
    t = (np.arange(n) + 0.5) / n * (np.pi / 2)
    p = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    tt, pp = np.meshgrid(t, p, indexing="ij")
    d = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
    b = hsh_basis(d, 3).reshape(-1, 9)
    dw = (np.sin(tt) * (np.pi / 2 / n) * (np.pi / n)).ravel()
    gram = (b * dw[:, None]).T @ b
    np.testing.assert_allclose(gram, np.eye(9), atol=2e-3)
    with pytest.raises(ValueError, match="order"):
        hsh_basis([0, 0, 1.0], 4)


def test_ptm_fit_recovers_a_polynomial_and_its_colour():
    rng = np.random.default_rng(3)
    lights = _random_lights(20)
    h, w = 6, 7
    a = rng.normal(0, 0.1, (h, w, 6))
    a[..., 5] += 0.5
    rgb = rng.uniform(0.2, 1, (h, w, 3))
    rgb /= rgb.max(-1, keepdims=True)
    lum = np.einsum("hwk,mk->mhw", a, ptm_basis(lights))
    imgs = lum[..., None] * rgb * 4.0
    fit = fit_ptm_lrgb(imgs, lights, white=4.0)
    np.testing.assert_allclose(fit.coeffs, a, atol=1e-4)   # Tikhonov bias (_RCOND)
    np.testing.assert_allclose(fit.rgb, rgb, atol=1e-12)
    assert fit.valid.all() and fit.white == 4.0
    np.testing.assert_allclose(relight_ptm(fit, lights[3]), np.maximum(imgs[3], 0), atol=1e-4)


def test_hsh_fit_recovers_coefficients_per_channel():
    rng = np.random.default_rng(4)
    lights = _random_lights(25, seed=1)
    c = rng.normal(0, 0.1, (5, 4, 3, 9))
    c[..., 0] += 1.0
    imgs = np.einsum("hwck,mk->mhwc", c, hsh_basis(lights, 3)) * 2.0
    fit = fit_hsh(imgs, lights, order=3, white=2.0)
    np.testing.assert_allclose(fit.coeffs, c, atol=1e-4)   # Tikhonov bias (_RCOND)
    assert relight_error(lambda d: relight_hsh(fit, d), imgs, lights, np.ones((5, 4), bool)) < 1e-4


def test_fit_relight_error_is_relight_error_and_samples_rows_of_large_maps():
    """Every row: the same figure as relight_error. Above max_pixels: the same figure on
    every k-th pair of rows, k the smallest step that keeps at most max_pixels."""
    rng = np.random.default_rng(5)
    lights = _random_lights(14, seed=2)
    h, w = 24, 5
    imgs = rng.uniform(0.1, 1.0, (14, h, w, 3))
    imgs[:, 4::6] *= rng.uniform(0.1, 3.0, (14, 4, w, 3))   # rows the sample leaves out fit worse
    imgs[2, 3, 1, 0] = np.nan
    mask = rng.uniform(size=(h, w)) > 0.2
    for fit, render in ((fit_ptm_lrgb(imgs, lights, mask=mask), relight_ptm),
                        (fit_hsh(imgs, lights, order=2, mask=mask), relight_hsh)):
        whole = relight_error(lambda d: render(fit, d), imgs, lights, mask)
        assert fit_relight_error(fit, imgs, lights, mask, max_pixels=None) == pytest.approx(whole, rel=1e-12)
        assert fit_relight_error(fit, imgs, lights, mask, max_pixels=h * w) == pytest.approx(whole, rel=1e-12)
        rows = np.zeros(h, bool)
        rows[0::6] = rows[1::6] = True             # 24×5 px at ≤ 40 px: every 3rd pair of rows
        sub = relight_error(lambda d: render(fit, d), imgs, lights, mask & rows[:, None])
        assert fit_relight_error(fit, imgs, lights, mask, max_pixels=40) == pytest.approx(sub, rel=1e-12)
        assert sub < 0.9 * whole


def test_the_relighting_error_s_sample_is_a_budget_of_values():
    """By default the rows are sampled down to RELIGHT_ERROR_VALUES values (pixels × lights): a
    DiLiGenT crop (316 × 252 px) every row under 12 lights, every other pair under 96."""
    from facette.recon import RELIGHT_ERROR_VALUES, relight_error_step
    assert relight_error_step(252, 316, 12) == 2 and relight_error_step(252, 316, 96) == 4
    assert relight_error_step(1424, 2144, 12) == 12        # 12 MP scan's maps: every 6th pair
    for m in (4, 12, 96):            # the values summed: within the budget, and not far under it
        summed = len(range(0, 1424, relight_error_step(1424, 2144, m))) * 2 * 2144 * m
        assert 0.5 * RELIGHT_ERROR_VALUES < summed <= 1.1 * RELIGHT_ERROR_VALUES
    assert relight_error_step(1424, 2144, 96, max_pixels=None) == 2


def test_near_lights_per_pixel_directions_and_missing_values():
    """Per-pixel light directions (H, W, m, 3); NaN samples and lights below the horizon are
    left out of each pixel's fit; a pixel with fewer usable lights than terms is invalid."""
    h, w = 8, 9
    lights = _random_lights(16, seed=2)
    dirs, _ = near_light_directions(lights * 60.0, (h, w), 1.0)
    a = np.zeros((h, w, 6))
    a[..., 5], a[..., 3] = 0.5, 0.2
    lum = np.einsum("hwk,hwmk->mhw", a, ptm_basis(dirs))
    imgs = np.repeat(lum[..., None], 3, axis=-1)
    imgs[:5, 0, 0] = np.nan                    # 11 usable lights left: still fitted exactly
    imgs[:12, 1, 1] = np.nan                   # 4 left: fewer than 6 terms
    dirs = dirs.copy()
    dirs[2, 2, :3] = [0.0, 0.6, -0.8]          # three lights below pixel (2, 2)'s horizon
    fit = fit_ptm_lrgb(imgs, dirs, white=1.0)
    assert fit.valid[0, 0] and not fit.valid[1, 1] and fit.valid[2, 2]
    np.testing.assert_allclose(fit.coeffs[0, 0], a[0, 0], atol=1e-4)
    np.testing.assert_allclose(fit.coeffs[3:, 3:], a[3:, 3:], atol=1e-4)
    assert np.all(fit.coeffs[1, 1] == 0)
    assert np.isfinite(relight_ptm(fit, dirs[:, :, 0])).all()


def test_black_pixels_and_bad_arguments():
    imgs = np.zeros((12, 3, 4, 3))
    imgs[:, 0, 0] = 1.0
    fit = fit_ptm_lrgb(imgs, L)
    assert fit.valid[0, 0] and not fit.valid[1, 1] and np.all(fit.coeffs[1, 1] == 0)
    assert np.isfinite(fit.coeffs).all() and np.isfinite(fit.rgb).all()
    with pytest.raises(ValueError, match=r"\(m, H, W, 3\)"):
        fit_ptm_lrgb(np.zeros((12, 3, 4)), L)
    with pytest.raises(ValueError, match="light directions"):
        fit_hsh(imgs, L[:5])
    with pytest.raises(ValueError, match="white"):
        fit_hsh(imgs, L, white=-1.0)
    with pytest.raises(ValueError, match="order"):
        fit_hsh(imgs, L, order=5)


def test_two_rings_of_lights_give_a_minimum_norm_hsh_not_cancelling_giants():
    """The rig's lights lie on two rings (15° and 30°): HSH order 3 has three zonal terms and
    only two elevations to tell them apart. Near lights make the system barely determined;
    the fit must stay small (it is quantised to bytes for RTIViewer) and still relight."""
    from facette.recon.synthetic import sphere_on_plane
    sc = sphere_on_plane(32, 32)
    dirs, fall = near_light_directions(L * 150.0, (32, 32), 1.0)
    shade = np.maximum(np.einsum("hwmi,hwi->mhw", dirs, sc.normals), 0)
    imgs = 0.5 / np.pi * shade[..., None] * np.ones(3)
    imgs = imgs + np.random.default_rng(5).normal(0, 0.002, imgs.shape)      # 1 % noise
    fit = fit_hsh(imgs, dirs, order=3, mask=sc.mask)
    assert np.abs(fit.coeffs).max() < 3                 # 1.2 here; a plain solve gives 76
    assert relight_error(lambda d: relight_hsh(fit, d), imgs, dirs, sc.mask) < 0.05


def _ridge_fit(basis_rows, y):
    """The per-pixel fit of the module notes, one pixel at a time: (BᵀB + 1e-6 tr(BᵀB) I) x = Bᵀy."""
    a = basis_rows.T @ basis_rows
    a = a + 1e-6 * np.trace(a) * np.eye(a.shape[0])
    return np.linalg.solve(a, basis_rows.T @ y)


def test_shared_and_per_pixel_solves_equal_a_pixel_by_pixel_fit(monkeypatch):
    """Far lights: pixels with every light known share one inverse, the others get their own
    solve; both, over several blocks on two threads, equal the fit done pixel by pixel."""
    import facette.recon._rti as rti

    monkeypatch.setattr(rti, "_BLOCK", 16)
    rng = np.random.default_rng(3)
    d = _random_lights(12, seed=5)
    d[11] = [0.6, 0.0, -0.8]                       # below the horizon: never used
    m, h, w = 12, 7, 9
    images = rng.uniform(0.05, 1.0, (m, h, w, 3)).astype(np.float32)
    holes = rng.random((m, h, w)) < 0.08           # about half of the pixels miss a light
    images[holes, rng.integers(0, 3, holes.sum())] = np.nan
    images[:, 0, 0] = np.nan                       # no light known
    images[:4, 0, 1] = np.nan                      # 7 of 11 usable lights: fewer than 9 HSH terms
    assert 0 < np.isnan(images).any(axis=(0, 3)).mean() < 0.9
    hsh = fit_hsh(images, d, order=3, white=1.0)
    ptm = fit_ptm_lrgb(images, d, white=1.0)
    for i in range(h):
        for j in range(w):
            e = images[:, i, j].astype(np.float64)
            use = np.isfinite(e).all(axis=1) & (d[:, 2] > 0)
            assert hsh.valid[i, j] == (use.sum() >= 9)
            if use.sum() >= 9:
                want = _ridge_fit(hsh_basis(d[use], 3), e[use]).T
                np.testing.assert_allclose(hsh.coeffs[i, j], want, rtol=1e-6, atol=2e-6)   # float32 solve and storage
            else:
                assert not hsh.coeffs[i, j].any()
            known = np.isfinite(e).all(axis=1)
            if use.sum() >= 6 and known.any():
                total = e[known].sum(axis=0)
                rgb = total / total.max()
                lum = e @ rgb / (rgb @ rgb)
                want = _ridge_fit(ptm_basis(d[use]), lum[use])
                np.testing.assert_allclose(ptm.rgb[i, j], rgb, rtol=1e-6)
                np.testing.assert_allclose(ptm.coeffs[i, j], want, rtol=1e-6, atol=2e-6)


@pytest.mark.parametrize("n, q, dtype", [(0, 99.0, np.float64), (1, 99.0, np.float64), (500, 99.0, np.float32),
                                         (200_003, 99.0, np.float64), (200_003, 99.0, np.float32),
                                         (200_003, 50.0, np.float32), (120_000, 100.0, np.float64)])
def test_white_level_from_the_top_values_is_numpys_percentile(n, q, dtype):
    from facette.recon._rti import _top_percentile

    rng = np.random.default_rng(n)
    v = rng.lognormal(0, 1, n).astype(dtype)
    blocks = np.array_split(v, 7)
    got = _top_percentile(lambda a: blocks[a], range(7), q)
    assert got == (float(np.percentile(v, q)) if n else 1.0)


def test_white_level_when_the_sample_misses_the_top():
    """Every 37th value (the sample) is large, the others small: the bound from the sample is
    too high and the full set is used, still numpy's percentile."""
    from facette.recon._rti import _top_percentile

    v = np.full(37 * 4000, 0.5)
    v[::37] = 10.0 + np.arange(4000)
    v[1::37] = np.linspace(0, 1, 4000)
    got = _top_percentile(lambda a: v if a == 0 else v[:0], range(2), 99.0)
    assert got == float(np.percentile(v, 99.0))


def test_compiled_ptm_colour_pass_gives_numpys_values():
    from facette.recon._rti_jit import ptm_colour_block
    rng = np.random.default_rng(1)
    for dtype in (np.float32, np.float64):
        e = rng.lognormal(size=(12, 500, 3)) * rng.choice([1, -1, 0], p=[.9, .05, .05], size=(12, 500, 3))
        e = e.astype(dtype)
        e[rng.random(e.shape) < 0.1] = np.nan
        e[:, 20], e[3, 30, 1] = np.nan, np.inf          # a pixel never known; an infinite channel
        # the numpy form it replaces (float64 sums over the lights in order)
        finite = np.isfinite(e).all(-1)
        known = np.where(finite[..., None], e, np.zeros((), dtype))
        total = known.sum(axis=0, dtype=np.float64)
        pk = total.max(axis=1)
        c = np.where(pk[:, None] > 0, np.clip(total, 0, None) / np.where(pk > 0, pk, 1)[:, None], 0)
        lum = (known[..., 0] * c[:, 0] + known[..., 1] * c[:, 1] + known[..., 2] * c[:, 2]) \
            / np.maximum((c ** 2).sum(axis=1), 1e-300)
        lum[~finite] = np.nan
        rgb, peak, got = np.zeros((600, 3)), np.zeros(600), np.zeros((12, 600))
        ptm_colour_block(e, rgb, peak, got, 100)                # pixels 100 .. 599
        np.testing.assert_array_equal(rgb[100:], c)
        np.testing.assert_array_equal(peak[100:], pk)
        np.testing.assert_array_equal(got[:, 100:], lum)
        assert not rgb[:100].any()


@pytest.mark.parametrize("fit_fn", [lambda i, l, e: fit_ptm_lrgb(i, l, encoding=e),
                                    lambda i, l, e: fit_hsh(i, l, 3, encoding=e)])
def test_srgb_fit_shows_the_encoded_photographs_and_relights_to_linear(fit_fn):
    """encoding="srgb": what a viewer shows (display_*) is close to the sRGB encoding of
    images / white, and relight_* gives the images' linear values back."""
    from facette.recon import display_hsh, display_ptm, relight_hsh, relight_ptm, srgb_decode, srgb_encode
    lights = thesis_light_directions()
    sc = sphere_on_plane(40, 48)
    imgs = render(sc, lights, "matte")
    fit = fit_fn(imgs, lights, "srgb")
    ptm = hasattr(fit, "rgb")
    show, relight = (display_ptm, relight_ptm) if ptm else (display_hsh, relight_hsh)
    num = den = num_lin = den_lin = 0.0
    for img, d in zip(imgs, lights):
        want = srgb_encode(img / fit.white)
        num += ((show(fit, d) - want)[sc.mask] ** 2).sum()
        den += (want[sc.mask] ** 2).sum()
        num_lin += ((relight(fit, d) - img)[sc.mask] ** 2).sum()
        den_lin += (img[sc.mask] ** 2).sum()
    assert np.sqrt(num / den) < 0.06
    assert np.sqrt(num_lin / den_lin) < 0.12
    np.testing.assert_allclose(srgb_decode(srgb_encode(np.linspace(0, 1, 11))), np.linspace(0, 1, 11), atol=1e-12)


def test_unknown_encoding_is_refused():
    lights = thesis_light_directions()
    imgs = render(sphere_on_plane(8, 8), lights, "matte")
    with pytest.raises(ValueError, match="encoding"):
        fit_hsh(imgs, lights, 3, encoding="gamma")
