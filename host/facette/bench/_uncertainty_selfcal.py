"""The lights' calibration error as the data show it, and the normals it moves (issue 50 item 3; tried for the
uncertainty band, `facette bench uncertainty --candidates`).

An error of one light's intensity or direction is common to every pixel it lights, so no pixel's own data show it
(the 16-bit ball's ~2° everywhere). But all the pixels together do: with the solve's normals and its material's
model fixed, each light i's residuals over the object, r_pi = e_pi − p_pi (p the fitted model's prediction),
are fitted by a correction of that light alone,

    r_pi ≈ a_i p_pi + δ_i1 ∂p_pi/∂t_i1 + δ_i2 ∂p_pi/∂t_i2     (least squares over p, Cauchy-reweighted),

a_i its relative intensity error and δ_i (rad) its direction's along two tangents t_i1, t_i2 (finite differences
of the model). The normals re-solved by the default's per-pixel solve (facette.fit.refine_normals_li, the material
fixed) under the corrected lights and under the lights as given: `self-calibration shift` is each pixel's angle
between the two (each re-solved from the solution, so that the solve's own step does not count). It is the error
field that the lights' calibration, if it is off as the data say, leaves on the normals. Not seen, as they should
not be: a rotation of the lights and normals together, a gain common to all the lights (each pixel's albedo); and
with each pixel's albedo free the lights are pinned to about 0.5° (12 lights near the axis; the test).
The model's misfit common to a light's pixels (a lobe that is too narrow) is absorbed too, and moves the normals
where that light matters.
"""
import numpy as np

from facette.bench._uncertainty_bootstrap import _prediction, _resolve
from facette.bench._uncertainty_li import _terms
from facette.recon import _uncertainty as unc

__all__ = ["light_corrections", "selfcal_shift", "SELFCAL_CANDIDATES"]

SELFCAL_CANDIDATES = ("self-calibration shift",)
_FD = 1e-3
ROUNDS = 3           # Cauchy reweightings of each light's fit
ALTERNATIONS = 4     # fits of the lights, each pixel's κ taken again between them
MAX_FIT_PIXELS = 20000


def _one_correction(e, w, n, lights, labels, materials):
    """((m,) relative intensity errors, (m, 2) direction errors along unc._tangents(lights)) of one fit."""
    pred = np.zeros_like(e)
    grads = [np.zeros_like(e), np.zeros_like(e)]
    tangents = unc._tangents(lights)
    for label in np.unique(labels):
        p = np.flatnonzero(labels == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        a, b = _terms(n[p], lights, mat)
        _, kappa = _prediction(e[p], w[p], n[p], lights, mat)
        pred[p] = a + b * kappa[:, None]
        for g, t in zip(grads, tangents):
            moved = lights + _FD * t
            moved /= np.linalg.norm(moved, axis=1, keepdims=True)
            am, bm = _terms(n[p], moved, mat)
            g[p] = (am + bm * kappa[:, None] - pred[p]) / _FD
    resid = (e - pred) * w
    scale_rel, delta = np.zeros(len(lights)), np.zeros((len(lights), 2))
    for i in range(len(lights)):
        use = np.flatnonzero(w[:, i] > 0)
        if use.size < 10:
            continue
        x = np.stack([pred[use, i], grads[0][use, i], grads[1][use, i]], axis=1)
        y = resid[use, i]
        wt = np.ones(use.size)
        for _ in range(ROUNDS):
            coef = np.linalg.lstsq(x * wt[:, None], y * wt, rcond=None)[0]
            r = y - x @ coef
            c = 2.385 * 1.4826 * max(np.median(np.abs(r)), 1e-12)
            wt = 1.0 / np.sqrt(1.0 + (r / c) ** 2)          # Cauchy's IRLS weight (square root: rows scaled)
        scale_rel[i], delta[i] = coef[0], coef[1:]
    return scale_rel, delta


def light_corrections(e, w, n, lights, labels, materials):
    """((m,) relative intensity errors a, (m, 3) corrected unit directions) from the residuals of all the pixels
    (module doc), refitted ALTERNATIONS times with each pixel's κ taken again under the corrected lights (one light's
    error moves every pixel's κ, which the other lights' residuals would otherwise take for theirs).
    e, w (N, m), n (N, 3) unit, lights (m, 3), labels (N,) into materials."""
    gain, moved = np.ones(len(lights)), np.asarray(lights, np.float64)
    for _ in range(ALTERNATIONS):
        a, delta = _one_correction(e / gain[None], w, n, moved, labels, materials)
        t1, t2 = unc._tangents(moved)
        gain = gain * (1 + a)
        moved = moved + delta[:, :1] * t1 + delta[:, 1:] * t2
        moved /= np.linalg.norm(moved, axis=1, keepdims=True)
    return gain - 1, moved


def selfcal_shift(e, w, n, lights, labels, materials, drawn, rng=None):
    """(N,) rad, NaN off `drawn`: the angle each drawn pixel's normal moves when re-solved under the lights the
    data correct (module doc). The lights' fit uses at most MAX_FIT_PIXELS pixels drawn at random."""
    rng = np.random.default_rng(0) if rng is None else rng
    fit = np.sort(rng.choice(len(e), min(MAX_FIT_PIXELS, len(e)), replace=False))
    materials = materials or []
    a, moved = light_corrections(e[fit], w[fit], n[fit], lights, labels[fit], materials)
    out = np.full(len(e), np.nan)
    corrected = e[drawn] / np.maximum(1 + a, 0.2)[None]   # the values as the corrected lights would give them
    ends, before = np.zeros((drawn.size, 3)), np.zeros((drawn.size, 3))
    for label in np.unique(labels[drawn]):
        p = np.flatnonzero(labels[drawn] == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        d = drawn[p]
        ends[p] = _resolve(corrected[p], w[d], n[d], moved, mat)
        before[p] = _resolve(e[d], w[d], n[d], lights, mat)        # the same solve under the lights as given
    out[drawn] = np.arccos(np.clip(np.sum(ends * before, 1), -1.0, 1.0))
    return out
