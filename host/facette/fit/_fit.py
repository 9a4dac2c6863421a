"""Identification of BRDF parameters on reflectance samples (thesis §4.2.2).

Two fitters on the same weighted residuals, and a front door with model selection:

- ``fit_genetic``: the thesis's genetic algorithm (inspired by Brady et al. 2014): random
  population, sort by error, keep the best, refill by cross-over (mean of two parents) and
  mutation (reset a parameter, or a random step), stop below an error threshold or after a
  number of generations. Seeded.
- ``fit_least_squares``: bounded ``scipy.optimize.least_squares`` (trust-region reflective)
  from several starts, the best kept.
- ``fit_brdf``: runs one of them, then leaves out what the data does not need: an interface
  with n_i ≈ 1 (→ Oren–Nayar or Lambert), inter-reflections below σ = 0.2.

Residuals: r = w · (f_model − f_data) per sample and channel, with w = √count (cells of the
hemisphere filter average count samples) × the weighting: "relative" (÷ |f_data|, the right
choice for noise proportional to the value, and it keeps the specular peak from swamping the
diffuse part), "absolute", and an extra ``specular_weight`` for samples whose half-vector is
within ``specular_cone_deg`` of the normal (the diffuse/specular balance of §4.2.2).
``specular_weight="balance"`` sets that factor so the specular samples weigh as much in total
(Σ count) as the others: without it, a scan's hemisphere cells (~1200 diffuse cells of ~200
samples each against ~100 small specular ones) let a few-% misfit of the diffuse shape outweigh
the whole lobe. On Cook–Torrance data (σ = 0.05, n_i = 1.2) the LI model's volume part, whose
Fresnel transmissions make it 3–25 % less flat than the data's K_d/π, then prefers n_i → 1 (a
flat volume, no lobe) to the lobe; balanced (5° cone), it finds σ ≈ 0.046–0.050, n_i ≈ 1.19.
Uncertainties: one standard deviation from the Jacobian, cov = (JᵀJ)⁻¹ · SSR / (m − p).
"""
import time

import numpy as np
from scipy.optimize import least_squares

from facette._registry import Registry
from facette._threads import run_blocks
from facette.brdf import INTERREFLECTION_MIN_SIGMA, MODELS

from ._models import FitModel
from ._result import FitResult

__all__ = ["fit_brdf", "fit_least_squares", "fit_genetic", "prepare_samples", "WEIGHTINGS", "METHODS"]

WEIGHTINGS = ("relative", "absolute")


class _Data:
    """Checked samples with their weights. ``weights`` are recomputed by ``reweight(pred)``
    for the "relative" weighting: 1/|f| taken from a model prediction rather than from the noisy
    values (1/|noisy value| favours the draws that came out low and biases K_d down by
    several % at 30 % noise)."""

    def __init__(self, s, o, values, base, relative, notes, o_spread=None, s_spread=None):
        self.s, self.o, self.values, self.base, self.relative, self.notes = s, o, values, base, relative, notes
        self.o_spread, self.s_spread = o_spread, s_spread
        self.floor = 0.05 * np.maximum(np.mean(np.abs(values), axis=0), 1e-12)  # for values near 0
        self.reweight(values)

    def reweight(self, ref):
        if self.relative:
            self.weights = self.base / np.maximum(np.abs(ref), self.floor[None, :])
        else:
            self.weights = self.base.copy()

    @property
    def channels(self):
        return self.values.shape[1]


def prepare_samples(s, o, values, counts=None, weighting="relative", specular_weight=1.0, specular_cone_deg=10.0,
                    o_spread=None, s_spread=None):
    """Check and weight samples. s, o: (N, 3) local-frame unit vectors; values (N,) or (N, C) in 1/sr;
    counts: (N,) samples averaged in each value (hemisphere-filter cells), or None;
    o_spread: (N, K, 3) directions spread over each value's observation cell, or None; s_spread: the
    same over its incidence bin, paired with o_spread's (or None: s).

    specular_weight: a factor for the samples whose half-vector is within specular_cone_deg of the
    normal, or "balance" (the factor that makes their total count match the others', ≥ 1).

    Rows with a non-finite value, a direction at or below the horizon or a count of 0 are dropped
    (and said in the result's message). Raises ValueError on shapes that do not match.
    """
    s = np.asarray(s, dtype=float)
    o = np.asarray(o, dtype=float)
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[:, None]
    if s.ndim != 2 or s.shape[1] != 3 or o.shape != s.shape:
        raise ValueError(f"s and o must both be (N, 3) arrays of local-frame directions; got {s.shape}, {o.shape}")
    if v.ndim != 2 or v.shape[0] != s.shape[0]:
        raise ValueError(f"values must be (N,) or (N, C) with N = {s.shape[0]} (one row per (s, o) pair); "
                         f"got {v.shape}")
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting = {weighting!r}: choose one of {', '.join(WEIGHTINGS)}")
    balance = isinstance(specular_weight, str)
    if balance and specular_weight != "balance":
        raise ValueError(f"specular_weight = {specular_weight!r}: give a positive factor (1 = no extra weight) "
                         "or 'balance'")
    if not balance and not (np.isfinite(specular_weight) and specular_weight > 0):
        raise ValueError(f"specular_weight = {specular_weight}: give a positive factor (1 = no extra weight) "
                         "or 'balance'")
    if o_spread is not None:
        o_spread = np.asarray(o_spread, dtype=float)
        if o_spread.ndim != 3 or o_spread.shape[0] != len(s) or o_spread.shape[2] != 3:
            raise ValueError(f"o_spread must be (N, K, 3) with N = {len(s)}: K directions spread over each "
                             f"sample's observation cell; got {o_spread.shape}")
    if s_spread is not None:
        s_spread = np.asarray(s_spread, dtype=float)
        if o_spread is None or s_spread.shape != o_spread.shape:
            raise ValueError(f"s_spread must be (N, K, 3) as o_spread ({None if o_spread is None else o_spread.shape}):"
                             f" K incidences paired with o_spread's directions; got {s_spread.shape}")
    c = np.ones(len(s)) if counts is None else np.asarray(counts, dtype=float).reshape(-1)
    if c.shape != (len(s),):
        raise ValueError(f"counts must be (N,) = ({len(s)},), one count per sample; got {c.shape}")
    with np.errstate(invalid="ignore"):
        ns = np.linalg.norm(s, axis=1)
        no = np.linalg.norm(o, axis=1)
        ok = (np.all(np.isfinite(v), axis=1) & np.isfinite(ns) & np.isfinite(no) & (ns > 0) & (no > 0)
              & (s[:, 2] > 1e-6 * ns) & (o[:, 2] > 1e-6 * no) & np.isfinite(c) & (c > 0))
    notes = []
    if not ok.all():
        notes.append(f"{int((~ok).sum())} of {len(ok)} samples dropped (non-finite, at/below the horizon, "
                     "or empty cells)")
    s, o, v, c = s[ok] / ns[ok, None], o[ok] / no[ok, None], v[ok], c[ok]
    if o_spread is not None:
        o_spread = o_spread[ok] / np.linalg.norm(o_spread[ok], axis=-1, keepdims=True)
    if s_spread is not None:
        s_spread = s_spread[ok] / np.linalg.norm(s_spread[ok], axis=-1, keepdims=True)
    base = np.sqrt(c)[:, None] * np.ones((1, v.shape[1]))
    if (balance or specular_weight != 1.0) and len(s):
        h = s + o
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        spec = h[:, 2] > np.cos(np.radians(specular_cone_deg))
        if balance:
            # the specular cells weigh as much in total as the others (never less than they do)
            c_spec, c_rest = c[spec].sum(), c[~spec].sum()
            specular_weight = float(np.sqrt(c_rest / c_spec)) if c_spec > 0 and c_rest > c_spec else 1.0
        base[spec] *= specular_weight
    return _Data(s, o, v, base, weighting == "relative", notes, o_spread, s_spread)


def _residual_fn(model, data):
    def fun(p):
        r = (model.predict(p) - data.values) * data.weights
        return r.ravel()
    return fun


def _jacobian(fun, p, lo, hi):
    """Forward differences, stepping inwards at a bound."""
    f0 = fun(p)
    jac = np.empty((f0.size, len(p)))
    for k in range(len(p)):
        h = 1e-6 * max(1.0, abs(p[k]))
        q = p.copy()
        q[k] = p[k] + h if p[k] + h <= hi[k] else p[k] - h
        jac[:, k] = (fun(q) - f0) / (q[k] - p[k])
    return jac


def _uncertainties(jac, resid, n_params):
    m = resid.size
    dof = max(1, m - n_params)
    jtj = jac.T @ jac
    try:
        cond = np.linalg.cond(jtj)
    except np.linalg.LinAlgError:
        cond = np.inf
    if not np.isfinite(cond) or cond > 1e14:
        return None, "the Jacobian is singular (a parameter the data does not constrain): no uncertainties"
    cov = np.linalg.inv(jtj) * (resid @ resid) / dof
    return np.sqrt(np.clip(np.diag(cov), 0, None)), None


def _finish(model, data, p, method, t0, opt_ok, opt_msg, lo, hi):
    fun = _residual_fn(model, data)
    notes = list(data.notes)
    pred = model.predict(p)
    finite = np.all(np.isfinite(p)) and np.all(np.isfinite(pred))
    params, unc = {}, {}
    err = {"n_samples": int(len(data.values)), "n_channels": int(data.channels)}
    if finite:
        resid = pred - data.values
        rms = float(np.sqrt(np.mean(resid**2)))
        err.update(rms=rms, relative_rms=rms / max(float(np.sqrt(np.mean(data.values**2))), 1e-300),
                   weighted_rms=float(np.sqrt(np.mean(fun(p) ** 2))))
        sd, why = _uncertainties(_jacobian(fun, p, lo, hi), fun(p), len(p))
        if why:
            notes.append(why)
        shared, kd = model.split(p)
        params = {k: float(v) for k, v in shared.items()}
        params["kd"] = [float(x) for x in kd]
        if sd is not None:
            sshared, skd = model.split(sd)
            unc = {k: float(v) for k, v in sshared.items()}
            unc["kd"] = [float(x) for x in skd]
        at = [nm for nm, x, a, b in zip(model.names, p, lo, hi) if (x - a) < 1e-6 * (b - a) or (b - x) < 1e-6 * (b - a)]
        if at:
            notes.append(f"at a bound: {', '.join(at)}")
    success = bool(opt_ok and finite)
    if not finite:
        notes.insert(0, "the optimiser returned non-finite parameters or predictions")
    elif not opt_ok:
        notes.insert(0, f"the optimiser did not converge: {opt_msg}")
    msg = "; ".join(notes) if notes else "converged"
    desc = model.describe()
    return FitResult(success=success, message=msg, model=desc["model"], params=params, uncertainties=unc,
                     error=err, method=method, distribution=desc.get("distribution"), masking=desc.get("masking"),
                     volume=desc.get("volume"), interreflection=bool(desc.get("interreflection", False)),
                     time_s=time.perf_counter() - t0, n_evaluations=model.n_evaluations)


def _failed(model_name, method, message, data=None, t0=None):
    return FitResult(success=False, message=message, model=model_name, params={}, uncertainties={},
                     error={"n_samples": 0 if data is None else int(len(data.values))}, method=method,
                     time_s=0.0 if t0 is None else time.perf_counter() - t0)


def _check_enough(model, data, method, t0):
    if len(data.values) <= model.n_params:  # σ and n_i are shared: channels do not add (s, o) pairs
        return _failed(model.name, method, f"too few valid samples ({len(data.values)}) for {model.n_params} "
                       "parameters: the fit needs more (s, o) pairs", data, t0)
    if not np.any(np.abs(data.values) > 0):
        return _failed(model.name, method, "all values are zero: nothing to fit (black material or missing "
                       "exposure?)", data, t0)
    return None


def _kd_guess(model, data):
    # volume-dominated samples ~ K_d/π: a robust start from the median
    return np.clip(np.pi * np.median(data.values, axis=0), 0.05, 0.95)


def _default_volume_options(volume, options):
    if volume == "quadrature" and not options:
        return {"n_theta": 16, "n_phi": 24}  # ~1e-3 relative on I; the fit needs many evaluations
    return options


def _make_model(model, data, distribution, masking, volume, interreflection, volume_options, n_paths=256,
                n_i_max=None):
    return FitModel(model, data.s, data.o, data.channels, distribution, masking, volume, interreflection,
                    _default_volume_options(volume, volume_options or {}), n_paths, data.o_spread, n_i_max,
                    data.s_spread)


def fit_least_squares(s, o, values, model="li", distribution="beckmann", masking="smith", volume="quadrature",
                      interreflection=False, counts=None, weighting="relative", specular_weight=1.0,
                      specular_cone_deg=10.0, n_starts=6, x0=None, volume_options=None, max_nfev=200,
                      reweight_passes=2, o_spread=None, n_i_max=None, s_spread=None):
    """Bounded least squares (scipy ``least_squares``, TRF) from ``n_starts`` starts; the best kept.

    Starts: a grid over σ ∈ {0.05, 0.15, 0.4, 0.8} × n_i ∈ {1.15, 1.5} (first n_starts of it) with
    K_d from the median value; ``x0`` (a parameter vector, see FitModel, or its shared part alone:
    (σ, n_i), K_d then from the median value) is tried first if given.
    n_i_max : Cook–Torrance only, a metal's lobe: n_i up to this (the starts then at n_i 15 and 3,
        F0 0.77 and 0.25).
    With the "relative" weighting, ``reweight_passes`` further solves take the weights from the
    previous solution's prediction (iteratively reweighted least squares).
    Returns a FitResult (success False with the reason when it fails).
    """
    t0 = time.perf_counter()
    data = prepare_samples(s, o, values, counts, weighting, specular_weight, specular_cone_deg, o_spread, s_spread)
    fm = _make_model(model, data, distribution, masking, volume, interreflection, volume_options, n_i_max=n_i_max)
    bad = _check_enough(fm, data, "least_squares", t0)
    if bad:
        return bad
    lo, hi = fm.bounds()
    kd0 = _kd_guess(fm, data)
    grid = [(sg, n) for sg in (0.15, 0.05, 0.4, 0.8) for n in ((15.0, 3.0) if n_i_max else (1.5, 1.15))]
    if x0 is not None and len(x0) == len(lo) - len(kd0):
        x0 = np.concatenate([np.asarray(x0, float), kd0])
    if x0 is not None and len(x0) != len(lo):
        raise ValueError(f"x0 has {len(x0)} values: {fm.name} takes {len(lo)} (shared and K_d) or its "
                         f"{len(lo) - len(kd0)} shared ones")
    starts = [] if x0 is None else [np.clip(np.asarray(x0, float), lo, hi)]
    for sg, n in grid[:max(1, int(n_starts))]:
        shared = {"li": [sg, n], "cook_torrance": [sg, n], "oren_nayar": [sg], "lambert": []}[fm.name]
        starts.append(np.concatenate([shared, kd0]))
    fun = _residual_fn(fm, data)

    def solve(x):
        x = np.clip(x, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
        try:
            return least_squares(fun, x, bounds=(lo, hi), method="trf", x_scale="jac", diff_step=1e-5,
                                 max_nfev=max_nfev)
        except (ValueError, FloatingPointError) as e:  # e.g. non-finite residuals at a start
            return str(e)

    # the starts are independent: on two threads (the model's numpy passes give the GIL up), and
    # the best chosen in the starts' order as before (the same result)
    best, last_err = None, "no start"
    for r in run_blocks(solve, starts):
        if isinstance(r, str):
            last_err = r
        elif np.isfinite(r.cost) and (best is None or r.cost < best.cost):
            best = r
    if best is None:
        return _failed(fm.name, "least_squares", f"every start failed ({last_err})", data, t0)
    for _ in range(int(reweight_passes) if data.relative else 0):
        # iteratively reweighted: relative weights from the model, not from the noisy values
        data.reweight(fm.predict(best.x))
        r = least_squares(fun, best.x, bounds=(lo, hi), method="trf", x_scale="jac", diff_step=1e-5,
                          max_nfev=max_nfev)
        if np.isfinite(r.cost):
            best = r
    res = _finish(fm, data, best.x, "least_squares", t0, best.status > 0, best.message, lo, hi)
    return res


def fit_genetic(s, o, values, model="li", distribution="beckmann", masking="smith", volume="quadrature",
                interreflection=False, counts=None, weighting="relative", specular_weight=1.0,
                specular_cone_deg=10.0, population=40, generations=60, keep=0.2, p_mutation=0.4,
                error_threshold=0.0, rng=0, volume_options=None, o_spread=None, project_kd=False, s_spread=None):
    """The thesis's genetic algorithm (§4.2.2, fig 4.18), seeded by ``rng``.

    1. ``population`` random parameter sets, uniform in the bounds;
    2. sort by the weighted mean squared error;
    3. keep the best ``keep`` fraction unchanged; refill with children of parents drawn with a
       bias to the best (rank-weighted), by cross-over (mean of two parents) or, with probability
       ``p_mutation``, by mutation (reset one parameter uniformly, or add random steps of
       log-uniform size 0.1 %–10 % of the ranges);
    4. stop when the best weighted RMS error < ``error_threshold`` or after ``generations``.

    ``project_kd=True`` (not in the thesis) replaces each individual's K_d by its closed-form
    optimum for the individual's (σ, n_i) before it is ranked (FitModel.project_kd), so the
    search is over (σ, n_i) only; it removes the K_d–n_i drift the plain algorithm shows on LI.
    """
    t0 = time.perf_counter()
    data = prepare_samples(s, o, values, counts, weighting, specular_weight, specular_cone_deg, o_spread, s_spread)
    fm = _make_model(model, data, distribution, masking, volume, interreflection, volume_options)
    bad = _check_enough(fm, data, "genetic", t0)
    if bad:
        return bad
    if population < 4 or generations < 1:
        raise ValueError(f"population = {population}, generations = {generations}: need ≥ 4 individuals "
                         "and ≥ 1 generation")
    rng = np.random.default_rng(rng)
    lo, hi = fm.bounds()
    fun = _residual_fn(fm, data)
    npop = int(population)

    def cost(p):
        r = fun(p)
        c = float(np.mean(r * r))
        return c if np.isfinite(c) else np.inf

    pop = lo + (hi - lo) * rng.random((npop, len(lo)))
    n_keep = max(1, int(round(keep * npop)))
    rank_p = 1.0 / np.arange(1, npop + 1)
    rank_p /= rank_p.sum()
    gen_done = 0
    for gen in range(int(generations)):
        if project_kd:
            pop = np.array([fm.project_kd(p, data.values, data.weights) for p in pop])
        costs = np.array([cost(p) for p in pop])
        order = np.argsort(costs)
        pop, costs = pop[order], costs[order]
        gen_done = gen + 1
        if np.sqrt(costs[0]) < error_threshold:
            break
        if data.relative and gen % 5 == 4:
            data.reweight(fm.predict(pop[0]))  # relative weights from the best model so far
        children = [pop[i].copy() for i in range(n_keep)]
        while len(children) < npop:
            if rng.random() < p_mutation:
                child = pop[rng.choice(npop, p=rank_p)].copy()
                if rng.random() < 0.3:
                    k = rng.integers(len(lo))
                    child[k] = lo[k] + (hi[k] - lo[k]) * rng.random()
                else:
                    child += rng.normal(size=len(lo)) * (hi - lo) * 10 ** rng.uniform(-3, -1)
            else:
                a, b = rng.choice(npop, size=2, replace=False, p=rank_p)
                child = 0.5 * (pop[a] + pop[b])
            children.append(np.clip(child, lo, hi))
        pop = np.array(children)
    if project_kd:
        pop = np.array([fm.project_kd(p, data.values, data.weights) for p in pop])
    costs = np.array([cost(p) for p in pop])
    best = pop[int(np.argmin(costs))]
    ok = bool(np.isfinite(costs.min()))
    res = _finish(fm, data, best, "genetic", t0, ok, "every individual gave a non-finite error", lo, hi)
    res.selection.append(f"{gen_done} generations of {npop}" + (", K_d projected" if project_kd else ""))
    return res


METHODS = Registry("fit method")
METHODS.add("least_squares", fit_least_squares)
METHODS.add("genetic", fit_genetic)


def fit_brdf(s, o, values, model="li", method="least_squares", distribution="beckmann", masking=None,
             volume="quadrature", interreflection="auto", counts=None, weighting="relative", specular_weight=1.0,
             specular_cone_deg=10.0, select=True, n_i_tolerance=0.01, rel_error_tolerance=0.02, o_spread=None,
             s_spread=None, **options):
    """Fit a BRDF to reflectance samples and keep only what the data needs.

    Parameters
    ----------
    s, o : (N, 3) unit vectors, local frame (n = +z); values : (N,) or (N, C) BRDF values (1/sr).
    model : "li" | "cook_torrance" | "oren_nayar" | "lambert".  method : "least_squares" | "genetic".
    distribution, masking, volume : of the LI / Cook–Torrance model (see facette.brdf.brdf_li);
        masking None = the model's default ("smith" for LI, "vcavity" for Cook–Torrance).
    interreflection : "auto" (LI with masking="vcavity": added only if the fitted σ ≥ 0.2 and it lowers
        the error), True, or False.
    counts : (N,) samples per value (hemisphere-filter cells) or None.
    o_spread : (N, K, 3) or None. When each value averages a cell of the hemisphere filter, K
        directions spread over that cell: the model is then averaged over them (the filter's
        forward model), which removes the bias a cell as wide as the specular lobe puts on σ.
    s_spread : (N, K, 3) or None: the incidences over each value's incidence bin, paired with
        o_spread's directions (the bin is as wide as a cell: 5° rings at θ0 = 3°).
    weighting, specular_weight, specular_cone_deg : the residual weights (module doc).
    select : try the simpler models when the interface is not needed (n_i − 1 < max(n_i_tolerance,
        2 × its uncertainty)): Oren–Nayar, then Lambert; a simpler model is kept when its relative
        RMS error is within ``rel_error_tolerance`` (relative) of the full model's.
    **options : passed to the fitter (n_starts, population, generations, rng, volume_options, …).

    Returns
    -------
    FitResult (``.to_json()`` writes brdf.json). ``selection`` lists the choices made.
    """
    fitter = METHODS[method]
    model = MODELS.canonical(model)
    if masking is None:
        masking = "vcavity" if model == "cook_torrance" else "smith"
    common = dict(counts=counts, weighting=weighting, specular_weight=specular_weight,
                  specular_cone_deg=specular_cone_deg, o_spread=o_spread, s_spread=s_spread)
    t0 = time.perf_counter()
    if interreflection not in ("auto", True, False):
        raise ValueError(f"interreflection = {interreflection!r}: use 'auto', True or False")
    if interreflection is True and (model != "li" or masking != "vcavity"):
        raise ValueError("inter-reflections are simulated in V-cavities: use model='li', masking='vcavity'")
    first_ir = interreflection is True
    res = fitter(s, o, values, model, distribution, masking, volume, first_ir, **common, **options)
    notes = list(res.selection)
    if not res.success:
        return res
    # 1) the interface: n_i ≈ 1 → simpler models
    if select and model in ("li", "cook_torrance"):
        n = res.params["n_i"]
        dn = (res.uncertainties or {}).get("n_i") or 0.0
        if n - 1.0 < max(n_i_tolerance, 2.0 * dn):
            notes.append(f"n_i = {n:.4f} ± {dn:.2g} ≈ 1: no interface needed, trying simpler models")
            simpler = ["oren_nayar", "lambert"] if model == "li" else ["lambert"]
            for alt in simpler:
                # a simpler model's own starts: x0 and n_starts were the full model's
                r2 = fitter(s, o, values, alt, **common,
                            **{k: v for k, v in options.items() if k not in ("n_i_max", "x0", "n_starts")})
                if r2.success and r2.error["relative_rms"] <= res.error["relative_rms"] * (1 + rel_error_tolerance) + 1e-12:
                    notes.append(f"{alt} kept: relative RMS {r2.error['relative_rms']:.4g} vs "
                                 f"{res.error['relative_rms']:.4g} for {res.model}")
                    res = r2
                elif r2.success:
                    notes.append(f"{alt} rejected: relative RMS {r2.error['relative_rms']:.4g}")
        else:
            notes.append(f"n_i = {n:.4f} ± {dn:.2g}: the interface is needed")
    # 2) inter-reflections, only where they matter
    if res.model == "li" and masking == "vcavity" and interreflection in ("auto", True):
        sg = res.params["sigma"]
        if sg < INTERREFLECTION_MIN_SIGMA and interreflection == "auto":
            notes.append(f"no inter-reflection term: σ = {sg:.3g} < {INTERREFLECTION_MIN_SIGMA}")
        elif interreflection == "auto":
            x0 = np.concatenate([[res.params["sigma"], res.params["n_i"]], res.params["kd"]])
            opts = {k: v for k, v in options.items() if k in ("volume_options", "max_nfev")}
            r2 = fit_least_squares(s, o, values, "li", distribution, masking, volume, True, **common, n_starts=1,
                                   x0=x0, **opts)
            if r2.success and r2.error["relative_rms"] < res.error["relative_rms"]:
                notes.append(f"inter-reflection term kept (σ ≥ {INTERREFLECTION_MIN_SIGMA}): relative RMS "
                             f"{r2.error['relative_rms']:.4g} vs {res.error['relative_rms']:.4g}")
                res = r2
            else:
                notes.append("inter-reflection term tried and dropped: it did not lower the error")
    elif res.model == "li" and interreflection == "auto":
        notes.append(f"no inter-reflection term: simulated only for masking='vcavity' (got {masking!r})")
    res.selection = notes
    res.time_s = time.perf_counter() - t0
    return res
