"""A residual bootstrap through the default's own per-pixel solve (issue 50 item 3), tried for the uncertainty
band (`facette bench uncertainty --candidates`).

Per pixel, on the lights the solve kept (usable, not flagged a cast shadow, n·l > 0), the fitted model of its
material (li_alternating's (σ, n_i); bench._uncertainty_li) predicts p_i(n) at the solution; the residuals
r_i = e_i − p_i are put back onto the prediction, resampled, and the normal re-solved by the same per-pixel solve
(facette.fit.refine_normals_li, the material's model fixed) from the solution. The root mean square of the
re-solved normals' angles to the solution (rad) is the measure. Two resamplings:
- `bootstrap wild`: each light keeps its own residual with a random sign (Rademacher; the wild bootstrap, which
  keeps each light's misfit where it is: a shadow or a lobe misfit stays on its light);
- `bootstrap neighbours`: each pixel takes the residual vector of a random pixel within NEIGHBOUR_RADIUS (over
  its prediction's scale κ): the misfit around the pixel carried through this pixel's geometry;
- `sector jackknife`: the lights of one of SECTORS azimuth sectors left out in turn (not a random half: a cast
  shadow or the light a wall sends comes from one side, so it sits in the lights of one sector), the normal
  re-solved from the solution on the rest; the RMS of the angles.
ROUNDS resamples each, on at most MAX_PIXELS pixels drawn at random (the others NaN: the bench scores the
measure on the pixels it has).

And one measure of the cost's other valleys (the local curvature, `li laplace`, sees only the solution's own):
- `valley spread`: the same solve from VALLEY_STARTS other starts (the Lambertian normal of the kept lights, the
  half vector of the brightest kept light, the solution tilted by VALLEY_TILT_DEG four ways); each end normal k
  weighs as its likelihood against the best, exp(−(C_k − C_min) / (2 s²)), C the least-squares cost of the kept
  lights (κ in closed form) and s² = C_min / (kept − 3); the measure is the weighted RMS angle of the ends to the
  solution. A pixel whose data a distant normal explains almost as well is ambiguous however sharp its valley.
"""
import numpy as np

from facette.bench._uncertainty_li import _lambertian, _terms
from facette.bench._uncertainty_li import _residual as _li_residual
from facette.fit import refine_normals_li
from facette.recon import _uncertainty as unc

__all__ = ["bootstrap_measures", "case_profiles", "valley_spread", "channel_spread", "BOOTSTRAP_CANDIDATES"]

BOOTSTRAP_CANDIDATES = ("bootstrap wild", "bootstrap neighbours", "valley spread", "sector jackknife",
                        "self-calibration shift")
SECTORS = 4
VALLEY_TILT_DEG = 15.0
VALLEY_STARTS = 6
ROUNDS = 8
NEIGHBOUR_RADIUS = 3
MAX_PIXELS = 4000
_SEED = 0


def _prediction(e, w, n, lights, mat):
    """(prediction (N, m), κ (N,)) of the material's model at unit normals n, κ ≥ 0 in closed form."""
    a, b = _terms(n, lights, mat)
    kappa = np.maximum(np.sum(w * b * (e - a), 1) / np.maximum(np.sum(w * b * b, 1), 1e-30), 0.0)
    return a + b * kappa[:, None], kappa


def _resolve(e, w, n, lights, mat):
    sigma, n_i, vm = (1e-3, 1.0, "lambert") if _lambertian(mat) else \
        (mat["sigma"], mat["n_i"], mat.get("volume_model", "tables"))
    return refine_normals_li(e[..., None].astype(np.float32), lights.astype(np.float32), n.astype(np.float32),
                             sigma, n_i, usable=w > 0, volume_model=vm).normals


def _spread(n, solves):
    ang = [np.arccos(np.clip(np.sum(s * n, axis=1), -1.0, 1.0)) for s in solves]
    return np.sqrt(np.mean(np.square(ang), axis=0))


def bootstrap_measures(e, ok, n, lights, labels, materials, shadow, rc, rng=None):
    """{name: (N,) rad, NaN off the drawn pixels} of BOOTSTRAP_CANDIDATES.

    e (N, m) values as the solve saw them (channels' mean, over each pixel's brightest), ok (N, m) usable, n (N, 3)
    unit normals, lights (m, 3), labels (N,) each pixel's index into `materials`, shadow (N, m) or None the solve's
    cast-shadow flags, rc (N, 2) each pixel's row and column (for the neighbours)."""
    out = {k: np.full(len(e), np.nan) for k in BOOTSTRAP_CANDIDATES}
    if np.ndim(lights) != 2 or len(e) == 0:
        return out
    rng = np.random.default_rng(_SEED) if rng is None else rng
    lights = np.asarray(lights, np.float64)
    keep = ok & (n @ lights.T > 0) & (True if shadow is None else ~shadow)
    w = keep.astype(np.float64)
    e = np.where(keep, e, 0.0)
    pred, kappa = np.zeros_like(e), np.zeros(len(e))
    materials = materials or []
    for label in np.unique(labels):
        p = np.flatnonzero(labels == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        pred[p], kappa[p] = _prediction(e[p], w[p], n[p], lights, mat)
    resid = (e - pred) * w
    drawn = np.sort(rng.choice(len(e), min(MAX_PIXELS, len(e)), replace=False))
    index = -np.ones(rc.max(0) + 1, np.intp)
    index[rc[:, 0], rc[:, 1]] = np.arange(len(e))
    wild, near = [], []
    for _ in range(ROUNDS):
        sign = rng.choice((-1.0, 1.0), size=(drawn.size, e.shape[1]))
        off = rng.integers(-NEIGHBOUR_RADIUS, NEIGHBOUR_RADIUS + 1, size=(drawn.size, 2))
        q = index[tuple(np.clip(rc[drawn] + off, 0, np.array(index.shape) - 1).T)]
        q = np.where(q >= 0, q, drawn)
        borrowed = resid[q] / np.maximum(kappa[q], 1e-12)[:, None] * kappa[drawn][:, None]
        for store, r in ((wild, resid[drawn] * sign), (near, borrowed * w[drawn])):
            ws = np.zeros((drawn.size, 3))
            for label in np.unique(labels[drawn]):
                p = np.flatnonzero(labels[drawn] == label)
                mat = materials[label] if 0 <= label < len(materials) else None
                d = drawn[p]
                ws[p] = _resolve(np.maximum(pred[d] + r[p], 0.0) * w[d], w[d], n[d], lights, mat)
            store.append(ws)
    from facette.bench._uncertainty_selfcal import selfcal_shift     # it builds on this module's solve
    out["self-calibration shift"] = selfcal_shift(e, w, n, lights, labels, materials, drawn)
    out["sector jackknife"][drawn] = sector_jackknife(e[drawn], w[drawn], n[drawn], lights, labels[drawn], materials)
    out["valley spread"][drawn] = valley_spread(e[drawn], w[drawn], n[drawn], lights, labels[drawn], materials)
    out["bootstrap wild"][drawn] = _spread(n[drawn], wild)
    out["bootstrap neighbours"][drawn] = _spread(n[drawn], near)
    return out


def sector_jackknife(e, w, n, lights, labels, materials):
    """(N,) rad: the RMS angle to n of the solves with each azimuth sector's lights left out (module doc)."""
    sector = np.floor((np.arctan2(lights[:, 1], lights[:, 0]) + np.pi) / (2 * np.pi) * SECTORS).astype(int) % SECTORS
    out = np.zeros(len(e))
    for label in np.unique(labels):
        p = np.flatnonzero(labels == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        ends = [_resolve(e[p], w[p] * (sector != k), n[p], lights, mat) for k in range(SECTORS) if np.any(sector == k)]
        out[p] = _spread(n[p], ends)
    return out


def _starts(e, w, n, lights):
    """(K, N, 3) the other starts: the Lambertian normal of the kept lights, the brightest kept light's half
    vector, n tilted by VALLEY_TILT_DEG along ± each tangent."""
    lw = lights[None] * w[..., None]
    a = np.einsum("nmi,nmj->nij", lw, lw) + 1e-9 * np.eye(3)
    lam = np.linalg.solve(a, np.einsum("nmi,nm->ni", lw, e * w)[..., None])[..., 0]
    half = unc._halves(lights)[np.argmax(e * w, axis=1)]
    t = np.radians(VALLEY_TILT_DEG)
    tilted = [np.cos(t) * n + sgn * np.sin(t) * tv for tv in unc._tangents(n) for sgn in (1.0, -1.0)]
    out = np.stack([lam, half] + tilted)
    out /= np.maximum(np.linalg.norm(out, axis=-1, keepdims=True), 1e-30)
    return np.where(out[..., 2:3] > 0, out, n[None])


def valley_spread(e, w, n, lights, labels, materials):
    """(N,) rad: the likelihood-weighted RMS angle to n of the solve's ends from the other starts (module doc)."""
    out = np.zeros(len(e))
    for label in np.unique(labels):
        p = np.flatnonzero(labels == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        ends = [n[p]] + [_resolve(e[p], w[p], s, lights, mat) for s in _starts(e[p], w[p], n[p], lights)]
        cost = np.stack([np.sum(_li_residual(x.astype(np.float64), e[p], w[p], lights, mat) ** 2, 1) for x in ends])
        dof = np.maximum(w[p].sum(1) - 3, 1)
        s2 = np.maximum(cost[0] / dof, 1e-12)          # the solution's own residual variance
        like = np.exp(-np.clip((cost - cost.min(0)) / (2 * s2), 0, 50))
        ang = np.stack([np.arccos(np.clip(np.sum(x * n[p], 1), -1.0, 1.0)) for x in ends])
        out[p] = np.sqrt(np.sum(like * ang ** 2, 0) / np.sum(like, 0))
    return out


def channel_spread(vals, ok, n, lights, labels, materials, shadow, rng=None):
    """(N,) rad, NaN off the MAX_PIXELS pixels drawn (and everywhere for fewer than 3 channels): the RMS pairwise
    angle of the normals re-solved on each colour channel alone (module doc). vals (N, m, C) the values as the solve
    saw them, ok (N, m) usable; the rest as `bootstrap_measures`."""
    out = np.full(len(vals), np.nan)
    if vals.ndim != 3 or vals.shape[2] < 3 or np.ndim(lights) != 2 or len(vals) == 0:
        return out
    rng = np.random.default_rng(_SEED) if rng is None else rng
    drawn = np.sort(rng.choice(len(vals), min(MAX_PIXELS, len(vals)), replace=False))
    lights = np.asarray(lights, np.float64)
    nd = n[drawn]
    keep = ok[drawn] & (nd @ lights.T > 0) & (True if shadow is None else ~shadow[drawn])
    materials = materials or []
    solves = []
    for c in range(3):
        e = np.where(keep, np.nan_to_num(vals[drawn, :, c]), 0.0)
        e = e / np.maximum(e.max(1, keepdims=True), 1e-30)
        sol = np.zeros_like(nd)
        for label in np.unique(labels[drawn]):
            p = np.flatnonzero(labels[drawn] == label)
            mat = materials[label] if 0 <= label < len(materials) else None
            sol[p] = _resolve(e[p], keep[p].astype(np.float64), nd[p], lights, mat)
        solves.append(sol)
    pairs = [np.arccos(np.clip(np.sum(solves[a] * solves[b], 1), -1.0, 1.0)) for a, b in ((0, 1), (1, 2), (0, 2))]
    out[drawn] = np.sqrt(np.mean(np.square(pairs), axis=0))
    return out


def case_profiles(images, sel, saturation=None):
    """(images as (m, H, W, C), (m, H, W), the flat indices of sel's pixels, their values (m, N, C), their
    (N, m) profiles (the channels' mean; 0 where not usable), usable (N, m): finite and under saturation)."""
    images = np.asarray(images)
    images = images[..., None] if images.ndim == 3 else images
    m, h, w, _ = images.shape
    idx = np.flatnonzero(np.asarray(sel, bool).ravel())
    vals = images.reshape(m, h * w, -1)[:, idx].astype(np.float64)
    e = vals.mean(axis=2).T
    ok = np.isfinite(e) & (True if saturation is None else np.all(vals < saturation, axis=2).T)
    return images, (m, h, w), idx, vals, np.where(ok, e, 0.0), ok


def bootstrap_from_case(images, lights, normals, sel, model, saturation=None):
    """bootstrap_measures over the pixels of sel (row-major), from images (m, H, W[, C]) as the solve saw them and
    the solve's model (materials, material map (H, W), shadow (H, W, m) or None)."""
    images, (m, h, w), idx, _, e, ok = case_profiles(images, sel, saturation)
    e = e / np.maximum((e * unc._carrying(e, ok)).max(1, keepdims=True), 1e-30)
    n = np.asarray(normals, np.float64).reshape(-1, 3)[idx]
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    materials, labels, shadow = model if model is not None else (None, None, None)
    labels = np.full(idx.size, -1) if labels is None else np.asarray(labels).reshape(-1)[idx]
    shadow = None if shadow is None else np.asarray(shadow, bool).reshape(h * w, m)[idx]
    rc = np.stack(np.unravel_index(idx, (h, w)), axis=1)
    return bootstrap_measures(e, ok, n, np.asarray(lights, np.float64), labels, materials, shadow, rc)
