"""A later round's refit of (σ, n_i) is judged on held-out pixels (facette.fit._ps_li_refit)."""
from types import SimpleNamespace

import numpy as np

from facette.fit._li_model import fit_li_per_pixel_kd
from facette.fit._normals_li import refine_normals_li
from facette.fit._ps_li_refit import HELD_OUT_MIN, fit_pixels_gain, refit_verdict
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _pixels(noise):
    """A satin sphere's lit pixels at their true normals under the rig's 12 lights, as
    `refit_verdict` reads them (a Pixels stand-in whose solve is the real per-pixel solve)."""
    sc = sphere_on_plane(48, 48)
    lights = thesis_light_directions()
    im = render(sc, lights, "satin", noise=noise, rng=np.random.default_rng(5))
    sel = sc.sphere & (sc.normals[..., 2] > 0.3)
    e = np.ascontiguousarray(np.transpose(im[:, sel], (1, 0, 2)), dtype=np.float32)
    nrm, ok = sc.normals[sel].astype(np.float32), np.isfinite(e).all(2)

    def refine(s, sigma, n_i, first_round=False):
        return refine_normals_li(e[s], lights, nrm[s], sigma, n_i, usable=ok[s], iterations=12, volume_model="lambert")

    return SimpleNamespace(values=e, gather=lambda s: e[s], lights_of=lambda s: lights, nrm=nrm, all_ok=ok, vm="lambert",
                           refine=refine, refined=np.ones(len(e), bool), rng=np.random.default_rng(0),
                           settings=SimpleNamespace(fit_pixels=1000))


def _fit(px, sel, x0=(0.15, 1.5)):
    """The material model fitted on the pixels `sel` at their true normals."""
    return fit_li_per_pixel_kd(px.gather(sel), px.lights_of(sel), px.nrm[sel], px.all_ok[sel], x0=x0,
                               volume_model="lambert")


def test_a_refit_that_explains_the_images_is_taken_and_one_fitted_to_its_draws_noise_is_a_tie():
    px = _pixels(noise=0.03)
    pix = np.arange(px.nrm.shape[0])
    fsel = pix[::4]
    good = _fit(px, fsel)
    x = (good["sigma"], good["n_i"])
    # from off the valley (σ 0.05): the pixels it was not fitted on are explained better too
    taken = refit_verdict(px, pix, fsel, (0.05, 1.3), good)
    assert taken["on"] == "held-out pixels" and taken["gain"] > 3 and not taken["tie"], taken
    # a refit whose fit pixels carry a bias the others do not (here: their lights 10 % off, as the
    # better-explained half a later round draws from may be): it gains there, not elsewhere
    few = fsel[::8]
    px.values[few] *= (1 + 0.1 * np.sin(1.7 * np.arange(12)))[None, :, None]
    noisy = _fit(px, few, x)
    assert abs(noisy["sigma"] - x[0]) > 0.05 * x[0] or abs(noisy["n_i"] - x[1]) > 0.01, noisy   # it moved
    assert fit_pixels_gain(px, few, x, noisy) > 0
    slid = refit_verdict(px, pix, few, x, noisy)
    assert slid["on"] == "held-out pixels" and slid["tie"], slid


def test_a_material_with_too_few_other_pixels_is_judged_on_its_fit_pixels():
    px = _pixels(noise=0.01)
    pix = np.argsort(px.gather(np.arange(px.nrm.shape[0])).max(axis=(1, 2)))[-(HELD_OUT_MIN + 5):]
    fsel = pix[-10:]
    fit = _fit(px, fsel)
    verdict = refit_verdict(px, pix, fsel, (0.05, 1.3), fit)
    assert verdict["on"] == "fit pixels" and not verdict["tie"], verdict


def test_held_out_pixels_come_from_the_population_the_fit_pixels_were_drawn_from():
    # half the material gathers light from a wall on one side (the lights on that side read
    # brighter: inter-reflections the model does not explain); the later rounds fit on the other,
    # better-explained half. A refit back to the model of the well-explained pixels, from σ 10 %
    # too wide, is a better fit there; held out among all the material's pixels the glowing half
    # prefers the wider lobe and reads it as a loss
    px = _pixels(noise=0.01)
    pix = np.arange(px.nrm.shape[0])
    glow = np.random.default_rng(3).random(pix.size) < 0.5
    side = np.clip(px.lights_of(None)[:, 0], 0, None)[None, :, None]
    px.values[glow] += 0.5 * px.values[glow].mean(1, keepdims=True) * side / side.mean()
    well = pix[~glow]
    fsel = well[::3]
    fit = _fit(px, fsel)
    wide = (1.1 * fit["sigma"], fit["n_i"])
    assert refit_verdict(px, pix, fsel, wide, fit)["tie"]            # judged among every pixel: kept
    verdict = refit_verdict(px, pix, fsel, wide, fit, population=well)
    assert verdict["on"] == "held-out pixels" and verdict["gain"] > 3 and not verdict["tie"], verdict


def test_a_half_the_fit_pixels_take_whole_holds_out_among_all_the_materials_pixels():
    px = _pixels(noise=0.03)
    pix = np.arange(px.nrm.shape[0])
    half = pix[::2]
    fit = _fit(px, half)
    verdict = refit_verdict(px, pix, half, (0.05, 1.3), fit, population=half)
    assert verdict["on"] == "held-out pixels" and not verdict["tie"], verdict


def test_the_verdict_says_how_far_the_refit_would_move_the_held_out_normals():
    # what `_ps_li._settled` reads: a refit from off the valley (σ 0.05) moves the held-out pixels'
    # solved normals by a lot, one from 1 % of σ away by next to nothing
    px = _pixels(noise=0.01)
    pix = np.arange(px.nrm.shape[0])
    fsel = pix[::4]
    fit = _fit(px, fsel)
    far = refit_verdict(px, pix, fsel, (0.05, 1.3), fit)
    near = refit_verdict(px, pix, fsel, (1.01 * fit["sigma"], fit["n_i"]), fit)
    assert far["mean_change_deg"] > 0.2 and near["mean_change_deg"] < 0.02, (far, near)
    assert far["change_deg"] > near["change_deg"], (far, near)          # the median
    # the angles between the two solves of each held-out pixel: none when nothing moves
    same = refit_verdict(px, pix, fsel, (fit["sigma"], fit["n_i"]), fit)
    assert same["change_deg"] == same["mean_change_deg"] == 0.0 and same["tie"], same
