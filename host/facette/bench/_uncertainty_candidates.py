"""Measures of a normal's reliability that were tried for the band and not taken (`facette bench
uncertainty --candidates`): each is printed as its Spearman against the true error, beside the band,
so that the choice can be checked on any render or photograph.

Per pixel, on the lights that carry it (recon._uncertainty._carrying: lit, unsaturated, the brightest
DROP_BRIGHT share left out), with e the values over the pixel's brightest carrying one:
- `jackknife`: the spread of the Lambertian solve when each carrying light is dropped in turn, by
  rank-one downdates (Sherman–Morrison) of the 3x3 normal matrix A = Σ l lᵀ: with r_i the residual of
  light i and h_i = l_iᵀ A⁻¹ l_i its leverage, dropping it moves the solution b by
  Δb_i = −A⁻¹ l_i r_i / (1 − h_i) (exact). The angle of Δb_i across b, as the jackknife's RMS
  sqrt((k−1)/k Σ_i angle_i²), k the carrying lights;
- `lambertian residual`: that solve's relative residual |r| / |e|;
- `kept lights`: how many carry the pixel (fewer: less known), as −k so that a high value is a poor pixel;
- `kept conditioning`: 1 / the smallest eigenvalue of A / k (lights all on one side or near one direction);
- `kept spread`: 1 − the mean n·l of the carrying lights (near grazing);
- `angle to lambertian`: between the given normal and that solve's;
- `table residual`: the relative residual of each pixel against one isotropic table T(n·l, θ_h) shared
  by all the pixels (16 x 16 bins of the cosine and of the half-angle, an albedo per pixel; 3
  alternations): what one reflectance for the whole object does not explain (cast shadows,
  inter-reflections, a second material);
- `local fit`, `curl`: the band's two terms alone (recon._uncertainty);
- with the solve's model (`model`: li_alternating's materials, each pixel's material and its cast-shadow
  flags) the default's own curvature and two half-light solves (bench._uncertainty_li: `li laplace`,
  `li crb`, `li split`, and the fitted model's residual at the highlight and the Lambertian solve on the lights
  both keep);
- the physically grounded measures of bench._uncertainty_physics (the normal's tilt, the lights in front of the
  facet, highlights, cast shadows, light from behind, the distances to an edge and to a cast shadow, the
  normal field's variation at two scales);
- the non-local measures of bench._uncertainty_global (the angle to the whole field's least-squares surface at
  two scales, the sky and the lights that surface hides, its concavity) and, with the solve's model, the
  re-solves of bench._uncertainty_bootstrap (a residual bootstrap through the default's per-pixel solve, the
  cost's other valleys, a sector jackknife, the lights' calibration, each colour channel alone).
"""
import numpy as np
from scipy.stats import spearmanr

from facette.bench._uncertainty_bootstrap import BOOTSTRAP_CANDIDATES, bootstrap_measures, case_profiles, channel_spread
from facette.bench._uncertainty_global import GLOBAL_CANDIDATES, global_measures
from facette.bench._uncertainty_li import LI_CANDIDATES, li_measures
from facette.bench._uncertainty_physics import PHYSICS_CANDIDATES, physics_measures
from facette.recon import _uncertainty as unc

__all__ = ["jackknife_lambertian", "table_residual", "candidate_measures", "candidate_spearman", "measure_spearman",
           "CANDIDATES", "LI_CANDIDATES", "PHYSICS_CANDIDATES", "GLOBAL_CANDIDATES", "BOOTSTRAP_CANDIDATES"]

CANDIDATES = ("jackknife", "lambertian residual", "kept lights", "kept conditioning", "kept spread",
              "angle to lambertian", "table residual", "local fit", "curl")
TABLE_BINS = 16


def jackknife_lambertian(e, w, lights):
    """(jackknife RMS angle (rad), relative residual, smallest eigenvalue of A / k, unit solve (N, 3)).

    e (N, m) values, w (N, m) 0/1 carrying weights, lights (m, 3) or (N, m, 3)."""
    L = np.broadcast_to(lights, e.shape + (3,)) if lights.ndim == 2 else lights
    lw = L * w[..., None]
    a = np.einsum("nmi,nmj->nij", lw, lw) + 1e-9 * np.eye(3)
    a_inv = np.linalg.inv(a)
    b = np.einsum("nij,nj->ni", a_inv, np.einsum("nmi,nm->ni", lw, e * w))
    r = (e - np.einsum("nmi,ni->nm", L, b)) * w
    ail = np.einsum("nij,nmj->nmi", a_inv, L)
    lev = np.einsum("nmi,nmi->nm", L, ail) * w
    moved = -ail * (r / np.maximum(1 - lev, 1e-3))[..., None]          # b_(i) − b, Sherman–Morrison
    norm = np.maximum(np.linalg.norm(b, axis=1), 1e-30)
    unit = b / norm[:, None]
    across = moved - np.einsum("nmi,ni->nm", moved, unit)[..., None] * unit[:, None, :]
    angle = np.linalg.norm(across, axis=-1) / norm[:, None]
    k = w.sum(1)
    jack = np.sqrt(np.maximum(k - 1, 1) / np.maximum(k, 1) * (angle ** 2 * w).sum(1))
    rel = np.sqrt((r ** 2).sum(1) / np.maximum(((e * w) ** 2).sum(1), 1e-30))
    smallest = np.linalg.eigvalsh(a)[:, 0] / np.maximum(k, 1)
    return jack, rel, smallest, unit


def table_residual(e, ok, normals, lights, bins=TABLE_BINS, rounds=3):
    """(N,) relative residual of each pixel against one isotropic table T(n·l, θ_h) shared by all.

    e (N, m) values, ok (N, m) usable, normals (N, 3) unit, lights (m, 3) or (N, m, 3)."""
    halves = unc._halves(lights)
    dot = (lambda d: normals @ d.T) if lights.ndim == 2 else (lambda d: np.einsum("ni,nmi->nm", normals, d))
    nl, nh = dot(lights), dot(halves)
    use = ok & (nl > 0)
    col = np.clip((np.clip(nl, 0, 1) * bins).astype(np.intp), 0, bins - 1)
    row = np.clip((np.arccos(np.clip(nh, 0, 1)) / (np.pi / 2) * bins).astype(np.intp), 0, bins - 1)
    cell = col * bins + row
    albedo = np.ones(len(e))
    for _ in range(rounds):
        total = np.bincount(cell[use], weights=(e / albedo[:, None])[use], minlength=bins * bins)
        table = total / np.maximum(np.bincount(cell[use], minlength=bins * bins), 1)
        pred = np.where(use, table[cell], 0.0)
        albedo = np.maximum((pred * e * use).sum(1) / np.maximum((pred * pred).sum(1), 1e-30), 1e-6)
    r = (e - albedo[:, None] * pred) * use
    return np.sqrt((r ** 2).sum(1) / np.maximum(((albedo[:, None] * pred) ** 2).sum(1), 1e-30))


def candidate_measures(images, light_dirs, normals, sel, saturation=None, model=None):
    """{name: (N,) measure, high = unreliable} over the pixels of `sel` (row-major order).

    images (m, H, W) or (m, H, W, C) as the solve saw them, light_dirs (m, 3) or (H, W, m, 3),
    normals (H, W, 3), sel (H, W) bool (pixels with a normal). model: (materials, material (H, W),
    shadow (H, W, m) or None) of the solve (PSResult.info["materials"], .material, .shadow) for the
    LI_CANDIDATES; None leaves them out."""
    images, (m, h, w), idx, vals, e, ok = case_profiles(images, sel, saturation)
    raw = e
    carry = unc._carrying(e, ok)
    e = e / np.maximum((e * carry).max(1, keepdims=True), 1e-30)
    lights = np.asarray(light_dirs, np.float64)
    lights = lights if lights.ndim == 2 else lights.reshape(h * w, m, 3)[idx]
    n = np.asarray(normals, np.float64).reshape(-1, 3)[idx]
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    jack, rel, smallest, lam = jackknife_lambertian(e, carry, lights)
    k = carry.sum(1)
    nl = n @ lights.T if lights.ndim == 2 else np.einsum("ni,nmi->nm", n, lights)
    mask = np.asarray(sel, bool)
    has = np.linalg.norm(normals, axis=-1) > 0.5
    fit = unc._fit_band(images, light_dirs, np.asarray(normals, np.float64), mask, saturation, None, unc.MAX_VALUES)
    out = {"jackknife": jack, "lambertian residual": rel, "kept lights": -k,
            "kept conditioning": 1 / np.maximum(smallest, 1e-12),
            "kept spread": 1 - (nl * carry).sum(1) / np.maximum(k, 1),
            "angle to lambertian": np.arccos(np.clip(np.sum(lam * n, axis=1), -1, 1)),
            "table residual": table_residual(e, ok, n, lights),
            "local fit": fit.ravel()[idx], "curl": unc.curl_angle(normals, has).ravel()[idx]}
    out.update(physics_measures(raw, ok, n, lights, mask, normals))
    out.update(global_measures(normals, mask, light_dirs))
    if model is not None and model[1] is not None:
        materials, labels, shadow = model
        shadow = None if shadow is None else np.asarray(shadow, bool).reshape(h * w, m)[idx]
        labels = np.asarray(labels).reshape(-1)[idx]
        out.update(li_measures(e, ok, n, lights, labels, materials, shadow))
        rc = np.stack(np.unravel_index(idx, (h, w)), axis=1)
        out.update(bootstrap_measures(e, ok, n, lights, labels, materials, shadow, rc))
        out["channel spread"] = channel_spread(vals.transpose(1, 0, 2), ok, n, lights, labels, materials, shadow)
    return out


def candidate_spearman(images, light_dirs, normals, sel, err, saturation=None, model=None):
    """{name: Spearman of the measure against err (N,) on the pixels of sel} (nan when constant; NaN
    values, pixels a measure did not draw, are left out; inf ranks last)."""
    return measure_spearman(candidate_measures(images, light_dirs, normals, sel, saturation, model), err)


def measure_spearman(measures, err):
    """{name: Spearman of each measure (N,) of `measures` against err (N,)} (nan when constant; NaN values left out)."""
    out = {}
    for name, v in measures.items():
        f = ~np.isnan(v)          # the re-solves are drawn on a subsample: scored on the pixels they have
        good = f.sum() > 2 and len(np.unique(v[f])) > 1 and np.ptp(err[f]) > 0
        out[name] = float(spearmanr(v[f], err[f]).statistic) if good else float("nan")
    return out
