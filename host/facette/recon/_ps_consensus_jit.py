"""The per-pixel search of `facette.recon._ps_consensus` (HM10), compiled (numba, cache=True):
for each pixel, the candidate normal that the fewest of its observations contradict. Imported on
first use (the first call in a fresh environment compiles it, a few seconds); releases the GIL
(the caller runs blocks on two threads)."""
import math

import numpy as np
from numba import njit

__all__ = ["consensus_block"]

_RING = 8          # neighbours tried around the current normal at each step (every 45°)


@njit(cache=True, nogil=True, inline="always")
def _ramp(x, margin):
    """1 for a pair ordered against n (x <= 0), 0 beyond the margin, linear between."""
    if x <= 0.0:
        return 1.0
    if x >= margin:
        return 0.0
    return 1.0 - x / margin


@njit(cache=True, nogil=True)
def _violations(n0, n1, n2, ls, hs, k, starts, dark, n_dark, pairs, t_shadow, w_nl, margin,
                bound, a, b):
    """The weighted count of observations that the candidate normal n contradicts (see
    `consensus_block`; ls, hs: the lit lights' l and h by decreasing value, dark: the dark
    lights' l), or a partial count above `bound` as soon as it passes it."""
    if n2 <= 0.0:                                  # seen from the camera: n·v > 0
        return 1e30
    v = 0.0
    v_nl = 0.0
    v_both = 0.0
    done = 0                                       # n·l, n·h known for ranks < done
    for r in range(k):
        stop = min(k, starts[r] + pairs)
        while done < max(stop, r + 1):
            a[done] = n0 * ls[done, 0] + n1 * ls[done, 1] + n2 * ls[done, 2]
            b[done] = n0 * hs[done, 0] + n1 * hs[done, 1] + n2 * hs[done, 2]
            done += 1
        if a[r] <= 0.0:                            # visibility: lit, so n·l > 0
            v += 1.0
        for s in range(starts[r], stop):           # monotonicity: r brighter than s
            d_nl = a[r] - a[s]
            if d_nl < margin:
                v_nl += _ramp(d_nl, margin)
                v_both += _ramp(max(d_nl, b[r] - b[s]), margin)
        if v + v_both + w_nl * (v_nl - v_both) > bound:     # worse already: stop counting
            return v + v_both + w_nl * (v_nl - v_both)
    for q in range(n_dark):                        # visibility: dark, so n·l <= t_shadow
        if n0 * dark[q, 0] + n1 * dark[q, 1] + n2 * dark[q, 2] > t_shadow:
            v += 1.0
    return v + v_both + w_nl * (v_nl - v_both)


@njit(cache=True, nogil=True)
def _sort_pixel(e, lit, ok, p, tie, ratio, order, vals, starts, shadowed):
    """The pixel's lit lights by decreasing value (order, vals), for each the first rank that is
    darker by more than tie and by more than the factor 1 + ratio (starts), and its dark usable
    lights. Returns (k lit, n dark)."""
    m = e.shape[1]
    k = 0
    n_shadow = 0
    for j in range(m):
        if lit[p, j]:
            vals[k] = -e[p, j]
            order[k] = j
            k += 1
        elif ok[p, j]:
            shadowed[n_shadow] = j
            n_shadow += 1
    idx = np.argsort(vals[:k], kind="mergesort")
    o = order[:k][idx].copy()
    w = -vals[:k][idx]
    order[:k] = o
    vals[:k] = w
    s = 0
    for r in range(k):
        if s <= r:
            s = r + 1
        while s < k and vals[s] >= min(vals[r] - tie, vals[r] / (1.0 + ratio)):
            s += 1
        starts[r] = s
    return k, n_shadow


@njit(cache=True, nogil=True)
def _step(n0, n1, n2, d, c):
    """n moved by the angle d (rad) towards the tangent direction of azimuth index c."""
    if abs(n2) < 0.9:
        t0, t1, t2 = n1, -n0, 0.0                  # n x z
    else:
        t0, t1, t2 = 0.0, n2, -n1                  # n x x
    tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 / tn, t1 / tn, t2 / tn
    u0, u1, u2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
    phi = 2.0 * math.pi * c / _RING
    td = math.tan(d)
    x0 = n0 + td * (math.cos(phi) * t0 + math.sin(phi) * u0)
    x1 = n1 + td * (math.cos(phi) * t1 + math.sin(phi) * u1)
    x2 = n2 + td * (math.cos(phi) * t2 + math.sin(phi) * u2)
    xn = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    return x0 / xn, x1 / xn, x2 / xn


@njit(cache=True, nogil=True)
def consensus_block(e, lit, ok, ref, lights, halves, cands, steps, pairs, tie_share, tie_ratio,
                    t_shadow, w_nl, margin, moves, out_n, out_v, out_votes):
    """Each pixel's normal by consensus over candidates, coarse to fine.

    e : (N, m) values; lit, ok : (N, m) bool (lit: above the shadow threshold; ok: usable);
    ref : (N,) the pixel's reference level (ties: tie_share x ref); lights, halves : (m, 3);
    cands : (C, 3) the coarse candidates; steps : (S,) angles (rad) of the local search,
    decreasing; pairs : each lit light is compared with the next `pairs` lights darker than it
    by more than tie_share x ref and by more than the factor 1 + tie_ratio; moves : at most this many moves per step.
    A candidate is contradicted once by each pair (brighter r, darker s) with n·l_r < n·l_s and
    n·h_r < n·h_s, w_nl times by each pair with n·l_r < n·l_s but n·h_r >= n·h_s (a specular lobe
    could give it), once by each lit light with n·l <= 0 and each dark one with n·l > t_shadow;
    a pair ordered as n but by less than `margin` (in cosine) counts in proportion (a ramp), so
    that within a set of normals that no pair contradicts the middle one wins.
    Writes out_n (N, 3) (zeros where fewer than 3 lit lights), out_v (N,) the weighted
    contradictions of the chosen normal, out_votes (N,) the observations that voted."""
    n_pix, m = e.shape
    order = np.empty(m, np.int64)
    vals = np.empty(m)
    starts = np.empty(m, np.int64)
    shadowed = np.empty(m, np.int64)
    a = np.empty(m)
    b = np.empty(m)
    ls = np.empty((m, 3))
    hs = np.empty((m, 3))
    dark = np.empty((m, 3))
    for p in range(n_pix):
        k, n_sh = _sort_pixel(e, lit, ok, p, tie_share * ref[p], tie_ratio, order, vals, starts,
                              shadowed)
        for r in range(k):
            ls[r] = lights[order[r]]
            hs[r] = halves[order[r]]
        for q in range(n_sh):
            dark[q] = lights[shadowed[q]]
        votes = k + n_sh
        for r in range(k):
            votes += max(0, min(k, starts[r] + pairs) - starts[r])
        out_votes[p] = votes
        if k < 3:
            out_n[p, 0] = out_n[p, 1] = out_n[p, 2] = 0.0
            out_v[p] = 0
            continue
        # coarse: every candidate, nearest the rank-weighted mean light first (so that the count
        # of the others stops early; ties keep the nearer): from the values' order alone
        g0 = g1 = g2 = 0.0
        for r in range(k):
            g0 += (k - r) * lights[order[r], 0]
            g1 += (k - r) * lights[order[r], 1]
            g2 += (k - r) * lights[order[r], 2]
        near = np.argsort(-(cands[:, 0] * g0 + cands[:, 1] * g1 + cands[:, 2] * g2), kind="mergesort")
        best = 1e300
        c0 = c1 = c2 = 0.0
        for c in near:
            v = _violations(cands[c, 0], cands[c, 1], cands[c, 2], ls, hs, k, starts,
                            dark, n_sh, pairs, t_shadow, w_nl, margin, best, a, b)
            if v < best:
                best, c0, c1, c2 = v, cands[c, 0], cands[c, 1], cands[c, 2]
        # fine: a pattern search on the sphere, the step halved each level
        for d in steps:
            for _ in range(moves):
                bv, b0, b1, b2 = best, c0, c1, c2
                for c in range(_RING):
                    x0, x1, x2 = _step(c0, c1, c2, d, c)
                    v = _violations(x0, x1, x2, ls, hs, k, starts, dark, n_sh, pairs, t_shadow,
                                    w_nl, margin, bv, a, b)
                    if v < bv:
                        bv, b0, b1, b2 = v, x0, x1, x2
                if bv >= best:
                    break
                best, c0, c1, c2 = bv, b0, b1, b2
        # the normals of the last step that do as well: their mean (the middle of the plateau)
        s0, s1, s2 = c0, c1, c2
        d = steps[steps.shape[0] - 1]
        for c in range(_RING):
            x0, x1, x2 = _step(c0, c1, c2, d, c)
            if _violations(x0, x1, x2, ls, hs, k, starts, dark, n_sh, pairs, t_shadow, w_nl, margin,
                           best, a, b) == best:
                s0, s1, s2 = s0 + x0, s1 + x1, s2 + x2
        sn = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        out_n[p, 0], out_n[p, 1], out_n[p, 2] = s0 / sn, s1 / sn, s2 / sn
        out_v[p] = best
