"""Per-pixel normals and K_d against a given LI reflectance model (the inner step of BRDF-aware
photometric stereo; the alternation with the BRDF fit is facette.fit.ps_li_alternating).
It lives in facette.fit beside the alternation it serves, whose (σ, n_i) fit is BRDF
identification (docs/ARCHITECTURE.md).

Each pixel's values over the m lights, E_ic (light i, channel c, divided by the light's
intensity), are matched to the LI model E = A(n, s_i) + B(n, s_i) κ_c (facette.brdf.li_shading_terms)
by a robust Gauss–Newton (Levenberg–Marquardt) on the 2-D tangent-plane parameterisation of the
normal, with κ_c (hence K_d per channel) solved in closed form at every step (variable projection),
all pixels at once (arrays (N, m, C); no loop over pixels). Loss: Cauchy,
ρ(r) = log(1 + (r / c_p)²) with a per-pixel scale c_p (1.4826 × the median absolute residual at
the start, at least 3 % of the pixel's mean value), so that a light the model cannot explain (an
inter-reflection, a cast shadow it did not see) weighs little. Left out: values that are not
usable (NaN, saturated) and cast shadows (observed < 25 % of the model's prediction at the start).
"""
import numpy as np

from facette.brdf import kd_from_kappa, li_shading_terms
from facette.brdf._fresnel import check_n_i

from ._orientation import search_start

__all__ = ["refine_normals_li", "RefineResult", "CAST_SHADOW_RATIO"]

CAST_SHADOW_RATIO = 0.25   # observed / predicted (green) below this: a cast shadow, left out
SCALE_FLOOR = 0.03         # Cauchy scale at least this fraction of the pixel's mean value
STEP_FD = 1e-3             # rad, forward-difference step on the normal
MAX_STEP = 0.15            # rad, largest normal update per iteration
STEP_TOL = 2e-4            # rad (0.011°), a pixel has converged once an accepted step is below this


class RefineResult:
    """normals (N, 3) unit; kappa (N, C) ≥ 0; kd (N, C) in [0, 1]; used (N, m) bool (values
    kept); cost (N,) robust cost per pixel at the end; rel_residual (N,) RMS of the kept
    residuals over the RMS of the kept values; iterations run; evaluations of the model."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def _tangents(n):
    """Two unit vectors (N, 3) orthogonal to n and to each other."""
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.float32([[0, 0, 1]]), np.float32([[1, 0, 0]]))
    t1 = np.cross(n, ref)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def _unit(v):
    """Rows scaled to unit length; zero rows become +z (a defined normal, never NaN)."""
    ln = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(ln > 1e-12, v / np.maximum(ln, 1e-12), np.float32([[0, 0, 1]])).astype(np.float32)


def _cauchy_scale(r, keep, mean_e):
    """(N, 1, 1) Cauchy scale: 1.4826 × the median |residual| of the kept values, at least
    SCALE_FLOOR × the pixel's mean value (and > 0)."""
    absr = np.where(keep[..., None], np.abs(r), np.nan).reshape(len(r), -1)
    absr[~keep.any(1)] = 0                                  # no kept value: no all-NaN row
    med = np.nanmedian(absr, axis=1) if len(r) else np.zeros(0, np.float32)
    return np.maximum(np.maximum(1.4826 * med, SCALE_FLOOR * mean_e), 1e-12).astype(np.float32)[:, None, None]


def _kappa(e, a, b, w):
    """Weighted least-squares κ (N, C) for E ≈ a + b κ; w (N, m) or (N, m, C)."""
    if w.ndim == 2:
        w = w[..., None]
    wb = w * b[..., None]
    den = np.sum(wb * b[..., None], axis=1)
    num = np.sum(wb * (e - a[..., None]), axis=1)
    return np.maximum(num / np.maximum(den, 1e-20), 0).astype(np.float32)


ENGINES = ("auto", "compiled", "arrays")


def refine_normals_li(e, lights, normals, sigma, n_i, usable=None, iterations=12, kappa=None,
                      extra_starts=None, extra_rows=None, engine="auto", step_tol=STEP_TOL,
                      volume_model="approx", table_grid=None, search=False):
    """Robust per-pixel normals and K_d against the LI model of given (σ, n_i); see
    `_refine_one_start` for the arguments. extra_starts : optional (K, N, 3) other starting
    normals (e.g. the half-vector of a pixel's brightest light: a highlight says where the normal
    is); every start is refined and the one with the lowest robust cost is kept per pixel.
    extra_rows : optional (N,) bool, the pixels for which the extra starts are tried (default all).
    step_tol : rad; the compiled engine stops a pixel once an accepted step is below it (the
        array engine uses STEP_TOL).
    engine : "compiled" (the per-pixel loop of facette.fit._normals_li_jit: distant lights, at
        most one extra start, no kappa given), "arrays" (whole-array numpy passes: any lights),
        or "auto" (compiled where it applies). The compiled one solves the normal on the channels'
        mean (the same model: the lobe is white; K_d per channel after, in closed form) and takes
        the volume part from a per-light table of normals (≤ ~4e-3 relative, p99), so on one
        channel the two agree to a small fraction of a degree, not bit for bit; on RGB the robust
        scale differs (36 residuals against 12).
    volume_model : the LI volume part, "approx" (eq 3.49–3.57) or "tables" (eq 3.15 by quadrature
        tables; facette.brdf.li_shading_terms), or "lambert".
    table_grid : the compiled engine's table of the volume part, points per axis (default
        TABLE_GRID of facette.fit._normals_li_jit, 257); a coarser one costs less to build.
    search : also search the visible hemisphere for a start where the given normal explains the
        pixel poorly (facette.fit._orientation; distant lights): that candidate replaces the
        first extra start on the pixels where it explains them better than the given normal.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine = {engine!r}: choose one of {', '.join(ENGINES)}")
    fits_compiled = (np.ndim(lights) == 2 and kappa is None
                     and (extra_starts is None or len(extra_starts) <= 1))
    if engine == "compiled" and not fits_compiled:
        raise ValueError("engine = 'compiled' takes distant lights (m, 3), at most one extra start "
                         "and no starting kappa; use engine='arrays' for the others")
    if search and np.ndim(lights) == 2:
        extra_starts, extra_rows = _with_search_start(e, lights, normals, sigma, n_i, usable, volume_model,
                                                      extra_starts, extra_rows)
    if engine != "arrays" and fits_compiled:
        return _refine_compiled(e, lights, normals, sigma, n_i, usable, iterations, extra_starts, extra_rows,
                                step_tol, volume_model, table_grid, second_above=0.0 if search else None)
    first = _refine_one_start(e, lights, normals, sigma, n_i, usable, iterations, kappa,
                              volume_model=volume_model)
    if extra_starts is None or len(extra_starts) == 0:
        return first
    best = first
    rows = np.arange(len(normals)) if extra_rows is None else np.flatnonzero(extra_rows)
    if rows.size == 0:
        return first
    s = np.asarray(lights, np.float32)
    s_rows = s if s.ndim == 2 else s[rows]
    u = None if usable is None else np.asarray(usable, bool)[rows]
    for start in extra_starts:
        other = _refine_one_start(np.asarray(e)[rows], s_rows, np.asarray(start)[rows], sigma, n_i, u,
                                  iterations, None, scale=first.scale[rows], volume_model=volume_model)
        win = np.zeros(len(normals), bool)
        win[rows] = other.cost < best.cost[rows]
        wr = win[rows]
        for name in ("normals", "kappa", "kd", "used", "cost", "rel_residual"):
            getattr(best, name)[win] = getattr(other, name)[wr]
        best.evaluations += other.evaluations
        best.iterations = max(best.iterations, other.iterations)
    return best


def _with_search_start(e, lights, normals, sigma, n_i, usable, volume_model, extra_starts, extra_rows):
    """(extra_starts, extra_rows) with the hemisphere search's start in the first extra start's
    place where it explains the pixel better than the given normal (`refine_normals_li`)."""
    e3 = np.asarray(e, np.float32)
    ok = np.ones(e3.shape[:2], bool) if usable is None else np.asarray(usable, bool)
    st, better = search_start(e3, lights, ok, sigma, n_i, volume_model, normals)
    if not better.any():
        return extra_starts, extra_rows
    n_pix = len(st)
    if extra_starts is None or len(extra_starts) == 0:
        return [st], better
    first = np.where(better[:, None], st, np.asarray(extra_starts[0], np.float32))
    rows = np.ones(n_pix, bool) if extra_rows is None else np.asarray(extra_rows, bool)
    return [first, *list(extra_starts)[1:]], rows | better


def _refine_one_start(e, lights, normals, sigma, n_i, usable=None, iterations=12, kappa=None, scale=None,
                      volume_model="approx"):
    """Robust per-pixel normals and K_d against the LI model of given (σ, n_i).

    e : (N, m, C) float image values divided by each light's intensity (NaN: missing).
    lights : (m, 3) unit vectors towards the lights, or (N, m, 3) per pixel (near lights).
    normals : (N, 3) unit starting normals (camera frame).
    sigma, n_i : the material's LI parameters (Beckmann σ ≥ 0, n_i in [1, 100]).
    usable : (N, m) bool, values allowed in the fit (default: finite values); saturated values
        should be False here.
    iterations : Levenberg–Marquardt steps (each: one model evaluation over the N pixels and two of
        the specular lobe alone).
    kappa : optional (N, C) starting κ (default: solved at the start).
    Returns a `RefineResult`. A pixel with fewer than 3 kept values (black is fine: 0 values are
    kept; saturated, missing or shadowed ones are not) keeps its starting normal, K_d from the
    kept values (0 if none) and rel_residual 1.
    """
    rescale = scale is None
    e, s, n = _checked(e, lights, normals)
    n_pix = e.shape[0]
    finite = np.all(np.isfinite(e), axis=2)
    ok = finite if usable is None else (np.asarray(usable, bool) & finite)
    e = np.where(ok[..., None], e, np.float32(0))
    evals = 0
    a, b = li_shading_terms(n, s, sigma, n_i, volume_model=volume_model)
    evals += 1
    keep, kw, mean_e, k, r, scale = _robust_start(e, a, b, ok, kappa, scale)
    active = keep.sum(1) >= 3

    def cost_of(r_, sc):
        return np.sum(np.log1p((r_ / sc) ** 2) * kw[..., None], axis=(1, 2))

    cost = cost_of(r, scale)
    lam = np.full(n_pix, 1e-2, np.float32)
    it = 0
    for it in range(1, int(iterations) + 1):
        if rescale and it in (3, 6):
            # the scale from the starting residuals is too wide to reject an outlier once the
            # normal is near: re-estimate it from the current residuals (and the cost with it)
            r = (e - a[..., None] - b[..., None] * k[:, None, :]) * kw[..., None]
            scale = _cauchy_scale(r, keep, mean_e)
            cost = cost_of(r, scale)
            lam[active] = np.maximum(lam[active], 1e-2)
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        cand, ac, bc, kc, cc, moved = _lm_step(e[idx], kw[idx], n[idx], (s if s.ndim == 2 else s[idx]), a[idx],
                                               b[idx], k[idx], scale[idx], lam[idx], sigma, n_i, volume_model)
        evals += 3     # the lobe twice (the Jacobian), the model once (the candidate)
        better = cc <= cost[idx]
        acc = idx[better]
        n[acc], a[acc], b[acc], k[acc], cost[acc] = cand[better], ac[better], bc[better], kc[better], cc[better]
        lam[acc] = np.maximum(lam[acc] / 3, 1e-4)
        lam[idx[~better]] *= 10
        # converged: the accepted step is below 0.01° or the damping says no step helps
        done = np.zeros(n_pix, bool)
        done[acc] = moved[better] < 2e-4
        done[idx[~better]] = lam[idx[~better]] > 1e3
        active &= ~done
    r = (e - a[..., None] - b[..., None] * k[:, None, :]) * kw[..., None]
    num = np.sqrt(np.sum(r * r, axis=(1, 2)))
    den = np.sqrt(np.sum((e * kw[..., None]) ** 2, axis=(1, 2)))
    # 0 for a black pixel (nothing to explain), 1 where fewer than 3 values were kept (nothing explained)
    rel = np.where(den > 0, num / np.maximum(den, 1e-30), 0).astype(np.float32)
    rel[keep.sum(1) < 3] = 1
    return RefineResult(normals=n, kappa=k, kd=kd_from_kappa(k, n_i, volume_model, sigma), used=keep, cost=cost,
                        rel_residual=rel, iterations=it, evaluations=evals, scale=scale)


def _checked(e, lights, normals):
    """(e (N, m, C) float32, lights float32, normals (N, 3) unit float32) of `_refine_one_start`'s
    arguments; ValueError for a shape that does not fit."""
    e = np.asarray(e, dtype=np.float32)
    if e.ndim == 2:
        e = e[..., None]
    if e.ndim != 3:
        raise ValueError(f"e must have shape (N, m) or (N, m, C), got {e.shape}")
    n_pix, m, c = e.shape
    s_shape = np.shape(lights)
    if s_shape not in ((m, 3), (n_pix, m, 3)):
        raise ValueError(f"lights must have shape ({m}, 3) or ({n_pix}, {m}, 3) for {n_pix} pixels and "
                         f"{m} lights, got {s_shape}")
    if np.shape(normals) != (n_pix, 3):
        raise ValueError(f"normals must have shape ({n_pix}, 3), got {np.shape(normals)}")
    n = _unit(np.asarray(normals, dtype=np.float32).reshape(n_pix, 3))
    return e, np.asarray(lights, dtype=np.float32), n


def _robust_start(e, a, b, ok, kappa, scale):
    """At the starting normal (model terms a, b): the values kept (usable, not a cast shadow),
    κ fitted robustly, and the Cauchy scale per pixel (`scale` when given).
    Returns (keep (N, m), its weights kw, mean kept value (N,), κ (N, C), the residuals (N, m, C)
    and the scale)."""
    c = e.shape[2]
    w0 = ok.astype(np.float32)
    k = _kappa(e, a, b, w0) if kappa is None else np.asarray(kappa, np.float32)
    pred = a[..., None] + b[..., None] * k[:, None, :]
    g_ch = 1 if c == 3 else 0
    cast = ok & (e[..., g_ch] < CAST_SHADOW_RATIO * pred[..., g_ch]) & \
        (pred[..., g_ch] > 0.05 * np.max(pred[..., g_ch], axis=1, keepdims=True))
    keep = ok & ~cast
    kw = keep.astype(np.float32)
    mean_e = np.sum(kw[..., None] * e, axis=(1, 2)) / np.maximum(kw.sum(1) * c, 1)
    k = _kappa(e, a, b, kw)
    r = (e - a[..., None] - b[..., None] * k[:, None, :]) * kw[..., None]
    # robust κ at the starting normal first (IRLS, no new model evaluation): an outlier absorbed
    # into κ would spread its residual over every light and pull the normal
    for _ in range(3):
        sc = _cauchy_scale(r, keep, mean_e) if scale is None else scale
        k = _kappa(e, a, b, kw[..., None] / (1 + (r / sc) ** 2))
        r = (e - a[..., None] - b[..., None] * k[:, None, :]) * kw[..., None]
    if scale is None:   # fixed per pixel for every start, so that the costs compare
        scale = _cauchy_scale(r, keep, mean_e)
    return keep, kw, mean_e, k, r, scale


def _lm_step(ei, kwi, ni, si, ai, bi, ki, scale_i, li, sigma, n_i, volume_model):
    """One Levenberg–Marquardt step of the active pixels (their values, weights, normals, lights,
    model terms, κ, Cauchy scale, damping). Returns the candidate (normals, A, B, κ, robust cost)
    and the length of the step taken (rad)."""
    t1, t2 = _tangents(ni)
    pred0 = ai[..., None] + bi[..., None] * ki[:, None, :]
    r0 = (ei - pred0) * kwi[..., None]
    # IRLS weights of the Cauchy loss: ρ'(r)/r ∝ 1 / (1 + (r/c)²)
    wr = kwi[..., None] / (1 + (r0 / scale_i) ** 2)
    # Jacobian: the lobe A by forward differences (it varies fast, and is cheap: only the pairs
    # near the lobe are evaluated); the volume part B = (n·s) I with I taken as locally
    # constant, dB/dt ≈ (B / n·s)(s·t). The cost and κ are always evaluated exactly, so this
    # changes the path, not the minimum.
    cs_i = ni @ si.T if si.ndim == 2 else np.einsum("nj,nmj->nm", ni, si)
    b_over = np.where(cs_i > 1e-4, bi / np.maximum(cs_i, 1e-4), 0)
    jac = []
    for t in (t1, t2):
        au, _ = li_shading_terms(_unit(ni + STEP_FD * t), si, sigma, n_i, volume=False)
        st = t @ si.T if si.ndim == 2 else np.einsum("nj,nmj->nm", t, si)
        jac.append(((au - ai) / STEP_FD)[..., None] + (b_over * st)[..., None] * ki[:, None, :])
    ju, jv = jac
    # variable projection: κ_c is solved again at every candidate, so the step is taken along
    # the Jacobian's part that a change of κ_c cannot mimic (ju − b (Σ w b ju / Σ w b²) per
    # channel, where κ_c > 0: Kaufman's form); without it the normal and κ zig-zag
    wb = wr * bi[..., None]
    sbb = np.sum(wb * bi[..., None], axis=1)
    free = (ki > 0) & (sbb > 1e-30)
    inv = np.where(free, 1 / np.where(free, sbb, 1), 0)
    sbu, sbv, sbr = (np.sum(wb * x, axis=1) for x in (ju, jv, r0))
    huu = np.sum(wr * ju * ju, axis=(1, 2)) - np.sum(sbu * sbu * inv, axis=1)
    hvv = np.sum(wr * jv * jv, axis=(1, 2)) - np.sum(sbv * sbv * inv, axis=1)
    huv = np.sum(wr * ju * jv, axis=(1, 2)) - np.sum(sbu * sbv * inv, axis=1)
    gu = np.sum(wr * ju * r0, axis=(1, 2)) - np.sum(sbu * sbr * inv, axis=1)
    gv = np.sum(wr * jv * r0, axis=(1, 2)) - np.sum(sbv * sbr * inv, axis=1)
    huu_d, hvv_d = huu * (1 + li) + 1e-20, hvv * (1 + li) + 1e-20
    det = huu_d * hvv_d - huv * huv
    det = np.where(np.abs(det) > 1e-30, det, 1e-30)
    du = (hvv_d * gu - huv * gv) / det
    dv = (huu_d * gv - huv * gu) / det
    step = np.sqrt(du * du + dv * dv)
    shrink = np.minimum(1, MAX_STEP / np.maximum(step, 1e-12))
    cand = _unit(ni + (du * shrink)[:, None] * t1 + (dv * shrink)[:, None] * t2)
    ac, bc = li_shading_terms(cand, si, sigma, n_i, volume_model=volume_model)
    kc = _kappa(ei, ac, bc, wr)
    rc = (ei - ac[..., None] - bc[..., None] * kc[:, None, :]) * kwi[..., None]
    cc = np.sum(np.log1p((rc / scale_i) ** 2) * kwi[..., None], axis=(1, 2))
    return cand, ac, bc, kc, cc, step * shrink


def _refine_compiled(e, lights, normals, sigma, n_i, usable, iterations, extra_starts, extra_rows, step_tol,
                     volume_model, table_grid=None, second_above=None):
    from ._normals_li_jit import refine_distant_compiled, volume_table
    e = np.asarray(e, np.float32)
    if e.ndim == 2:
        e = e[..., None]
    if e.ndim != 3:
        raise ValueError(f"e must have shape (N, m) or (N, m, C), got {e.shape}")
    n_pix, m, _ = e.shape
    if np.shape(lights) != (m, 3):
        raise ValueError(f"lights must have shape ({m}, 3) or ({n_pix}, {m}, 3) for {n_pix} pixels and "
                         f"{m} lights, got {np.shape(lights)}")
    if np.shape(normals) != (n_pix, 3):
        raise ValueError(f"normals must have shape ({n_pix}, 3), got {np.shape(normals)}")
    check_n_i(n_i)
    ok = np.ones((n_pix, m), bool) if usable is None else np.asarray(usable, bool)
    extra = None if extra_starts is None or len(extra_starts) == 0 else np.asarray(extra_starts[0])
    nrm, k, used, cost, rel, its = refine_distant_compiled(
        e, lights, normals, sigma, n_i, ok, iterations, extra_start=extra, extra_rows=extra_rows,
        cast_ratio=CAST_SHADOW_RATIO, floor=SCALE_FLOOR, max_step=MAX_STEP,
        step_tol=step_tol, volume_model=volume_model, second_above=second_above,
        table=None if table_grid is None else volume_table(lights, sigma, n_i, grid=table_grid, volume_model=volume_model))
    return RefineResult(normals=nrm, kappa=k, kd=kd_from_kappa(k, n_i, volume_model, sigma), used=used, cost=cost,
                        rel_residual=rel, iterations=int(its.max()) if its.size else 0,
                        mean_iterations=float(its.mean()) if its.size else 0.0,
                        evaluations=None, scale=None)
