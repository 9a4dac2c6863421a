"""Round 1's model choice (facette.fit._li_model.choose_material_model): the gain measured again on
the fit pixels when the profile is only a sample of them."""
import numpy as np

from facette.fit._li_model import LOBE_MIN_GAIN, choose_material_model
from facette.fit._normals_li import refine_normals_li
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _pixels(material, lights, sc, rng):
    im = render(sc, lights, material, noise=0.003, rng=rng)         # (m, H, W, 3)
    sel = sc.mask & (sc.normals[..., 2] > 0.3)
    e = np.transpose(im[:, sel], (1, 0, 2)).astype(np.float32)      # (N, m, 3)
    return e, np.isfinite(e).all(2), sc.normals[sel].astype(np.float64)


def _solver(e, lights, usable, n0):
    def solve(sigma, n_i, vm, search=True, grid=65):
        return refine_normals_li(e, lights, n0, sigma, n_i, usable=usable, iterations=12, volume_model=vm,
                                 engine="compiled", table_grid=grid).normals
    return solve


def test_the_bar_decides_on_the_check_pixels_when_the_profile_is_a_sample():
    # a glossy sphere (Cook–Torrance σ 0.05, n_i 1.2) whose profile sample happens to hold none of
    # its highlights (the pixels where no light exceeds the matte rendering by 2 % of their mean):
    # alone it says no lobe; its candidates measured again on every pixel clear the bar, and the
    # choice says on how many pixels
    lights = thesis_light_directions()
    sc = sphere_on_plane(40, 40)
    e_m, _, _ = _pixels("matte", lights, sc, np.random.default_rng(1))
    e, ok, n = _pixels("glossy", lights, sc, np.random.default_rng(0))
    excess = (e - e_m * e.mean() / e_m.mean()).max(axis=(1, 2)) / e.mean(axis=(1, 2))
    p = excess < 0.02
    assert 0.9 * len(e) < p.sum() < len(e)
    models = ("tables", "lambert")
    _, _, alone = choose_material_model(e[p], lights, ok[p], _solver(e[p], lights, ok[p], n[p]), models)
    assert alone["model"] == "lambertian" and alone["gain"] < LOBE_MIN_GAIN and "gain_pixels" not in alone
    fit, _, checked = choose_material_model(e[p], lights, ok[p], _solver(e[p], lights, ok[p], n[p]), models,
                                            check=(e, lights, ok, _solver(e, lights, ok, n)))
    assert checked["gain_pixels"] == len(e) and checked["profile_gain"] < LOBE_MIN_GAIN, checked
    assert checked["model"] == "lobe" and checked["gain"] > 3 * LOBE_MIN_GAIN, checked
    # (σ, n_i) are then warmed up on the profile pixels (later rounds refit on the fit pixels)
    assert np.isfinite(fit["sigma"]) and fit["n_i"] > 1.0, fit


def test_the_line_searches_find_a_unimodal_profiles_lowest_point_with_fewer_solves():
    from facette.fit._li_model import PROFILE_N_IS, PROFILE_SIGMAS, _line_search
    for line, known, hows in ((PROFILE_SIGMAS, {}, ("coarse-to-fine", "downhill")),
                              (tuple(sorted(PROFILE_N_IS + (1.3,))), {1.3: None}, ("downhill",))):
        for low in line:
            calls = []

            def cost(x):
                calls.append(x)
                return abs(np.log(x) - np.log(low))
            k = {p: cost(p) for p in known}
            calls.clear()
            for how in hows:
                calls.clear()
                got = _line_search(line, dict(k), cost, how)
                assert min(got, key=got.get) == low, (how, low, got)
                assert len(calls) < len(line) - len(known) or len(line) - len(known) <= 3, (how, low, calls)
                assert len(set(calls)) == len(calls)
            calls.clear()
            assert set(_line_search(line, dict(k), cost, "all")) == set(line) and len(calls) == len(line) - len(k)


def _glossy_with_pixels_on_the_peak(fraction, seed=1):
    """A glossy sphere's pixels (Cook–Torrance σ 0.05, n_i 1.2, 12 rig lights) and normals with
    `fraction` of them on a light's mirror direction (a solve stopped on the lobe's peak)."""
    lights = thesis_light_directions()
    e, ok, n = _pixels("glossy", lights, sphere_on_plane(40, 40), np.random.default_rng(0))
    rng = np.random.default_rng(seed)
    bad = rng.choice(len(e), int(fraction * len(e)), replace=False)
    h = lights + np.array([0.0, 0.0, 1.0])
    n = n.copy()
    n[bad] = (h / np.linalg.norm(h, axis=1, keepdims=True))[rng.integers(0, len(lights), bad.size)]
    return e, ok, n, lights


def test_a_lobe_whose_fit_slides_to_no_interface_is_fitted_again_on_the_pixels_that_cleared_the_bar(monkeypatch):
    # a tenth of the pixels on the lobe's peak carry most of the all-pixel cost: from the grid
    # point (the truth) the fit slides to n_i < 1.02 to lower them; on the grid point's kept
    # pixels (the trimmed cost that cleared the bar) it stays at the truth
    from facette.fit import _li_model
    e, ok, n, lights = _glossy_with_pixels_on_the_peak(0.1)
    kept = _li_model._trimmed(_li_model._pixel_costs(e, lights, n, ok, 0.05, 1.2, "lambert"))[1]
    best = dict(sigma=0.05, n_i=1.2, volume_model="lambert", normals=n, kept=kept, gain=0.5)

    def solve(sigma, n_i, vm, search=True, grid=65):     # a solve that stops where it stopped
        return n
    fit, _ = _li_model._warm_up(e, lights, ok, solve, best)
    assert fit["refit_on"] == "kept"
    assert abs(fit["sigma"] - 0.05) < 0.005 and abs(fit["n_i"] - 1.2) < 0.02, (fit["sigma"], fit["n_i"])
    # an earlier solve's lobe (no kept pixels given, `_ps_li_start`): its own trimmed pixels
    again, _ = _li_model._warm_up(e, lights, ok, solve, dict(best, kept=None))
    assert again["refit_on"] == "kept" and abs(again["n_i"] - fit["n_i"]) < 1e-9
    # under many lights (above KEPT_MAX_LIGHTS) the fit is left as it was: slid to no interface
    monkeypatch.setattr(_li_model, "KEPT_MAX_LIGHTS", len(lights) - 1)
    slid, _ = _li_model._warm_up(e, lights, ok, solve, best)
    assert slid["n_i"] < _li_model.LAMBERTIAN_N_I and "refit_on" not in slid, slid["n_i"]
