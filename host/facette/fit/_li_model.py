"""The material model of BRDF-aware photometric stereo: the LI model's shared (σ, n_i) fitted on
pixels of known normals, and round 1's choice of model by the profile of the robust cost.

    fit_li_per_pixel_kd(e, lights, normals, usable, ...) -> dict(sigma, n_i, kd, ...)
    li_fit_cost(e, lights, normals, usable, sigma, n_i, ...) -> float
    choose_material_model(e, lights, usable, solve, volume_models, check=None) -> (fit, refits, choice)

Used by facette.fit._ps_li (ps_li_alternating); the volume part and the lobe are
facette.brdf.li_shading_terms (eq 3.10, 3.15).
"""
import time

import numpy as np
from scipy.optimize import least_squares

from facette._threads import run_blocks
from facette.brdf import kd_from_kappa, li_shading_terms
from ._li_fit_lm import li_jacobian, robust_lm
from ._li_line_search import line_search as _line_search
from ._li_noise import relative_floor

__all__ = ["choose_material_model", "fit_bounds", "METAL_FIT_BOUNDS", "fit_li_per_pixel_kd", "li_fit_cost", "LI_FIT_BOUNDS", "LI_VOLUME_MODEL", "DIFFUSE", "LOBE_MIN_GAIN"]

LI_FIT_BOUNDS = ((1e-3, 1.0), (1.0, 2.5))   # σ, n_i (σ ≤ 1: beyond it no lobe is left to see)
# Beside a Lambertian part the lobe may be a metal's: its index then stands for the conductor's
# reflectance at normal incidence (facette.brdf._fresnel.check_n_i; aluminium ~38, gold ~10-20 in
# green). At the true normals of Mitsuba's roughconductor spheres this model fits σ 0.150 (gold,
# α 0.15) and 0.300 (aluminium, α 0.3) and the per-pixel solve from the truth stays within 0.5 and
# 0.04°; the LI substrate (n_i ≤ 2.5) fits 0.194 / 0.396 and moves them by 3.5 and 23°.
METAL_FIT_BOUNDS = ((1e-3, 1.0), (1.0, 100.0))
# The (σ, n_i) fits' Jacobian: analytic for these diffuse parts (facette.brdf._shading_grad), a
# finite difference (two more model evaluations a step) for the approximate formula
ANALYTIC_JACOBIAN = ("tables", "coupled", "lambert")
LAMBERTIAN_N_I = 1.02      # a fitted n_i below this: no interface, the BRDF step is skipped
LAMBERTIAN_SIGMA = LI_FIT_BOUNDS[0][0]    # the model without interface (n_i = 1): Lambert
# a lobe must lower the trimmed profile cost this much against Lambert's (Mitsuba renders: plaster
# sphere / relief / vase −20.5 / −0.3 / +4.4 %, a false lobe there costs the vase 0.41° and the
# relief 0.03°; paints and satin 74–99 %; the simulated scan 54 %): twice the matte renders' most
LOBE_MIN_GAIN = 0.1
# A lobe's fit that ends without an interface though its grid point cleared the bar is made again on
# the pixels whose costs cleared it (`_warm_up`), under at most this many lights: the bar is measured
# on the trimmed PROFILE_KEEP of the pixels, the fit counts all of them, and under 12 lights a few
# pixels whose solve stopped on the lobe's peak carry most of the cost (8-bit dark paint crater field,
# rig12: the 5 % costliest of the profile pixels 64 % of it, each 100 × its mean off at one light),
# and the fit slides to n_i 1 to lower them (cost 1152 -> 386; at σ 0.06, n_i 1.15: 271). Above it
# (96 lights, domes) nothing changes. Chosen on the 8 concave paint renders under the rig's 12 lights
# (bench concave), mean errors summed: 8-bit 18.11 -> 16.36°, 16-bit 12.00 -> 11.72°; every fit on the
# kept pixels instead (not only one that slid): 15.77 / 13.88° (the paint 0.10 scenes 0.3-0.8° worse,
# σ, n_i held near the grid), dropped. DiLiGenT crops, 12 lights: it never runs (normals identical).
KEPT_MAX_LIGHTS = 16
_STARTS = ((0.1, 1.3), (0.3, 1.5), (0.04, 1.2))
# The volume part eq 3.15 from quadrature tables (facette.brdf.volume_table_at), not the approximate
# formula eq 3.49-3.57, which is 3-5 % off the integral at the median and 10-20 % at grazing angles.
# Mitsuba, 256 spp, mean normal error approx -> tables: sphere paint 0.10 1.10 -> 0.46 deg, 0.05
# 0.48 -> 0.19, satin 2.93 -> 1.98, near lights 1.17 -> 0.53, shell lacquer 0.91 -> 0.58; the relief
# paints with inter-reflections removed 0.54-0.74 -> 0.42-0.46; K_d/true 0.97-1.10 -> 0.99-1.03.
# Worse: the reliefs' raw paints 0.53-0.59 -> 0.56-0.66 and the glossy vase 3.12 -> 3.32, whose error
# is the inter-reflections' (with them removed, facette.fit.ps_li_without_interreflections: 1.38).
# Costs 0-2 s more at 128² (node tables, 0.03-0.05 s each, cached in the process).
LI_VOLUME_MODEL = "tables"
# Round 1's model choice (`_profile_lobe`): a grid of (σ, n_i), each diffuse part, the fit pixels'
# normals solved against each point, scored by the summed robust cost of the PROFILE_KEEP best
# explained fit pixels. Fitting (σ, n_i) on the initial normals, as before, is pulled to no lobe by
# the few pixels whose robust normal is a degree off where the lobe is steep: on the simulated
# rig's scan (Cook–Torrance σ 0.05, n_i 1.2, dark glossy table) it found σ 0.017, n_i 1.06 on the
# initial normals and σ 0.035 on normals solved against each point with every pixel counted; the
# best 80 % give σ 0.050, n_i 1.200, and the lobe lowers their cost to 46 % of Lambert's.
# The search: σ along PROFILE_SIGMAS at n_i PROFILE_N_I0, then n_i along PROFILE_N_IS at that line's best σ
# (and a metal's start the same way, on its own lines: `_profile_lobe`)
# (each line walked as PROFILE_SIGMA_SEARCH and PROFILE_N_I_SEARCH say),
# for each diffuse part (at most 14 solves of the profile pixels each), on at most PROFILE_VALUES values (pixels ×
# lights): a full 8 × 3 grid stopped at n_i 1.15 on the scan above (truth 1.2; the search: 1.2).
# σ 0.4 between 0.3 and 0.5: a broad lobe's cost is a narrow valley along σ and n_i together, and
# the step 0.3 -> 0.5 missed it (Mitsuba rough plastic sphere, σ 0.4, n_i 1.5: the coupled part's
# best grid cost 2.50 against 0.30 once σ 0.4 is on the grid, so Lambert's won: 2.30° -> 1.62°).
PROFILE_SIGMAS = (0.02, 0.035, 0.05, 0.08, 0.13, 0.2, 0.3, 0.4, 0.5)
PROFILE_N_I0 = 1.3
PROFILE_N_IS = (1.1, 1.2, 1.45, 1.7, 2.0)
# beside a Lambertian part also a metal's lobe (F0 0.25, 0.5, 0.77, 0.9), σ searched at a metal's
# index too (its lobe is 10-20x a dielectric's: the σ that fits best at PROFILE_N_I0 says nothing of it)
PROFILE_N_IS_METAL = (3.0, 6.0, 15.0, 40.0)
PROFILE_N_I0_METAL = 15.0
PROFILE_KEEP = 0.8
PROFILE_VALUES = 12_000
PROFILE_TABLE_GRID = 65
# The grid search's solves (`_profile_lobe`: one per grid point and diffuse part, ~55 with 3 diffuse
# parts) interpolate the volume part B from a table per (σ, n_i) of this many points per axis; at 65
# the ~55 tables took 3.2 of DiLiGenT cat's 15.4 CPU s (96 lights, one thread). At 33 a table costs a
# quarter; B is within 0.25 % at the median (65: 0.06 %) but 8 % at the 99th percentile (65: 1.5 %),
# at grazing normals. The search only ranks grid points; the warm-ups and the check (`_gain_on`,
# `_diffuse_at_fits`), which fit (σ, n_i) and decide the bar and the diffuse part on oblique pixels,
# keep PROFILE_TABLE_GRID: all at 33, the test sphere of the coupled diffuse part was still chosen
# but at 0.94 of LI's cost, not < 0.8 (tests/fit/test_ps_li.py).
# Renders (`bench lights` relief 481x466, 65 -> 33): satin 12/48/96 lights 0.3194/0.0715/0.0510 ->
# 0.3194/0.0715/0.0511°, glossy 12/48 0.4404/0.0703 -> 0.4405/0.0692°; DiLiGenT crops, 96 lights:
# 6.263 -> 6.237° (no crop worse by more than 0.001°).
PROFILE_SEARCH_GRID = 33
# How each line of the search is walked (`_line_search`): σ coarse-to-fine (every other σ, then the
# best one's neighbours: 6-7 solves for 9), n_i downhill from the σ line's best point (2-3 solves for
# 5 where the profile is lowest near n_i 1.3, as on every DiLiGenT crop). "all" is the full line.
# DiLiGenT crops, 96 lights (process's inputs): 61 -> 43-49 solves, the same grid point chosen on
# all five.
PROFILE_SIGMA_SEARCH = "coarse-to-fine"
PROFILE_N_I_SEARCH = "downhill"
# The diffuse part beside the lobe: the LI substrate under the interface (eq 3.15: Fresnel
# transmissions in and out through the facets), a Lambertian term with no transmission
# (Cook–Torrance), or a Lambertian substrate weighted by the interface's transmittance in and out
# (Kelemen & Szirmay-Kalos 2001, the facets' single-scattering transmittance: facette.brdf._coupled).
# Which one a material gets is its fit pixels' profile cost (`diffuse="auto"`), never a fixed
# choice: the simulated rig renders Cook–Torrance, Mitsuba's roughplastic a layered material.
DIFFUSE = {"li": LI_VOLUME_MODEL, "lambert": "lambert", "coupled": "coupled"}


def diffuse_name(volume_model):
    """The DIFFUSE name ("li", "lambert", "coupled") of a volume model, or the model itself (e.g. "approx")."""
    return next((k for k, v in DIFFUSE.items() if v == volume_model), volume_model)


def _relative_fit_values(e, usable):
    """Values, weights, the usable mask per channel and each pixel's mean value (the residuals'
    denominator) of `fit_li_per_pixel_kd` and `li_fit_cost`."""
    e = np.asarray(e, np.float32)
    ok = np.asarray(usable, bool) & np.all(np.isfinite(e), axis=2)
    e0 = np.where(ok[..., None], e, np.float32(0))
    w = ok.astype(np.float32)
    mean_e = np.sum(w[..., None] * e0, axis=(1, 2)) / np.maximum(w.sum(1) * e.shape[2], 1)
    # residuals relative to each pixel's mean value: every pixel weighs alike whatever its K_d, and a
    # highlight's misfit counts in full (relative to the value itself it would count ≤ 1 and
    # missing the lobe altogether would be cheap)
    # ... at least the quantisation noise's floor under few lights when asked for (`_li_noise`: 8-bit darks)
    den = np.maximum(mean_e, max(relative_floor(e, usable), 1e-12))[:, None, None]
    return e0, w, np.broadcast_to(ok[..., None], e.shape), den


def _kd_and_residuals(e0, w, den, normals, lights, sigma, n_i, volume_model):
    """κ (N, C) in closed form (E = A + B κ, weights w) and the relative residuals (N, m, C)."""
    return _residuals_from(e0, w, den, *li_shading_terms(normals, lights, sigma, n_i, volume_model=volume_model))


def _residuals_from(e0, w, den, a, b):
    """`_kd_and_residuals` from the shading terms A, B (N, m)."""
    wb = w * b
    k = np.maximum(np.einsum("nm,nmc->nc", wb, e0 - a[..., None]) / np.maximum(np.sum(wb * b, 1), 1e-20)[:, None], 0)
    return k, (e0 - a[..., None] - b[..., None] * k[:, None, :]) / den


def _soft_l1_cost(r, f_scale):
    """scipy's least_squares cost with loss="soft_l1": ½ Σ 2 f² (√(1 + (r/f)²) − 1)."""
    z = (np.asarray(r, np.float64) / f_scale) ** 2
    return float(np.sum(f_scale ** 2 * (np.sqrt(1 + z) - 1)))


def li_fit_cost(e, lights, normals, usable, sigma, n_i, f_scale=0.05, volume_model=LI_VOLUME_MODEL):
    """The robust cost `fit_li_per_pixel_kd` minimises, at given normals and (σ, n_i): soft-L1
    (scale f_scale) of the relative residuals of every usable value, K_d per pixel and channel in
    closed form. e : (N, m, C); lights : (m, 3) or (N, m, 3); normals : (N, 3); usable : (N, m).
    n_i = 1 is the Lambertian model (no interface: no lobe). Returns a float ≥ 0."""
    e0, w, sel, den = _relative_fit_values(e, usable)
    return _soft_l1_cost(_kd_and_residuals(e0, w, den, normals, lights, sigma, n_i, volume_model)[1][sel],
                         f_scale)


def fit_bounds(volume_model):
    """The (σ, n_i) bounds of the fits with this diffuse part: a metal's index only beside a
    Lambertian part (the LI substrate's tables stop at n_i 2.5)."""
    return METAL_FIT_BOUNDS if volume_model == "lambert" else LI_FIT_BOUNDS


def fit_li_per_pixel_kd(e, lights, normals, usable, x0=None, f_scale=0.05, max_nfev=40, bounds=None,
                        volume_model=LI_VOLUME_MODEL):
    """(σ, n_i) shared by all pixels, K_d per pixel and channel, from image values.

    e : (N, m, C) values divided by the light intensities; lights : (m, 3) or (N, m, 3);
    normals : (N, 3) unit (fixed); usable : (N, m) bool.
    x0 : (σ, n_i) start (alone when it has a lobe: σ > 0.01, n_i > 1.02); otherwise the best
        of three fixed starts and x0.
    f_scale : soft-L1 scale on the relative residual (0.05: 5 % misfits count fully,
        larger ones linearly).
    bounds : ((σ_min, σ_max), (n_i_min, n_i_max)), within `fit_bounds(volume_model)` (the default;
        a narrower n_i range above 1 asks for the best solution with a lobe).
    volume_model : the volume part's evaluation (facette.brdf.li_shading_terms; LI_VOLUME_MODEL).
    Returns dict(sigma, n_i, kd (N, C), kappa (N, C), cost, n_values, seconds, success).
    Residual per value: (E − A − B κ) / (the pixel's mean value).
    """
    t0 = time.perf_counter()
    bounds = fit_bounds(volume_model) if bounds is None else bounds
    e0, w, sel, den = _relative_fit_values(e, usable)
    lo, hi = np.array([b[0] for b in bounds], float), np.array([b[1] for b in bounds], float)
    if not np.all(lo < hi):
        raise ValueError(f"bounds = {bounds!r}: each (low, high) pair needs low < high")

    last = {}

    def fun(p):
        a, b = li_shading_terms(normals, lights, p[0], p[1], volume_model=volume_model)
        last.update(p=tuple(p), a=a, b=b)
        return _residuals_from(e0, w, den, a, b)[1][sel].astype(np.float64)

    flat_sel = sel.ravel()

    def jac(p):        # at the point `fun` was last called at: its shading terms reused
        a, b = (last["a"], last["b"]) if last.get("p") == tuple(p) else (None, None)
        return li_jacobian(e0, w, den, normals, lights, p[0], p[1], volume_model, a, b)[flat_sel].astype(np.float64)

    if not sel.any():
        return dict(success=False, sigma=float("nan"), n_i=float("nan"), message="no usable values to fit")
    # the previous solution and the fixed starts: at σ near its lower bound the lobe is too narrow
    # for a finite-difference gradient, so a start there alone would stay there
    if x0 is not None and x0[0] > 0.01 and x0[1] > LAMBERTIAN_N_I:
        starts = [np.clip(np.asarray(x0, float), lo, hi)]
    else:
        starts = [np.clip(np.array(x), lo, hi) for x in _STARTS] + \
            ([] if x0 is None else [np.clip(np.asarray(x0, float), lo, hi)])
    best = None
    for x in starts:
        x_scale = np.array([0.05, 0.1 * max(1.0, x[1] - 1)])
        # from a metal's index, scipy's trust region (its first steps cross to a dielectric's basin
        # where this LM stayed near the start: the rendered satin sphere of tests/fit/test_light_gains).
        # scipy with the analytic Jacobian instead of the LM: DiLiGenT cat's fits 3.25 CPU s against
        # 2.65 with finite differences and 0.87 in the LM (one thread)
        if volume_model in ANALYTIC_JACOBIAN and not is_metal(x[1]):
            r = robust_lm(fun, jac, x, lo, hi, f_scale, max_nfev, x_scale)
        else:          # the approximate formula: scipy's trust region, a finite-difference Jacobian
            r = least_squares(fun, x, bounds=(lo, hi), loss="soft_l1", f_scale=f_scale, diff_step=1e-3,
                              max_nfev=max_nfev, x_scale=x_scale)
        if best is None or r.cost < best.cost:
            best = r
    k, _ = _kd_and_residuals(e0, w, den, normals, lights, best.x[0], best.x[1], volume_model)
    return dict(success=bool(best.success), sigma=float(best.x[0]), n_i=float(best.x[1]), kappa=k,
                kd=kd_from_kappa(k, best.x[1], volume_model, best.x[0]), cost=float(best.cost), n_values=int(sel.sum()),
                seconds=time.perf_counter() - t0, message=str(best.message))


def _pixel_costs(e, lights, normals, usable, sigma, n_i, volume_model, f_scale=0.05):
    """(N,) each pixel's share of `li_fit_cost` (soft-L1 of its relative residuals)."""
    e0, w, sel, den = _relative_fit_values(e, usable)
    r = _kd_and_residuals(e0, w, den, normals, lights, sigma, n_i, volume_model)[1]
    z = (r.astype(np.float64) / f_scale) ** 2
    return np.sum(np.where(sel, f_scale ** 2 * (np.sqrt(1 + z) - 1), 0), axis=(1, 2))


def _trimmed(costs, keep=PROFILE_KEEP):
    """(sum of the `keep` fraction of smallest per-pixel costs, bool mask of those pixels)."""
    n = max(1, int(round(keep * costs.size)))
    order = np.argsort(costs, kind="stable")
    kept = np.zeros(costs.size, bool)
    kept[order[:n]] = True
    return float(costs[order[:n]].sum()), kept


def _profile_lobe(e, lights, usable, solve, volume_models):
    """Round 1's model choice on the profile pixels: for each diffuse part (`volume_models`), the
    normals solved against each (σ, n_i) of a coordinate search (σ along PROFILE_SIGMAS at
    PROFILE_N_I0, then n_i along PROFILE_N_IS at that line's best σ; beside a Lambertian part also σ
    at PROFILE_N_I0_METAL, then PROFILE_N_IS_METAL at its best σ; `solve(sigma, n_i, volume_model, grid=...)` ->
    (N, 3)), each scored by the trimmed robust cost of the result (`_trimmed`: a pixel whose solve
    stopped in a wrong minimum does not decide the model).
    Returns ({(is a metal's lobe, volume_model): the best such candidate, a dict(cost,
    cost_lambertian: the Lambertian solution's cost on its kept pixels, gain, volume_model, sigma,
    n_i, normals, kept)}, {volume_model: its best trimmed cost}, the number of solves)."""
    def search(vm):
        # one diffuse part's search: its candidates, its best cost, its solves
        best, low, solves = {}, np.inf, 0

        def score(sigma, n_i):
            nonlocal low, solves
            n = solve(sigma, n_i, vm, grid=PROFILE_SEARCH_GRID)
            solves += 1
            cost, kept = _trimmed(_pixel_costs(e, lights, n, usable, sigma, n_i, vm))
            low = min(low, cost)
            key = (is_metal(n_i), vm)
            if key not in best or cost < best[key]["cost"]:
                best[key] = dict(cost=cost, volume_model=vm, sigma=sigma, n_i=n_i, normals=n, kept=kept)
            return cost

        # each start's own valley: its σ line, then its n_i line (the dielectrics' or the metals')
        # at that line's best σ. From the overall best σ only, a metal start's σ decided where the
        # dielectric n_i line ran, and a dielectric valley beside a Lambertian part went unseen
        # (the satin sphere of tests/pipeline/test_process_light_gains: lambert's best 19.9 there,
        # 4.5 at σ 0.13, n_i 1.7), or was found depending on which σ the walk skipped
        for n0, line in ((PROFILE_N_I0, PROFILE_N_IS),) + (((PROFILE_N_I0_METAL, PROFILE_N_IS_METAL),)
                                                          if vm == "lambert" else ()):
            costs = _line_search(PROFILE_SIGMAS, {}, lambda x: score(x, n0), PROFILE_SIGMA_SEARCH)
            sigma = min(costs, key=costs.get)
            _line_search(tuple(sorted(set(line) | {n0})), {n0: costs[sigma]}, lambda x: score(sigma, x),
                         PROFILE_N_I_SEARCH)
        return best, low, solves

    # the diffuse parts' searches are independent: on two threads (the solves' compiled kernel and
    # numpy give the GIL up), merged in their order (the same candidates as one after the other)
    best, per_model, solves = {}, {}, 0
    for vm, (b, low, k) in zip(volume_models, run_blocks(search, volume_models)):
        best.update(b)
        per_model[vm] = low
        solves += k
    # the Lambertian solution scored on each candidate's kept pixels: trimmed on its own, it would
    # drop the highlights, the very pixels that show a lobe (a glossy sphere's few % of pixels)
    n = solve(LAMBERTIAN_SIGMA, 1.0, volume_models[0], grid=PROFILE_SEARCH_GRID)
    costs = _pixel_costs(e, lights, n, usable, LAMBERTIAN_SIGMA, 1.0, volume_models[0])
    for b in best.values():
        b["cost_lambertian"] = float(costs[b["kept"]].sum())
        b["gain"] = 1 - b["cost"] / max(b["cost_lambertian"], 1e-30)
    return best, per_model, solves + 1


def _pick(candidates):
    """(the candidate the bar decides on, the best dielectric one or None) of `_profile_lobe`'s:
    a metal's lobe only where it gains more against Lambert's than the best dielectric's (each on
    its own kept pixels: a metal's global search fits the pixels it keeps at any (σ, n_i)); of the
    diffuse parts, the lower trimmed cost."""
    def top(metal):
        c = [b for (m, _), b in candidates.items() if m == metal]
        return min(c, key=lambda b: b["cost"]) if c else None
    metal, dielectric = top(True), top(False)
    if metal is not None and (dielectric is None or metal["gain"] > dielectric["gain"]):
        return metal, dielectric
    return dielectric, dielectric


def _has_interface(fit):
    """Whether a fit's (σ, n_i) is not Lambertian: an interface (n_i > 1) gives a specular lobe and
    Fresnel transmissions that shape the volume part, even where σ is too small for a lobe to be
    seen (DiLiGenT buddha and cat on 12 lights fit σ < 0.01, n_i 1.07–1.11, and the BRDF step still
    takes their error from 13.8° to 11.1° and 8.6° to 7.2°)."""
    return bool(np.isfinite(fit["sigma"]) and fit["n_i"] >= LAMBERTIAN_N_I)


def is_metal(n_i):
    """Whether an index is a metal's lobe (above the dielectrics' range, see METAL_FIT_BOUNDS)."""
    return n_i > LI_FIT_BOUNDS[1][1]


def _warm_up(e, lights, usable, solve, best):
    """(fit, refits): (σ, n_i) fitted from a grid point on its re-solved normals, the normals
    re-solved against the fit and refit until they settle (at most 3 refits). Under ≤ KEPT_MAX_LIGHTS
    lights a fit from a lobe that cleared the bar but ending without an interface is made again on the
    pixels whose costs cleared it (the grid point's `kept`, else its trimmed PROFILE_KEEP: an earlier
    solve's lobe, `_ps_li_start`; module constant KEPT_MAX_LIGHTS)."""
    fit, warm = _warm_up_on(e, lights, usable, solve, best, slice(None))
    if _has_interface(fit) or np.shape(e)[1] > KEPT_MAX_LIGHTS or best.get("gain", 0.0) < LOBE_MIN_GAIN:
        return fit, warm
    kept = best.get("kept")
    if kept is None:
        kept = _trimmed(_pixel_costs(e, lights, best["normals"], usable, best["sigma"], best["n_i"],
                                     best["volume_model"]))[1]
    if 0 < kept.sum() < kept.size:
        again, more = _warm_up_on(e, lights, usable, solve, best, np.flatnonzero(kept))
        fit, warm = (dict(again, refit_on="kept"), warm + more) if _has_interface(again) else (fit, warm + more)
    return fit, warm


def _warm_up_on(e, lights, usable, solve, best, on):
    """`_warm_up`'s refits, (σ, n_i) fitted on the pixels `on` (an index or slice of the solve's)."""
    vm_, n_f = best["volume_model"], best["normals"]
    fit, warm = dict(sigma=best["sigma"], n_i=best["n_i"]), 0
    e_on, usable_on = np.asarray(e)[on], np.asarray(usable)[on]
    lights_on = lights if np.ndim(lights) == 2 else np.asarray(lights)[on]
    while warm < 3:
        warm += 1
        prev = fit
        fit = fit_li_per_pixel_kd(e_on, lights_on, n_f[on], usable_on, x0=(prev["sigma"], prev["n_i"]),
                                  volume_model=vm_)
        if not _has_interface(fit):
            break
        n_f = solve(fit["sigma"], fit["n_i"], vm_, search=False)
        if abs(fit["sigma"] - prev["sigma"]) < 0.02 * prev["sigma"] and abs(fit["n_i"] - prev["n_i"]) < 0.005:
            break
    return fit, warm


def _gain_on(check, candidates, volume_models):
    """The candidates' cost, Lambert's cost on their kept pixels and the gain, measured again on
    the larger set of pixels `check` = (e, lights, usable, solve) (each candidate dict updated, its
    profile gain kept as profile_gain); the number of solves."""
    e, lights, usable, solve = check
    n = solve(LAMBERTIAN_SIGMA, 1.0, volume_models[0])
    lam = _pixel_costs(e, lights, n, usable, LAMBERTIAN_SIGMA, 1.0, volume_models[0])
    for b in candidates:
        n = solve(b["sigma"], b["n_i"], b["volume_model"])
        cost, kept = _trimmed(_pixel_costs(e, lights, n, usable, b["sigma"], b["n_i"], b["volume_model"]))
        b.update(profile_gain=b["gain"], cost=cost, cost_lambertian=float(lam[kept].sum()))
        b["gain"] = 1 - cost / max(b["cost_lambertian"], 1e-30)
    return 1 + len(candidates)


def _diffuse_at_fits(e, lights, usable, solve, check, candidates, best, fit, choice):
    """(best, fit, warm-up refits): the dielectric diffuse parts whose grid point clears the bar,
    each warmed up to its own (σ, n_i), then scored on the check pixels at that fit; the lowest
    wins. At the grid's points the parts differ by how near each point is to its own optimum (a
    sphere rendered with the coupled part: LI 0.0351 against coupled 0.0366 at σ 0.08, n_i 1.45);
    at their fits, by how well each explains the pixels. `choice` gets the costs."""
    fits, warm = [(best, fit)], 0
    for b in candidates.values():
        if b is best or is_metal(b["n_i"]) or b["gain"] < LOBE_MIN_GAIN:
            continue
        f, w = _warm_up(e, lights, usable, solve, b)
        warm += w
        if _has_interface(f) and not is_metal(f["n_i"]):
            fits.append((b, f))
    if len(fits) == 1:
        return best, fit, warm
    e_c, l_c, ok_c, solve_c = check
    costs = []
    for b, f in fits:
        n = solve_c(f["sigma"], f["n_i"], b["volume_model"], search=False)
        costs.append(_trimmed(_pixel_costs(e_c, l_c, n, ok_c, f["sigma"], f["n_i"], b["volume_model"]))[0])
    choice["fitted_cost_by_diffuse"] = {diffuse_name(b["volume_model"]): c for (b, _), c in zip(fits, costs)}
    b, f = fits[int(np.argmin(costs))]
    return b, f, warm


def choose_material_model(e, lights, usable, solve, volume_models, check=None):
    """Round 1 of ps_li_alternating for one material: lobe or none, which diffuse part, and (σ, n_i).

    e, lights, usable : the profile pixels' values (N, m, C), directions, usable flags.
    solve(sigma, n_i, volume_model, search=True, grid=PROFILE_TABLE_GRID) -> (N, 3): those pixels' normals
        solved against a model (search=False: the converged solve of the rounds; grid: the volume
        part's table, PROFILE_SEARCH_GRID in the grid search).
    check : None, or (e, lights, usable, solve) of other pixels on which each diffuse part's best
        candidate (and the metals') is measured again, the choice among them and the bar decided
        there. `ps_li_alternating` gives a draw of all the material's pixels: the profile's are
        the brighter, less oblique fit pixels (few under many lights: one draw of ~100 pixels
        decided the model, DiLiGenT cat, 96 lights: gain 0.079-0.131 over three seeds, Lambertian
        on one), and there the diffuse parts tie where oblique pixels tell them apart.
    The search (`_profile_lobe`) scores every candidate by its trimmed robust cost; the lobe must
    lower it by LOBE_MIN_GAIN against Lambert's on the same pixels. Returns (fit: dict(sigma, n_i,
    volume_model, ...), warm-up refits, choice: the costs and the reason, for info["materials"]).
    """
    e_f, l_f, ok_f, diffuse_models = e, lights, usable, volume_models
    t_p = time.perf_counter()
    candidates, per_model, solves = _profile_lobe(e_f, l_f, ok_f, solve, diffuse_models)
    if check is not None:          # the best of each diffuse part and of the metals, measured again
        solves += _gain_on(check, list(candidates.values()), diffuse_models)
    best, dielectric = _pick(candidates)
    choice = {"profile_pixels": int(len(e_f)), "profile_solves": solves,
              "profile_seconds": time.perf_counter() - t_p, "trimmed_to": PROFILE_KEEP,
              "cost_by_diffuse": {diffuse_name(k): c for k, c in per_model.items()}}
    if check is not None:
        choice.update(gain_pixels=int(len(check[0])), profile_gain=best["profile_gain"],
                      check_cost_by_diffuse={diffuse_name(b["volume_model"]): b["cost"]
                                             for (metal, _), b in candidates.items() if not metal})
    # (σ, n_i) from the best point, on its re-solved normals, then warmed up (the normals
    # re-solved against the fit, refit) until they settle, every profile pixel counted. Chosen on
    # renders (mean normal error, the simulated scan + Mitsuba sphere paint 0.10, relief paints
    # 0.10 and 0.05, satin sphere): this 0.38 / 0.48 / 0.58 / 0.87 / 1.95°; on the search's kept
    # pixels only 0.38 / 0.40 / 0.81 / 0.88 / 2.39 (σ, n_i stuck near the grid: paint 0.10 gave
    # 0.086, 1.386); starting from the initial normals 0.42 / 0.52 / 0.60 / 0.66 / 2.15.
    fit, warm = _warm_up(e_f, l_f, ok_f, solve, best) if best["gain"] >= LOBE_MIN_GAIN else (None, 0)
    if fit is not None and is_metal(best["n_i"]) and not is_metal(fit["n_i"]) and dielectric is not None:
        # a metal's lobe won the grid, but its fit ends at a dielectric's index: the metal's global
        # search found the normals, not the model (Mitsuba satin sphere: lambert, n_i 40 -> 1.57,
        # 2.84° against 1.95° from the best dielectric point); the best dielectric point instead,
        # held to the same bar
        choice["metal_fit_n_i"] = fit["n_i"]
        best = dielectric
        fit, more = _warm_up(e_f, l_f, ok_f, solve, best) if best["gain"] >= LOBE_MIN_GAIN else (None, 0)
        warm += more
    if check is not None and fit is not None and not is_metal(fit["n_i"]) and _has_interface(fit):
        best, fit, more = _diffuse_at_fits(e_f, l_f, ok_f, solve, check, candidates, best, fit, choice)
        warm += more
    gain, name = best["gain"], diffuse_name(best["volume_model"])
    choice.update(cost_lambertian=best["cost_lambertian"], cost_lobe=best["cost"], gain=gain,
                  grid_sigma=best["sigma"], grid_n_i=best["n_i"])
    if fit is None:
        choice.update(model="lambertian", why=f"the best lobe (σ {best['sigma']:.3f}, n_i {best['n_i']:.2f}, "
                      f"{name} diffuse) lowers the trimmed robust cost by {100 * gain:.1f} % only")
        return dict(sigma=LAMBERTIAN_SIGMA, n_i=1.0, volume_model=diffuse_models[0]), warm, choice
    vm_ = best["volume_model"]
    choice.update(lobe_sigma=fit["sigma"], lobe_n_i=fit["n_i"], diffuse=name)
    if not _has_interface(fit):
        choice.update(model="lambertian", why=f"the fit from the best grid point (σ {best['sigma']:.3f}, "
                      f"n_i {best['n_i']:.2f}) ends at n_i {fit['n_i']:.3f}: no interface")
        return dict(fit, sigma=LAMBERTIAN_SIGMA, n_i=1.0, volume_model=diffuse_models[0]), warm, choice
    choice.update(model="lobe", why=f"a lobe (σ {fit['sigma']:.3f}, n_i {fit['n_i']:.3f}) with {name} diffuse "
                  f"lowers the trimmed robust cost by {100 * gain:.0f} % against Lambert's")
    return dict(fit, volume_model=vm_), warm, choice
