"""The model choice's search walks each start's own valley, and a later round's refit that only
slides along a flat valley keeps the model (facette.fit._li_model._profile_lobe,
facette.fit._ps_li_refit.fit_pixels_gain, facette.fit._ps_li._settled)."""
from types import SimpleNamespace

import numpy as np

import facette.fit._li_model as li_model
from facette.fit._ps_li import _settled
from facette.fit._ps_li_refit import FIT_PIXELS_MIN_GAIN, fit_pixels_gain
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def test_the_dielectric_n_i_line_runs_at_the_dielectric_sigma_lines_best(monkeypatch):
    # a landscape where the metal start's σ line is lower than the dielectric one (σ 0.5 there),
    # but the lowest point of all is a dielectric valley at σ 0.13, n_i 1.7 (the satin sphere
    # beside a Lambertian part): from the overall best σ the dielectric line would run at 0.5
    def cost(sigma, n_i):
        if n_i > 2.5:
            return 3.0 + abs(np.log(sigma / 0.5)) + 0.1 * abs(np.log(n_i / 15))
        return 4.0 + 5 * abs(np.log(sigma / 0.13)) - (3.5 if n_i == 1.7 else 0.0) + abs(n_i - 1.7)

    calls = []

    def solve(sigma, n_i, vm, search=True, grid=65):
        calls.append((sigma, n_i))
        return np.full((10, 3), [sigma, n_i, 0.0])

    # the per-pixel costs of a "solve": the landscape's value at the (σ, n_i) it was solved for
    monkeypatch.setattr(li_model, "_pixel_costs",
                        lambda e, lights, n, usable, sigma, n_i, vm: np.full(10, cost(sigma, n_i) / 8))
    for how in ("all", "coarse-to-fine"):
        monkeypatch.setattr(li_model, "PROFILE_SIGMA_SEARCH", how)
        monkeypatch.setattr(li_model, "PROFILE_N_I_SEARCH", "all" if how == "all" else "downhill")
        calls.clear()
        best, _, _ = li_model._profile_lobe(None, None, None, solve, ("lambert",))
        dielectric = best[(False, "lambert")]
        assert (dielectric["sigma"], dielectric["n_i"]) == (0.13, 1.7), (how, dielectric["sigma"], dielectric["n_i"])
        assert (0.5, 1.7) not in calls or how == "all"


def _fit_pixels(sigma, n_i):
    """A satin sphere's lit pixels at their true normals, as `fit_pixels_gain` reads them (a Pixels stand-in)."""
    sc = sphere_on_plane(40, 40)
    lights = thesis_light_directions()
    im = render(sc, lights, "satin", noise=0.01, rng=np.random.default_rng(5))
    sel = sc.sphere & (sc.normals[..., 2] > 0.3)
    e = np.ascontiguousarray(np.transpose(im[:, sel], (1, 0, 2)), dtype=np.float32)
    return SimpleNamespace(gather=lambda s: e[s], lights_of=lambda s: lights, nrm=sc.normals[sel].astype(np.float32),
                           all_ok=np.isfinite(e).all(2), vm="lambert"), np.arange(e.shape[0])


def test_a_refit_that_explains_the_pixels_is_taken_and_one_that_does_not_move_is_a_tie():
    px, fsel = _fit_pixels(0.15, 1.3)
    fitted = li_model.fit_li_per_pixel_kd(px.gather(fsel), px.lights_of(fsel), px.nrm, px.all_ok,
                                          x0=(0.15, 1.7), volume_model="lambert")
    x = (fitted["sigma"], fitted["n_i"])
    # from off the valley (σ 0.05) the refit lowers every pixel's cost alike: several standard errors
    far = fit_pixels_gain(px, fsel, (0.05, 1.3), fitted)
    assert far > 3 * FIT_PIXELS_MIN_GAIN and not _settled((0.05, 1.3), x), far
    # a refit that stays where it was gains nothing: a tie, the model kept
    same = fit_pixels_gain(px, fsel, x, fitted)
    assert same == 0 and same < FIT_PIXELS_MIN_GAIN and _settled(x, x)
    # a move beyond the σ / n_i tolerances that is a tie is settled all the same
    assert _settled((0.15, 1.3), (0.2, 1.5), {"tie": True}) and not _settled((0.15, 1.3), (0.2, 1.5))


def test_a_refit_judged_held_out_is_settled_by_how_far_it_moves_the_normals_not_by_its_parameters():
    far, near = ((0.15, 1.3), (0.2, 1.5)), ((0.15, 1.3), (0.151, 1.301))
    # held out, the held-out normals' median move against the rounds' tol_deg decides
    assert _settled(*far, {"tie": False, "change_deg": 0.05}, tol_deg=0.1)
    assert not _settled(*near, {"tie": False, "change_deg": 0.15}, tol_deg=0.1)
    assert _settled(*near, {"tie": False, "change_deg": 0.15}, tol_deg=0.2)
    # judged on its fit pixels only (no held-out solves, no move measured): the σ / n_i tolerances
    assert not _settled(*far, {"tie": False}) and _settled(*near, {"tie": False})
