"""Compiled kernel of `facette.fit._ps_li_minima`: each pixel's minima searched from starts spread
over the hemisphere (numba, cache=True).

    search_minima_compiled(e, usable, normals, starts, lights, sigma, n_i, ...) ->
        (best (N, 3), cost_here (N,), cost_best (N,), cost_second (N,))

Per pixel, on the channels' mean as the compiled solve (facette.fit._normals_li_jit, whose
`_solve_one` it calls): the solve from the pixel's current normal (its robust scale, re-estimated as
the solve does, is then fixed for every other start, so that the costs compare); the cost at each
start of `starts` (no step: the screen); the `keep` starts of lowest cost, at least `min_sep` from the
first solve's normal, solved; the minimum of lowest cost kept, and the cost of the best other
minimum more than `min_sep` from it (the second minimum: how sure the pixel is of its choice).
"""
import math

import numpy as np
from numba import njit, prange

from facette.brdf._lobe_jit import SMITH_G1_TABLE

from ._normals_li_jit import _kappa, _model, _solve_one, _workspace, chunk_for, model_constants

__all__ = ["search_minima_compiled"]


@njit(cache=True)
def _insert(costs, index, c, k):
    """Keep the len(costs) lowest costs, ascending, with their start index."""
    n = costs.shape[0]
    if c >= costs[n - 1]:
        return
    j = n - 1
    while j > 0 and costs[j - 1] > c:
        costs[j] = costs[j - 1]
        index[j] = index[j - 1]
        j -= 1
    costs[j] = c
    index[j] = k


@njit(cache=True)
def _full_cost(em, ok, x, y, z, s, sh, fres, btab, g1tab, sigma, spec, sc, buf):
    """The robust cost at the normal (x, y, z) over every usable light (none left out as a cast
    shadow: the solves from different starts leave out different lights, and a minimum that left
    out more would look cheaper), κ by the robust weights of three IRLS passes, on the scale sc."""
    (a, b, pa, qa, cs, idx, e, w) = buf
    n = 0
    for i in range(em.shape[0]):
        if ok[i]:
            idx[n] = i
            e[n] = em[i]
            n += 1
    _model(x, y, z, s, sh, fres, btab, g1tab, sigma, spec, idx, n, a, b, pa, qa, cs)
    for t in range(n):
        w[t] = 1.0
    k = _kappa(e, a, b, w, n)
    for _ in range(3):
        for t in range(n):
            q = (e[t] - a[t] - b[t] * k) / sc
            w[t] = 1.0 / (1.0 + q * q)
        k = _kappa(e, a, b, w, n)
    tot = 0.0
    for t in range(n):
        q = (e[t] - a[t] - b[t] * k) / sc
        tot += math.log1p(q * q)
    return tot


@njit(cache=True)
def _buffers(m):
    return (np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m, np.int64),
            np.empty(m), np.empty(m))


@njit(cache=True)
def _search_one(em, ok, n0, starts, s, sh, fres, btab, g1tab, sigma, spec, iterations, keep, min_sep_cos,
                cast_ratio, floor, max_step, step_tol, ws, buf, out):
    """One pixel: out[:3] the best minimum's normal, out[3] the first solve's cost, out[4] the best
    cost, out[5] the second minimum's cost (inf: none found); the costs over every usable light
    (`_full_cost`)."""
    r1 = _solve_one(em, ok, n0, s, sh, fres, btab, g1tab, sigma, spec, iterations, -1.0,
                    cast_ratio, floor, max_step, step_tol, ws)
    x1, y1, z1, sc = r1[0], r1[1], r1[2], r1[4]
    c1 = _full_cost(em, ok, x1, y1, z1, s, sh, fres, btab, g1tab, sigma, spec, sc, buf)
    out[0], out[1], out[2], out[3], out[4], out[5] = x1, y1, z1, c1, c1, np.inf
    if r1[6] < 3:
        return
    low = np.full(keep, np.inf)
    index = np.full(keep, -1, np.int64)
    for k in range(starts.shape[0]):
        if starts[k, 0] * x1 + starts[k, 1] * y1 + starts[k, 2] * z1 > min_sep_cos:
            continue
        rk = _solve_one(em, ok, starts[k], s, sh, fres, btab, g1tab, sigma, spec, 0, sc,
                        cast_ratio, floor, max_step, step_tol, ws)
        if rk[6] >= 3:
            _insert(low, index, rk[3], k)
    # the minima: the first solve's and each kept start's
    mx = np.empty(keep + 1)
    my = np.empty(keep + 1)
    mz = np.empty(keep + 1)
    mc = np.full(keep + 1, np.inf)
    mx[0], my[0], mz[0], mc[0] = x1, y1, z1, c1
    for j in range(keep):
        if index[j] < 0:
            continue
        rj = _solve_one(em, ok, starts[index[j]], s, sh, fres, btab, g1tab, sigma, spec, iterations, sc,
                        cast_ratio, floor, max_step, step_tol, ws)
        if rj[6] >= 3:
            mx[j + 1], my[j + 1], mz[j + 1] = rj[0], rj[1], rj[2]
            mc[j + 1] = _full_cost(em, ok, rj[0], rj[1], rj[2], s, sh, fres, btab, g1tab, sigma, spec, sc, buf)
    b = 0
    for j in range(1, keep + 1):
        if mc[j] < mc[b]:
            b = j
    second = np.inf
    for j in range(keep + 1):
        if j != b and mx[j] * mx[b] + my[j] * my[b] + mz[j] * mz[b] < min_sep_cos:
            second = min(second, mc[j])
    out[0], out[1], out[2], out[4], out[5] = mx[b], my[b], mz[b], mc[b], second


@njit(cache=True, parallel=True, nogil=True)
def _search_all(em, ok, n0, starts, s, sh, fres, btab, g1tab, sigma, spec, iterations, keep, min_sep_cos,
                cast_ratio, floor, max_step, step_tol, out, chunk):
    n_pix, m = em.shape
    n_chunks = (n_pix + chunk - 1) // chunk
    for q in prange(n_chunks):
        ws = _workspace(m)
        buf = _buffers(m)
        for p in range(q * chunk, min((q + 1) * chunk, n_pix)):
            st = starts[p if starts.shape[0] > 1 else 0]        # the pixel's starts, or the common ones
            _search_one(em[p], ok[p], n0[p], st, s, sh, fres, btab, g1tab, sigma, spec, iterations, keep,
                        min_sep_cos, cast_ratio, floor, max_step, step_tol, ws, buf, out[p])


def search_minima_compiled(e, usable, normals, starts, lights, sigma, n_i, iterations, keep, min_sep_deg,
                           cast_ratio, floor, max_step, step_tol, volume_model="approx", table=None, chunk=64):
    """e : (N, m, C) values over the lights' intensities; usable : (N, m) bool; normals : (N, 3) the
    current normals; starts : (K, 3) unit start normals, or (N, K, 3) per pixel; lights : (m, 3)
    distant; (σ, n_i, volume_model) the model; iterations, cast_ratio, floor, max_step, step_tol :
    the solve's (facette.fit._normals_li); keep : starts solved per pixel (those of lowest cost at the start);
    min_sep_deg : two minima closer than this are one. Returns (best (N, 3) float32, cost_here (N,),
    cost_best (N,), cost_second (N,) float64, inf where no other minimum was found)."""
    e = np.asarray(e, np.float32)
    n_pix, m, _ = e.shape
    s, sh, fres, btab, sig, spec = model_constants(lights, sigma, n_i, volume_model, table)
    # the channels' mean, a light used where usable and finite in every channel (as the compiled solve)
    ok = np.ascontiguousarray(np.broadcast_to(np.asarray(usable, bool), (n_pix, m)) & np.isfinite(e).all(2))
    em = np.ascontiguousarray(np.where(ok, e.astype(np.float64).mean(2), 0.0))
    starts = np.asarray(starts, np.float64)
    starts = starts[None] if starts.ndim == 2 else starts
    out = np.empty((n_pix, 6))
    _search_all(em, ok, np.ascontiguousarray(normals, np.float64), np.ascontiguousarray(starts, np.float64),
                s, sh, fres, btab, SMITH_G1_TABLE, sig, spec, int(iterations), int(keep),
                math.cos(math.radians(min_sep_deg)), cast_ratio, floor, max_step, float(step_tol), out,
                chunk_for(n_pix, chunk))
    return out[:, :3].astype(np.float32), out[:, 3], out[:, 4], out[:, 5]
