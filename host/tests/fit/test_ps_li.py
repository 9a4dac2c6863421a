"""ps_li_alternating (BRDF-aware photometric stereo) on scenes from an independent renderer
(Mitsuba 3, small and few samples per pixel), and its edges."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.fit import LI_VOLUME_MODEL, fit_li_per_pixel_kd, ps_li_alternating
from facette.methods import photometric_stereo
from facette.recon import ps_hierarchical_tautzia2016
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("mitsuba")


def _err(n, truth, mask):
    return np.degrees(np.arccos(np.clip(np.sum(n * truth, -1), -1, 1)))[mask]


def test_glossy_sphere_beats_least_squares_by_a_clear_margin(cache):
    d = render_scene("sphere", "paint_0.10", size=64, spp=16, cache_dir=cache)
    sel = binary_erosion(d["mask"])
    ls = photometric_stereo(d["images"], d["light_dirs"], method="woodham1980", mask=d["mask"])
    r = photometric_stereo(d["images"], d["light_dirs"], method="li_alternating", mask=d["mask"])
    e_ls, e_li = _err(ls.normal, d["normals"], sel).mean(), _err(r.normal, d["normals"], sel).mean()
    assert e_li < 0.5 * e_ls, (e_li, e_ls)
    last = r.info["rounds"][-1]
    assert abs(last["sigma"] - 0.10) < 0.03 and abs(last["n_i"] - 1.30) < 0.06
    # albedo is K_d, a reflectance: the renderer's diffuse_reflectance
    np.testing.assert_allclose(np.median(r.albedo[sel], axis=0), d["params"]["kd"], rtol=0.08)
    lv = r.info["levels"]
    assert lv["lambertian"]["pixels"] + lv["brdf_aware"]["pixels"] == int(r.valid.sum())
    assert all("median_change_deg" in q for q in r.info["rounds"])


def test_coarse_to_fine_keeps_the_accuracy_of_the_full_solve(cache):
    # a 96 px sphere: coarse-to-fine forced by a low threshold (factor 2, a 48 px alternation,
    # then two steps per pixel at full size); the full-size alternation is the reference
    d = render_scene("sphere", "paint_0.10", size=96, spp=16, cache_dir=cache)
    sel = binary_erosion(d["mask"])
    full = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"], coarse_pixels=0)
    c2f = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"], coarse_pixels=2000)
    assert "coarse" not in full.info and c2f.info["coarse"]["factor"] == 2
    e_full = _err(full.normal, d["normals"], sel).mean()
    e_c2f = _err(c2f.normal, d["normals"], sel).mean()
    assert e_c2f < e_full + 0.15, (e_c2f, e_full)
    last = c2f.info["rounds"][-1]
    assert last["round"] == "full size" and last["pixels_refined"] > 0
    choice = c2f.info["materials"][0]["model_choice"]
    assert choice["model"] == "lobe" and choice["made_on"] == "the coarse pass"
    assert abs(last["sigma"] - 0.10) < 0.03 and abs(last["n_i"] - 1.30) < 0.06
    np.testing.assert_allclose(np.median(c2f.albedo[sel], axis=0), d["params"]["kd"], rtol=0.08)
    assert np.array_equal(c2f.valid, full.valid)


def test_binning_averages_the_usable_values_only():
    from facette.fit._bin_jit import bin_images
    im = np.arange(2 * 4 * 6, dtype=np.float32).reshape(2, 4, 6, 1)
    im[0, 0, 0, 0] = np.nan                       # missing
    im[1, 1, 1, 0] = 100.0                        # saturated (level 90 below)
    mask = np.ones((4, 6), bool)
    mask[2:, 4:] = False                          # a block with nothing masked in
    b = bin_images(im, mask, 2, saturation=90.0)
    assert b.shape == (2, 2, 3, 1)
    np.testing.assert_allclose(b[0, 0, 0, 0], np.mean([1, 6, 7]))
    np.testing.assert_allclose(b[1, 0, 0, 0], np.mean([24, 25, 30]))
    np.testing.assert_allclose(b[0, 0, 1, 0], np.mean([2, 3, 8, 9]))
    assert np.isnan(b[:, 1, 2]).all()
    odd = bin_images(im[:, :3, :5], mask[:3, :5], 2)   # sizes not divisible: partial blocks
    assert odd.shape == (2, 2, 3, 1) and np.isnan(odd[:, 1, 2]).all()   # 1 of 4 pixels: too few


def test_matte_material_skips_the_brdf_step(cache):
    d = render_scene("sphere", "plaster", size=48, spp=8, cache_dir=cache)
    r = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    h = photometric_stereo(d["images"], d["light_dirs"], method="rank_trimmed", mask=d["mask"])   # the init
    mat = r.info["materials"][0]
    assert mat["brdf_step"] is False and "Lambertian" in mat["note"]
    # the lobe refitted with a lobe kept either falls back to n_i = 1 or does not pay its way
    choice = mat["model_choice"]
    assert choice["model"] == "lambertian"
    assert choice.get("lobe_n_i", 1.0) < 1.02 or choice.get("gain", 0.0) < 0.1
    # least squares where it explains the pixel under every light or the robust start left no light
    # out (a shadow or a highlight), the initial normals elsewhere
    ls = photometric_stereo(d["images"], d["light_dirs"], method="woodham1980", mask=d["mask"])
    clean = ~(h.shadow | h.specular).any(-1)
    lam = ls.valid & ((ls.residual < 0.03) | clean) & np.all(np.isfinite(d["images"]), axis=(0, 3))
    assert 0 < lam.sum() < r.valid.sum()
    np.testing.assert_allclose(r.normal[lam], ls.normal[lam])
    np.testing.assert_allclose(r.normal[~lam], h.normal[~lam])
    assert r.info["rounds"][0]["pixels_lambertian"] == int(lam.sum())
    assert r.info["levels"]["brdf_aware"]["pixels"] == 0


def test_fit_with_true_normals_per_pixel_kd(cache):
    d = render_scene("sphere", "paint_0.10", size=64, spp=16, textured=True, cache_dir=cache)
    sel = binary_erosion(d["mask"]) & (d["normals"][..., 2] > 0.3)
    e = np.transpose(d["images"][:, sel], (1, 0, 2))
    f = fit_li_per_pixel_kd(e, d["light_dirs"], d["normals"][sel], np.ones(e.shape[:2], bool))
    assert abs(f["sigma"] - 0.10) < 0.02 and abs(f["n_i"] - 1.30) < 0.04
    ratio = f["kd"] / d["kd"][sel]
    assert np.median(np.abs(ratio - 1)) < 0.05          # K_d per pixel follows the texture


def test_arguments_and_degenerate_inputs():
    L = np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]
                  for t, p in [(0.5, 0), (0.5, 2), (0.5, 4), (0.3, 1), (0.3, 3), (0.3, 5)]])
    with pytest.raises(ValueError, match="rounds"):
        ps_li_alternating(np.ones((6, 4, 4)), L, rounds=0)
    with pytest.raises(ValueError, match="highlight_start"):
        ps_li_alternating(np.ones((6, 4, 4)), L, highlight_start="some")
    with pytest.raises(ValueError, match="neighbour_deg"):
        ps_li_alternating(np.ones((6, 4, 4)), L, neighbour_deg=-1)
    with pytest.raises(ValueError, match="another method"):
        ps_li_alternating(np.ones((6, 4, 4)), L, init=ps_li_alternating)
    black = ps_li_alternating(np.zeros((6, 8, 8, 3)), L)       # nothing lit: no valid pixel, no crash
    assert not black.valid.any() and np.all(np.isfinite(black.normal))
    f = fit_li_per_pixel_kd(np.zeros((3, 6, 3)), L, np.tile([0, 0, 1.0], (3, 1)), np.zeros((3, 6), bool))
    assert f["success"] is False and "no usable" in f["message"]


def test_stability_black_saturated_shadowed_and_single_light_pixels(cache):
    d = render_scene("sphere", "paint_0.10", size=48, spp=8, cache_dir=cache)
    im = d["images"].copy()
    c = 24
    im[:, c, c - 4:c - 2] = 0                       # black under every light (shadowed everywhere)
    im[:, c, c:c + 2] = 10.0                        # saturated under every light
    im[1:, c + 2, c:c + 2] = np.nan                 # a single light left
    im[3:5, c - 2, c:c + 2] = 10.0                  # two saturated lights: still solvable
    r = ps_li_alternating(im, d["light_dirs"], mask=d["mask"], saturation=5.0)
    for name in ("normal", "albedo", "residual"):
        assert np.all(np.isfinite(getattr(r, name))), name
    assert not r.valid[c, c - 4:c - 2].any() and not r.valid[c, c:c + 2].any()
    assert not r.valid[c + 2, c:c + 2].any()        # too few lights: marked not valid, normal 0
    assert np.all(r.normal[c + 2, c:c + 2] == 0)
    assert r.valid[c - 2, c:c + 2].all()
    err = np.degrees(np.arccos(np.clip(np.sum(r.normal[c - 2, c:c + 2] * d["normals"][c - 2, c:c + 2], -1), -1, 1)))
    assert np.all(err < 5)


def test_the_lobe_and_its_diffuse_part_are_chosen_by_the_profile_cost(cache):
    # the satin sphere (Mitsuba's roughplastic: a layered, LI-like material), from the hierarchy's
    # normals and with either volume evaluation: a lobe, a layered diffuse part (the LI substrate
    # or the coupled one, not Cook–Torrance's), (σ, n_i) near the truth
    d = render_scene("sphere", "satin", size=48, spp=8, cache_dir=cache)
    for volume_model in ("tables", "approx"):
        r = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"], init=ps_hierarchical_tautzia2016,
                              volume_model=volume_model)
        mat = r.info["materials"][0]
        choice = mat["model_choice"]
        assert choice["model"] == "lobe" and mat["brdf_step"] is True, choice
        assert choice["cost_lobe"] < 0.9 * choice["cost_lambertian"]
        if volume_model == "tables":   # the approximate formula is 3-5 % off the LI integral itself
            assert mat["diffuse"] in ("li", "coupled"), choice["cost_by_diffuse"]
        last = r.info["rounds"][-1]
        assert 0.15 < last["sigma"] < 0.26 and 1.35 < last["n_i"] < 1.65, last
        assert r.info["levels"]["brdf_aware"]["pixels"] > 0.3 * r.valid.sum()


def test_a_broad_lobe_between_the_grids_sigmas_gets_its_layered_diffuse_part(cache):
    # Mitsuba's rough plastic (σ 0.4, n_i 1.5): its cost is a narrow valley along σ and n_i; with no
    # σ between 0.3 and 0.5 on the search's grid, Cook–Torrance's Lambertian part won (σ 0.43, 3.0°
    # here against 2.4° with the coupled part)
    d = render_scene("sphere", "rough_plastic", size=48, spp=8, cache_dir=cache)
    r = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    mat = r.info["materials"][0]
    assert mat["diffuse"] in ("li", "coupled"), mat["model_choice"]["cost_by_diffuse"]
    assert 0.36 < mat["sigma"] < 0.44 and 1.4 < mat["n_i"] < 1.6, mat
    if mat["diffuse"] == "coupled":     # K_d through the rough interface's own r_i: 0.98 of the truth here
        on = r.valid & d["mask"]        # (0.93-0.95 with the smooth interface's, brdf._coupled)
        np.testing.assert_allclose(np.median(r.albedo[on] / d["kd"][on], axis=0), 1.0, atol=0.04)


def test_a_lambertian_diffuse_part_beside_the_lobe_is_found_and_gives_better_normals():
    # Cook–Torrance images (a Lambertian term beside the lobe, σ 0.05, n_i 1.2: the simulated rig's
    # material): the search picks the "lambert" diffuse part and the lobe near the truth, and the
    # normals beat the same solve forced to the LI substrate
    sc = sphere_on_plane(96, 96)
    lights = thesis_light_directions()
    im = render(sc, lights, "glossy", noise=0.005, rng=np.random.default_rng(3))
    auto = ps_li_alternating(im, lights, mask=sc.mask)
    forced = ps_li_alternating(im, lights, mask=sc.mask, diffuse="li")
    mat = auto.info["materials"][0]
    assert mat["model_choice"]["model"] == "lobe" and mat["diffuse"] == "lambert", mat["model_choice"]
    assert abs(mat["sigma"] - 0.05) < 0.01 and abs(mat["n_i"] - 1.2) < 0.05, mat
    assert forced.info["materials"][0]["diffuse"] == "li"
    err_auto = np.mean(angular_error_deg(auto.normal, sc.normals, sc.mask))
    err_li = np.mean(angular_error_deg(forced.normal, sc.normals, sc.mask))
    assert err_auto < err_li, (err_auto, err_li)
    with pytest.raises(ValueError, match="diffuse"):
        ps_li_alternating(im, lights, mask=sc.mask, diffuse="metal")


def test_a_matte_material_gets_no_lobe(cache):
    # Mitsuba plaster: the best lobe does not lower the trimmed profile cost by LOBE_MIN_GAIN
    from facette.fit._li_model import LOBE_MIN_GAIN
    d = render_scene("sphere", "plaster", size=48, spp=8, cache_dir=cache)
    r = ps_li_alternating(d["images"], d["light_dirs"], mask=d["mask"])
    choice = r.info["materials"][0]["model_choice"]
    assert choice["model"] == "lambertian" and choice["gain"] < LOBE_MIN_GAIN, choice
    assert r.info["levels"]["brdf_aware"]["pixels"] == 0


def test_fit_bounds_and_cost():
    from facette.brdf import li_shading_terms
    from facette.fit import li_fit_cost
    LOBE_FIT_BOUNDS = ((0.01, 1.0), (1.05, 2.5))    # bounds that keep a lobe
    rng = np.random.default_rng(1)
    L = np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]
                  for t, p in [(0.5, 0), (0.5, 2), (0.5, 4), (0.3, 1), (0.3, 3), (0.3, 5), (0.2, 0.5), (0.4, 2.5)]])
    n = rng.normal(size=(200, 3)) * [0.3, 0.3, 0] + [0, 0, 1]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    _, b = li_shading_terms(n, L, 1e-3, 1.0, volume_model=LI_VOLUME_MODEL)   # Lambertian images, K_d varying
    e = (b[..., None] * rng.uniform(0.2, 0.8, (200, 1, 3))).astype(np.float32)
    ok = np.ones(e.shape[:2], bool)
    assert li_fit_cost(e, L, n, ok, 1e-3, 1.0) < 1e-9           # the model that made them
    assert li_fit_cost(e, L, n, ok, 0.1, 1.4) > 1e-4            # a lobe where there is none
    lobe = fit_li_per_pixel_kd(e, L, n, ok, bounds=LOBE_FIT_BOUNDS)
    assert lobe["sigma"] >= LOBE_FIT_BOUNDS[0][0] - 1e-12 and lobe["n_i"] >= LOBE_FIT_BOUNDS[1][0] - 1e-12
    np.testing.assert_allclose(li_fit_cost(e, L, n, ok, lobe["sigma"], lobe["n_i"]), lobe["cost"], rtol=1e-4)
    with pytest.raises(ValueError, match="low < high"):
        fit_li_per_pixel_kd(e, L, n, ok, bounds=((0.1, 0.1), (1.0, 2.0)))


def test_glossy_walls_mirror_light_that_the_second_removal_takes_out(cache):
    # a vase in glossy paint (Mitsuba, path traced): after the Lambertian removal its walls still
    # hold the light they mirror from each other; the second gather, with li's lobe, takes it out
    from facette.fit import ps_li_without_interreflections
    from facette.recon import without_interreflections
    d = render_scene("vase", "paint_0.08", size=64, spp=32, textured=True, cache_dir=cache)
    sel = binary_erosion(d["mask"], iterations=1)

    def err(r):
        return np.degrees(np.arccos(np.clip(np.sum(r.normal[sel] * d["normals"][sel], -1), -1, 1))).mean()

    im, L = d["images"], d["light_dirs"]
    lambertian = ps_li_alternating(without_interreflections(im, L, d["mask"])[0], L, mask=d["mask"])
    r, direct, info = ps_li_without_interreflections(im, L, d["mask"])
    assert info["applied"] and info["glossy"] is not None
    (sigma, n_i), = info["glossy"]["lobes"]
    assert 0.06 < sigma < 0.11 and 1.2 < n_i < 1.36
    assert info["glossy"]["p95_fraction"] > info["p95_fraction"]      # more is removed than before
    assert err(r) < 0.97 * err(lambertian), (err(r), err(lambertian))
    assert np.all(direct <= im + 1e-6)
    # above coarse_pixels the first li pass, which only feeds the gather's cells, runs on binned
    # images (2 x 2 here: 192 px for 96 cells), its lobe li's own: the same lobe, and normals as good
    # as with no coarse pass at all (here 2.21° against 2.15°, li without the removal 3.99°; the 12 MP
    # relief: 0.45° against 0.48° with the first pass at full size)
    big, big_mask = np.repeat(np.repeat(im, 6, 1), 6, 2), np.repeat(np.repeat(d["mask"], 6, 0), 6, 1)
    big_truth, coarse = np.repeat(np.repeat(d["normals"], 6, 0), 6, 1), int(big_mask.sum()) // 3
    whole, _, info_w = ps_li_without_interreflections(big, L, big_mask, coarse_pixels=None)
    binned, _, info_b = ps_li_without_interreflections(big, L, big_mask, coarse_pixels=coarse)
    left_in = ps_li_alternating(big, L, mask=big_mask, coarse_pixels=coarse)
    (sigma_w, n_i_w), = info_w["glossy"]["lobes"]
    (sigma_b, n_i_b), = info_b["glossy"]["lobes"]
    assert abs(sigma_b - sigma_w) < 0.01 and abs(n_i_b - n_i_w) < 0.03

    def big_err(r):
        return np.degrees(np.arccos(np.clip(np.sum(r.normal * big_truth, -1), -1, 1)))[big_mask & r.valid].mean()

    assert big_err(binned) < min(1.1 * big_err(whole), 0.7 * big_err(left_in)), \
        (big_err(binned), big_err(whole), big_err(left_in))
    # a convex object gathers nothing: no removal, so no second stage
    s = render_scene("sphere", "paint_0.10", size=48, spp=8, cache_dir=cache)
    _, same, info = ps_li_without_interreflections(s["images"], s["light_dirs"], s["mask"])
    assert not info["applied"] and info["glossy"] is None and same is s["images"]


def _li_sphere(sigma, n_i, kd, size=32):
    """(images (12, size, size, 3), lights, true normals, mask) of the LI model on a sphere, rig lights."""
    from facette.bench._mitsuba_scenes import rig_light_directions
    from facette.brdf import li_kappa, li_shading_terms
    u = (np.arange(size) + 0.5) / size * 2 - 1
    gx, gy = np.meshgrid(u, -u)
    r2 = gx ** 2 + gy ** 2
    mask = r2 < 0.9
    n = np.stack([gx, gy, np.sqrt(np.clip(1 - r2, 0, 1))], -1).astype(np.float32)
    n[~mask] = [0, 0, 1]
    lights = rig_light_directions()
    a, b = li_shading_terms(n.reshape(-1, 3), lights, sigma, n_i)
    k = li_kappa(np.asarray(kd, float)[None], n_i)[0] if n_i > 1 else np.asarray(kd, float) / np.pi
    e = a[..., None] + b[..., None] * k[None, None, :]
    im = np.transpose(e.reshape(size, size, len(lights), 3), (2, 0, 1, 3)).astype(np.float32)
    im[:, ~mask] = 0
    return im, lights, n, mask


@pytest.mark.parametrize("sigma, n_i", [(1e-3, 1.3), (0.1, 1.001), (0.1, 1.0)])
def test_sigma_to_zero_and_n_i_to_one_give_finite_close_normals(sigma, n_i):
    """σ → 0 (a lobe too narrow to see) and n_i → 1 (no interface: Lambert) are the LI model's
    edges: the whole alternation stays finite and close to the truth."""
    im, lights, n, mask = _li_sphere(sigma, n_i, (0.6, 0.5, 0.4))
    r = ps_li_alternating(im, lights, mask=mask)
    for name in ("normal", "albedo", "residual"):
        assert np.all(np.isfinite(getattr(r, name))), name
    ok = mask & r.valid
    assert ok.sum() > 0.9 * mask.sum()
    # noise-free, but 12 lights and attached shadows at the rim: 1.1-1.9 deg median today
    assert np.median(_err(r.normal, n, ok)) < 2.5


def test_metal_without_diffuse_part_gives_finite_results_or_invalid_pixels():
    """A lobe and no substrate (K_d = 0, n_i 2.5: metal-like, outside the LI model's dielectric
    over a diffuse body): most pixels are black under every light; nothing may turn NaN, the black
    ones are marked not valid. (The K_d found where the lobe is seen is not near 0, up to 0.76
    here: the LI model has no metal, issue 24 item 3.)"""
    im, lights, n, mask = _li_sphere(0.15, 2.5, (0.0, 0.0, 0.0))
    r = ps_li_alternating(im, lights, mask=mask)
    for name in ("normal", "albedo", "residual"):
        assert np.all(np.isfinite(getattr(r, name))), name
    black = mask & np.all(im.max(-1) <= 0, axis=0)
    assert black.any() and not r.valid[black].any()
    norms = np.linalg.norm(r.normal[r.valid], axis=-1)
    np.testing.assert_allclose(norms, 1, atol=1e-4)


def _grid_lights_96():
    """96 directions on a plane of LEDs in front of the object, up to 43° from the axis (a
    DiLiGenT-like layout; our own grid)."""
    gx, gy = np.meshgrid(np.linspace(-1, 1, 12), np.linspace(-0.67, 0.67, 8))
    lights = np.stack([gx.ravel(), gy.ravel(), np.full(96, 1.3)], -1)
    return lights / np.linalg.norm(lights, axis=1, keepdims=True)


@pytest.mark.parametrize("diffuse", ["li", "coupled"])
def test_a_dark_level_under_every_photograph_is_taken_out(cache, diffuse):
    """A pedestal (black level, ambient light) of 2 % of the lit median added to every value of a
    glossy sphere under 96 lights: li_alternating finds it in the pixels whose light is behind
    them and takes it out; the clean render has none and is solved as it is. One diffuse part
    throughout: with diffuse="auto" the choice between these two, a near tie here, moved with the
    pedestal (the clean render and the one taken out: coupled; kept: li)."""
    d = render_scene("sphere", "paint_0.05", size=64, spp=16, lights=_grid_lights_96(), cache_dir=cache)
    sel = binary_erosion(d["mask"])
    im = d["images"]
    pedestal = 0.02 * np.median(im[:, d["mask"], 1][im[:, d["mask"], 1] > 0])
    clean = ps_li_alternating(im, d["light_dirs"], mask=d["mask"], diffuse=diffuse)
    assert clean.info["dark_offset"]["applied"] is False and clean.info["dark_offset"]["estimated"] == 0
    same = ps_li_alternating(im, d["light_dirs"], mask=d["mask"], dark_offset="none", diffuse=diffuse)
    assert np.array_equal(clean.normal, same.normal)
    auto = ps_li_alternating(im + pedestal, d["light_dirs"], mask=d["mask"], diffuse=diffuse)
    kept = ps_li_alternating(im + pedestal, d["light_dirs"], mask=d["mask"], dark_offset="none", diffuse=diffuse)
    dark = auto.info["dark_offset"]
    assert dark["applied"] and dark["estimated"] >= 40
    np.testing.assert_allclose(dark["median"], pedestal, rtol=1e-3)
    e_clean, e_auto, e_kept = (_err(r.normal, d["normals"], sel).mean() for r in (clean, auto, kept))
    # measured: li 0.28 clean, 0.41 taken out, 0.50 kept; coupled 0.27, 0.49, 0.59 (the photographs
    # with too few dark pixels keep it)
    assert e_auto < e_kept - 0.05 and e_auto < e_clean + 0.25, (e_clean, e_auto, e_kept)


def test_the_later_rounds_refit_on_round_twos_draw(monkeypatch):
    # a refit on pixels drawn again each round moves with the draw (DiLiGenT pot2: n_i by 0.01-0.03
    # a round) and the rounds ran to their limit; the later rounds refit on round 2's pixels
    import facette.fit._ps_li as ps_li
    from facette.fit._ps_li_pixels import Pixels
    drawn = []
    draw = Pixels.draw

    def counted(self, trust):
        drawn.append(draw(self, trust))
        return drawn[-1]

    monkeypatch.setattr(Pixels, "draw", counted)
    monkeypatch.setattr(ps_li, "_settled", lambda *args: False)     # every round runs
    sc = sphere_on_plane(64, 64)
    lights = thesis_light_directions()
    im = render(sc, lights, "satin", noise=0.02, rng=np.random.default_rng(3))
    r = ps_li_alternating(im, lights, mask=sc.mask, tol_deg=0.0, rounds=4, fit_pixels=200)
    assert [x["round"] for x in r.info["rounds"]] == [1, 2, 3, 4]
    assert len(drawn) == 2 and not np.array_equal(drawn[0], drawn[1])
    # on the same pixels the refit follows the normals alone: rounds 3 and 4 agree closely
    r3, r4 = r.info["rounds"][2:]
    assert abs(r3["sigma"] - r4["sigma"]) < 0.01 * r3["sigma"] and abs(r3["n_i"] - r4["n_i"]) < 0.005


def test_a_cast_shadow_stays_flagged_and_the_lobes_own_tail_does_not(cache):
    # a narrow lobe (paint σ 0.05) with a block cast into shadow under two lights: the solve's
    # test, read at its start normal, flagged 86 lit values of the highlights' tails too (which
    # the BRDF fit's samples then left out); settled at the final normal against the diffuse
    # part, the shadow's values stay flagged and the lit ones are lifted
    d = render_scene("sphere", "paint_0.05", size=64, spp=32, cache_dir=cache)
    im, mask = d["images"].copy(), d["mask"]
    block = np.zeros(mask.shape, bool)
    block[20:30, 24:40] = True
    for k in (0, 5):
        im[k][block & mask] *= 0.02
    r = ps_li_alternating(im, d["light_dirs"], mask=mask)
    solved = r.valid & ~r.skipped
    assert r.shadow[block & mask & solved][:, [0, 5]].all()
    lit = r.shadow.copy()
    lit[block] = False
    assert lit[solved].sum() <= 10, lit[solved].sum()
    assert r.info["materials"][0]["shadows_settled"]["flags_lifted"] > 50


def test_the_diffuse_part_is_chosen_on_all_the_materials_pixels_under_few_lights_too():
    # a glossy sphere whose diffuse part is the coupled one (a Lambertian substrate through the
    # interface), 12 lights: each diffuse part is fitted, then scored at its fit on a draw of all the
    # sphere's pixels, oblique ones included (the fit pixels are the less oblique ones); at the grid's
    # points LI's scored lower (0.0351 against 0.0366), and its normals were 0.52° off
    from facette.brdf import kappa_from_kd, li_shading_terms
    sc = sphere_on_plane(64, 64)
    lights = thesis_light_directions()
    sel = sc.sphere
    a, b = li_shading_terms(sc.normals[sel], lights, 0.1, 1.3, volume_model="coupled")
    kd = np.array([0.6, 0.5, 0.4])
    images = np.zeros((len(lights),) + sel.shape + (3,), np.float32)
    images[:, sel] = np.transpose(a[..., None] + b[..., None] * kappa_from_kd(kd, 1.3, "coupled", 0.1), (1, 0, 2))
    r = ps_li_alternating(images, lights, mask=sel)
    choice = r.info["materials"][0]["model_choice"]
    assert choice["gain_pixels"] == min(1000, int(r.valid.sum())), choice
    costs = choice["fitted_cost_by_diffuse"]
    assert choice["diffuse"] == "coupled" and costs["coupled"] < 0.8 * costs["li"], choice
    assert _err(r.normal, sc.normals, sel & r.valid).mean() < 0.1
