"""Whether a later round's refit of (σ, n_i) is taken: judged on pixels it was not fitted on.

A later round of `ps_li_alternating` refits (σ, n_i) on its fit pixels at their current normals.
On those pixels the refit always lowers the cost (it was fitted there), so its gain says little
about whether the model is better: a refit that slides along a flat valley with the draw lowers it
too. The refit is judged instead on **held-out pixels**: a draw of the material's other pixels the
BRDF-aware step solved, each solved again against the previous and the refit (σ, n_i) from its
current normal (the profile, as the model choice scores its candidates), and their paired robust
costs compared. The refit is taken when it lowers the held-out cost by more than HELD_OUT_MIN_GAIN
standard errors of the paired differences; otherwise it is a tie and the model stays.

Why not the fit pixels' own gain (the rule before: ≥ 1 standard error of their paired differences):
fitted there, the gain is ≥ 0 by construction and its size does not tell a slide from a better
fit. The satin sphere of tests/pipeline/test_process_light_gains (12 lights, gains corrected):
round 2 slid (σ, n_i) 0.168/1.73 -> 0.193/1.88 at **+0.75** standard errors on its fit pixels,
**−16.0** on held-out pixels (their cost 1.9 % higher); the refits that explain the images better
(the same sphere's other solves, 2 lights' gains off or not) +1.8 to +8.1 held out. A refit that
gained < 1 standard error on its fit pixels can still be better held out (DiLiGenT pot2, 12 lights).
On 24 rendered 12-light spheres (satin and glossy, dark and bright, 8- and 16-bit, gains 3 % off or
not: issue 50's note of 2026-12-07) every refit moved σ by < 5 % and n_i by < 0.01 (settled either way).

The held-out pixels are drawn from the population the fit pixels were drawn from (round 2's
better-explained half, the `population` `_rounds` passes), not from all the material's pixels: the badly explained half
(cast shadows, light gathered from the surface) prefers another model than the one the fit pixels
show, and a refit that explains the well-explained pixels better read as a loss there (textbook
cross-validation: held out from the same population). DiLiGenT 12 lights (confirmed there, chosen on
the generated case of tests/fit/test_ps_li_refit: half the pixels lit by a wall on one side):
pot2 8.73 -> 8.16°, mean 7.05 -> 6.92°.

A half with fewer than HELD_OUT_MIN pixels besides the fit pixels (a small material: under
`fit_pixels` + HELD_OUT_MIN in its half, the draw takes it all) holds out among all the material's.
Too few held-out pixels even there: the fit pixels' own gain decides, with
the rule before (FIT_PIXELS_MIN_GAIN standard errors).
"""
import numpy as np

from ._li_model import _pixel_costs

HELD_OUT_MIN_GAIN = 0.0     # held out, the fit's optimism is gone: any gain beyond none is a gain
HELD_OUT_MIN = 30           # fewer held-out pixels than this: the fit pixels decide
FIT_PIXELS_MIN_GAIN = 1.0   # their rule (in-sample: the refit was fitted there)


def paired_gain(costs_before, costs_after):
    """The paired cost differences' sum over its standard error (√N × their standard deviation):
    how far the second set of costs is below the first, in units of its own noise."""
    d = costs_before - costs_after
    return float(d.sum() / max(np.sqrt(d.size) * d.std(), 1e-30))


def fit_pixels_gain(px, fsel, x0, fit):
    """How much the refit `fit` lowers its fit pixels' (`fsel`) robust cost against `x0` at their
    current normals, in standard errors (`paired_gain`)."""
    args = (px.gather(fsel), px.lights_of(fsel), px.nrm[fsel], px.all_ok[fsel])
    return paired_gain(_pixel_costs(*args, x0[0], x0[1], px.vm), _pixel_costs(*args, fit["sigma"], fit["n_i"], px.vm))


def held_out_gain(px, hold, x0, fit):
    """(gain, median, mean): how much the refit lowers the robust cost of the pixels `hold`, each
    solved against the previous (`x0`) and the refit (σ, n_i) from its current normal, in standard
    errors; and the median and mean angle (°) between each pixel's two solved normals: how far a
    round that re-estimates the pixels against the refit would move them (`_ps_li._settled`)."""
    values, lights, ok = px.gather(hold), px.lights_of(hold), px.all_ok[hold]
    models = (x0, (fit["sigma"], fit["n_i"]))
    normals = [px.refine(hold, s, n, first_round=False).normals for s, n in models]
    costs = [_pixel_costs(values, lights, nrm, ok, s, n, px.vm) for nrm, (s, n) in zip(normals, models)]
    # the angle from the chord, 2 asin(|a − b| / 2): exact at 0, where arccos of a float32 dot is 0.02° off
    chord = np.linalg.norm(normals[0].astype(np.float64) - normals[1], axis=1)
    moved = np.degrees(2 * np.arcsin(np.minimum(chord / 2, 1.0)))
    return paired_gain(*costs), float(np.median(moved)), float(moved.mean())


def refit_verdict(px, pix, fsel, x0, fit, population=None):
    """{"gain": standard errors, "on": "held-out pixels" | "fit pixels", "tie": bool} of a later
    round's refit `fit` (from `x0`, fitted on `fsel`) of the material whose pixels are `pix`; the
    held-out pixels drawn from `population` (the pixels the fit pixels were drawn from) when given
    and it holds HELD_OUT_MIN besides the fit pixels, else from all of `pix`. Judged held out, also
    "change_deg" and "mean_change_deg": the median and mean move of their normals (`held_out_gain`)."""
    src = pix if population is None else population
    pool = np.setdiff1d(src[px.refined[src]], fsel, assume_unique=True)
    if pool.size < HELD_OUT_MIN and src is not pix:      # a small half: all but its fit pixels are drawn
        pool = np.setdiff1d(pix[px.refined[pix]], fsel, assume_unique=True)
    if pool.size < HELD_OUT_MIN:
        gain = fit_pixels_gain(px, fsel, x0, fit)
        return {"gain": gain, "on": "fit pixels", "tie": gain < FIT_PIXELS_MIN_GAIN}
    # a generator of its own: the rounds' draws stay as they were
    hold = np.sort(px.rng.spawn(1)[0].choice(pool, min(px.settings.fit_pixels, pool.size), replace=False))
    gain, median, mean = held_out_gain(px, hold, x0, fit)
    return {"gain": gain, "on": "held-out pixels", "tie": gain <= HELD_OUT_MIN_GAIN, "change_deg": median,
            "mean_change_deg": mean}
