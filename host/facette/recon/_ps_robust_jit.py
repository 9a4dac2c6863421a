"""Compiled per-pixel loop of `ps_rank_trimmed` (numba, cache=True).

The same steps as the array code of facette.recon._ps_robust (its `block`: the intensity window,
least squares on it, the ratio windows, the residual and the shadow / highlight maps), one pixel at
a time: the array code sorts every pixel's values and builds a dozen (m, N) temporaries per pass
(a 12 MP scan's object, 3 MP x 12 lights: 2.5 s on two cores). Sums run in float64 where the
array code multiplies float32 matrices, so a normal may differ from its by ~1e-5 degree, and a
value tied with a window's bound to the last bit may fall on the other side (tests: the
two agree on all but a few pixels in 10 000).

Loaded only when `ps_rank_trimmed` runs (numba is imported here).
"""
import math

import numpy as np
from numba import njit, prange

from facette._select_jit import SORT_BELOW, kth_smallest, sort_prefix

__all__ = ["rank_trimmed_pixels"]

_F32 = np.float32
CHUNK = 1024          # pixels per work item of the threaded loop (one set of work arrays each)


@njit(cache=True, nogil=True)
def _bounds(v, u, lo, hi):
    """(the lo-th, the hi-th smallest) of v[:u] (v reordered): by insertion sort up to SORT_BELOW
    values, else two quickselects (the second on the part below the hi-th), the same values as the
    sort's. The window needs only its two bounds: numpy's sort of every pixel's 60 values was ~40 %
    of rank_trimmed under a 60-light dome (6 MP band: 4.9 -> ~3 CPU µs a pixel, one thread)."""
    if u <= SORT_BELOW or lo > hi or hi >= u:
        sort_prefix(v, u)
        return v[lo], v[hi]
    v_hi = kth_smallest(v, u, hi)
    return (kth_smallest(v, hi, lo) if lo < hi else v_hi), v_hi


@njit(cache=True, nogil=True)
def _window(key, use, m, trim, min_keep, tol, srt, out):
    """`_trim_window` for one pixel: out[i] = use[i] and key[i] within the bounds of ranks
    ceil(trim (u − 1)) .. floor((1 − trim) (u − 1)) of the u usable keys (widened by tol, relative),
    the middle min_keep ranks when that holds fewer. key float32 (m,); returns the count kept."""
    u = 0
    for i in range(m):
        if use[i]:
            srt[u] = key[i]
            u += 1
    if u == 0:
        for i in range(m):
            out[i] = False
        return 0
    lo = int(math.ceil(trim * (u - 1) - 1e-9))
    hi = int(math.floor((1 - trim) * (u - 1) + 1e-9))
    want = min(u, min_keep)
    if hi - lo + 1 < want:
        lo = (u - want) // 2
        hi = lo + want - 1
    v_lo, v_hi = _bounds(srt, u, min(max(lo, 0), m - 1), min(max(hi, 0), m - 1))
    if tol != 0:                  # in float32, as the array code's
        tf = _F32(tol)
        v_lo = v_lo - tf * abs(v_lo)
        v_hi = v_hi + tf * abs(v_hi)
    n = 0
    for i in range(m):
        out[i] = use[i] and hi >= lo and key[i] >= v_lo and key[i] <= v_hi
        n += out[i]
    return n


@njit(cache=True, nogil=True)
def _wls(e, s, keep, m, g):
    """`_wls` for one pixel: g (3,) float32 = argmin Σ_kept (E_i − s_i·g)² (sums in float64), NaN
    where fewer than 3 lights are kept or they are (nearly) coplanar."""
    xx = xy = xz = yy = yz = zz = 0.0
    b0 = b1 = b2 = 0.0
    n = 0
    for i in range(m):
        if keep[i]:
            sx, sy, sz = float(s[i, 0]), float(s[i, 1]), float(s[i, 2])
            xx += sx * sx
            xy += sx * sy
            xz += sx * sz
            yy += sy * sy
            yz += sy * sz
            zz += sz * sz
            b0 += sx * e[i]
            b1 += sy * e[i]
            b2 += sz * e[i]
            n += 1
    c00, c01, c02 = yy * zz - yz * yz, xz * yz - xy * zz, xy * yz - xz * yy
    c11, c12, c22 = xx * zz - xz * xz, xy * xz - xx * yz, xx * yy - xy * xy
    det = xx * c00 + xy * c01 + xz * c02
    if n < 3 or not abs(det) > 1e-9 * max(xx + yy + zz, 1e-30) ** 3:
        g[0] = g[1] = g[2] = np.nan
        return
    g[0] = (c00 * b0 + c01 * b1 + c02 * b2) / det
    g[1] = (c01 * b0 + c11 * b1 + c12 * b2) / det
    g[2] = (c02 * b0 + c12 * b1 + c22 * b2) / det


@njit(cache=True, nogil=True)
def _unit(g, nrm):
    """nrm = g / |g| (float32, as the array code's) where |g| is finite and > 1e-12 (else 0);
    whether it was."""
    norm = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    if not (np.isfinite(norm) and norm > 1e-12):
        nrm[0] = nrm[1] = nrm[2] = 0.0
        return False
    nrm[0], nrm[1], nrm[2] = g[0] / norm, g[1] / norm, g[2] / norm
    return True


@njit(cache=True, nogil=True)
def _chunk(e, ok, s, src, cols, trim, min_keep, tol, t_dark, rounds, min_lit, shadow_below, specular_above,
           normal, found, resid, changes, below, above, rho, start, stop):
    """The pixels start .. stop − 1 of `rank_trimmed_pixels`, with one set of work arrays."""
    m = e.shape[0]
    ep = np.empty(m, np.float32)
    okp = np.empty(m, np.bool_)
    bright = np.empty(m, np.bool_)
    kb = np.empty(m, np.bool_)
    kr = np.empty(m, np.bool_)
    lit = np.empty(m, np.bool_)
    key = np.empty(m, np.float32)
    srt = np.empty(m, np.float32)
    g = np.empty(3, np.float32)
    gr = np.empty(3, np.float32)
    nb = np.empty(3, np.float32)
    nr = np.empty(3, np.float32)
    sw = np.empty(m, np.float32)      # s·n where a light counts in the albedo, else 0
    for p in range(start, stop):
        top = _F32(0)
        for i in range(m):
            okp[i] = ok[i, p]
            ep[i] = e[i, p] if okp[i] else _F32(0)       # a missing value never enters a sum
            top = max(top, ep[i])
        for i in range(m):
            # ranks count every usable value; a dark one (cast shadow) is never kept
            bright[i] = okp[i] and (t_dark < 0 or ep[i] > _F32(t_dark) * top)
            key[i] = ep[i] if okp[i] else np.inf
        _window(key, okp, m, trim, min_keep, tol, srt, kb)
        nk = 0
        for i in range(m):
            kb[i] = kb[i] and bright[i]
            nk += kb[i]
        if nk < 3:                        # too few left: every bright value
            for i in range(m):
                kb[i] = bright[i]
        sp = s[p]                         # (m, 3): the pixel's lights
        _wls(ep, sp, kb, m, g)
        fb = _unit(g, nb)
        for r in range(rounds):
            for i in range(m):
                sn = sp[i, 0] * nb[0] + sp[i, 1] * nb[1] + sp[i, 2] * nb[2]
                lit[i] = okp[i] and sn > min_lit and fb
                key[i] = ep[i] / sn if lit[i] else np.inf
            _window(key, lit, m, trim, min_keep, tol, srt, kr)
            nk = 0
            for i in range(m):
                kr[i] = kr[i] and bright[i]
                nk += kr[i]
            _wls(ep, sp, kr, m, gr)
            fr = _unit(gr, nr)
            changes[r, p] = 0.0
            if nk >= 3 and fr:
                dots = min(max(float(nr[0] * nb[0] + nr[1] * nb[1] + nr[2] * nb[2]), -1.0), 1.0)
                changes[r, p] = math.degrees(math.acos(dots))
                nb[:] = nr
                kb[:] = kr
                g[:] = gr
        normal[0, p], normal[1, p], normal[2, p] = nb[0], nb[1], nb[2]
        found[p] = fb
        # residual on the kept lights, and the maps (attached or far below the fit: shadow; left
        # out far above it: highlight); they do not steer the normal
        num = den = 0.0
        g0 = _F32(0) if np.isnan(g[0]) else g[0]
        g1 = _F32(0) if np.isnan(g[1]) else g[1]
        g2 = _F32(0) if np.isnan(g[2]) else g[2]
        for i in range(m):
            pred = sp[i, 0] * g0 + sp[i, 1] * g1 + sp[i, 2] * g2
            sn = sp[i, 0] * nb[0] + sp[i, 1] * nb[1] + sp[i, 2] * nb[2]
            sw[i] = sn if kb[i] and sn > 0 else _F32(0)
            if kb[i]:
                d = ep[i] - pred
                num += d * d
                den += float(ep[i]) * ep[i]
            below[p, i] = okp[i] and (sn <= 0 or ep[i] < _F32(shadow_below) * pred)
            above[p, i] = okp[i] and not kb[i] and ep[i] > _F32(specular_above) * pred and sn > 0
        r_ = math.sqrt(num) / math.sqrt(den) if den > 0 else 0.0
        resid[p] = r_ if np.isfinite(r_) else 0.0
        # ρ = π Σ E s·n / Σ (s·n)² per channel over the kept lit lights whose value in that
        # channel is finite (`_ps._albedo`)
        for c in range(rho.shape[1]):
            num = 0.0
            den = 0.0
            for i in range(m):
                if sw[i] > 0:
                    v = src[i, cols[p], c]
                    if np.isfinite(v):
                        num += float(v) * sw[i]
                        den += float(sw[i]) * sw[i]
            rho[p, c] = math.pi * num / den if den > 1e-12 else 0.0


@njit(cache=True, parallel=True, nogil=True)
def rank_trimmed_pixels(e, ok, s, src, cols, trim, min_keep, tol, t_dark, rounds, min_lit, shadow_below,
                        specular_above, normal, found, resid, changes, below, above, rho):
    """`ps_rank_trimmed`'s passes over every pixel of e (m, N) float32 (read where ok (m, N), the
    usable values), s (N, m, 3) float32 the pixels' lights (distant ones: a broadcast view), into its
    outputs: normal (3, N), found (N,), resid (N,), changes (rounds, N) degrees,
    below / above (N, m: pixel-major, as the result's maps) and rho (N, C), the albedo per channel
    of src (m, *, C) whose column cols[p] is pixel p (`_ps._albedo`). t_dark < 0: no dark test."""
    m, n_pix = e.shape
    n_chunks = (n_pix + CHUNK - 1) // CHUNK
    for q in prange(n_chunks):
        _chunk(e, ok, s, src, cols, trim, min_keep, tol, t_dark, rounds, min_lit, shadow_below, specular_above,
               normal, found, resid, changes, below, above, rho, q * CHUNK, min((q + 1) * CHUNK, n_pix))
