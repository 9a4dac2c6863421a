"""Compiled per-pixel solve of `refine_normals_li` for distant lights (numba, cache=True).

The same robust Levenberg–Marquardt as facette.fit._normals_li (its module doc: tangent-plane
parameterisation, κ per channel in closed form at every step, Cauchy loss with a per-pixel scale
re-estimated at steps 3 and 6, cast shadows and unusable values left out, a second start kept
where its robust cost is lower), written as one loop per pixel instead of whole-array passes, so
that a pixel costs a few microseconds and stops as soon as it has converged. One difference: the
lobe's Jacobian is analytic (`_model` returns dA/dt with A), where the array code takes forward
differences, two more evaluations of the lobe per step (DiLiGenT cat, 96 lights, its 44 312 pixels
of round 1 on one thread: 4.66 -> 2.62 CPU s for 8000 of them, the same mean number of steps;
normals within 0.02° at the 90th percentile, 0.04° at the 99th, 0.6° at most. Through the whole
`process` on cat the normals move by 0.06° at the 90th percentile, 0.27° at the 99th; 0.3 % of the
pixels by > 1° (to another minimum, up to 30°); `facette bench diligent`, 96 lights: every object's
mean the same to 0.01° (reading 9.63 -> 9.64°), the mean 6.68°).

The model values: the specular lobe A (eq 3.10) is evaluated exactly per pixel and light (the
Fresnel factor F(s·h) is one number per distant light); the volume part B(n, s_i) (eq 3.15, by the
formula eq 3.49–3.57 or the quadrature tables: `volume_model`)
is smooth in the normal, so for each light it is tabulated once per (σ, n_i) on a grid of normals
(nx, ny) ∈ [−1, 1]² by `facette.brdf.li_shading_terms` itself and interpolated bilinearly
(relative difference to the direct evaluation ≤ ~1e-3 on lit pixels, see the tests). Per-pixel
(near-light) directions are not tabulated: they go through the array code.

First call in a fresh environment compiles the kernel (~10–20 s on one core); numba caches the
machine code next to this file (__pycache__), later processes load it in well under a second.
"""
import math

import numpy as np
from numba import njit, prange

from facette.brdf import fresnel_dielectric, li_shading_terms
from facette.brdf._lobe_jit import beckmann_d

__all__ = ["volume_table", "refine_distant_compiled", "bin_images", "TABLE_GRID"]

CHUNK = 256               # pixels per work item of the threaded per-pixel loop
TABLE_GRID = 257           # grid points per axis of the B table over nx, ny ∈ [−1, 1]
# The extra start is tried where the first leaves a relative RMS residual ≥ this. 0: everywhere.
# Skipping it where the first start already explains the pixel is faster and was no worse on the
# DiLiGenT cat and reading, 96 lights (their round-1 pixels: 0.05 skips 61 % / 11 % of the second
# starts, mean error 5.658 -> 5.637 / 10.380 -> 10.379°), but on the Mitsuba renders, which choose,
# every threshold tried was worse (0.03: satin sphere 1.947 -> 1.975°, shell lacquer 0.571 -> 0.601,
# satin relief 1.079 -> 1.094; 0.05 and 0.08 worse still): so 0. Never applied to a metal's
# hemisphere search start (`refine_normals_li` passes 0 there).
SECOND_START_ABOVE = 0.0


_TABLES = {}               # (σ, n_i, grid, lights' bytes) -> table; the last few kept


def volume_table(lights, sigma, n_i, grid=TABLE_GRID, volume_model="approx"):
    """`_volume_table`, remembered for the last 8 (σ, n_i, lights, grid): the alternation asks for
    the same model in its full-size step as in its last round."""
    s = np.ascontiguousarray(lights, np.float64)
    key = (float(sigma), float(n_i), int(grid), volume_model, s.tobytes())
    tab = _TABLES.get(key)
    if tab is None:
        tab = _volume_table(s, sigma, n_i, grid, volume_model)
        if len(_TABLES) >= 8:
            _TABLES.pop(next(iter(_TABLES)))
        _TABLES[key] = tab
    return tab


def _volume_table(lights, sigma, n_i, grid, volume_model):
    """(grid, grid, m) float32 B(n, s_i) on normals n = (x, y, √(1 − x² − y²)), x and y on
    linspace(−1, 1, grid) (row index: y, column: x); 0 outside the unit disk. Lights last: the
    four corners of a pixel's cell hold every light's value side by side (cache lines)."""
    u = np.linspace(-1, 1, grid)
    gx, gy = np.meshgrid(u, u)
    r2 = gx * gx + gy * gy
    inside = r2 < 1
    nz = np.sqrt(np.maximum(1 - r2, 0))
    gn = np.stack([gx, gy, nz], -1)[inside].astype(np.float32)
    # the disk's normals only (π/4 of the grid; the values are per normal, the same bits)
    b = np.zeros((grid, grid, len(lights)), np.float32)
    b[inside] = li_shading_terms(gn, lights, sigma, n_i, specular=False, volume_model=volume_model)[1]
    return b


_SQRT_PI = math.sqrt(math.pi)


@njit(cache=True)
def _g1_dlog(c, sigma):
    """(Smith G_1 for Beckmann at cosine c, the same bits as `smith_g1_beckmann`; d ln G_1 / dc)."""
    if c <= 0.0:
        return 0.0, 0.0
    if c > 1.0:
        c = 1.0
    sn = math.sqrt(max(1.0 - c * c, 0.0))
    if sn <= 0.0:
        return 1.0, 0.0
    a = c / (sigma * sn)
    ex = math.exp(-a * a)
    lam = 0.5 * (ex / (a * _SQRT_PI) - math.erfc(a))
    g = 1.0 / (1.0 + lam)
    # dΛ/da = −e^(−a²) / (2√π a²), da/dc = 1 / (σ sin³): d ln G_1/dc = G_1 e^(−a²) σ / (2√π c² sin)
    return g, g * ex * sigma / (2.0 * _SQRT_PI * c * c * sn)


@njit(cache=True)
def _model(nx, ny, nz, s, sh, fres, btab, sigma, spec, a_out, b_out, pa_out, qa_out):
    """A and B for one normal and every light into a_out, b_out (m,), and A's derivative along a
    tangent t of the normal as dA/dt = pa_out (s·t) + qa_out t_z (eq 3.10 differentiated: D through
    cos θ_h = n·h, G_1 through n·s and n·z, 1 / (4 n·z))."""
    m = s.shape[0]
    g = btab.shape[0]
    # bilinear position in the B table (same for every light)
    fx = (nx + 1.0) * 0.5 * (g - 1)
    fy = (ny + 1.0) * 0.5 * (g - 1)
    fx = min(max(fx, 0.0), g - 1.000001)
    fy = min(max(fy, 0.0), g - 1.000001)
    ix = int(fx)
    iy = int(fy)
    wx = fx - ix
    wy = fy - iy
    co = min(max(nz, 0.0), 1.0)
    g1o, dg1o = _g1_dlog(co, sigma) if spec else (0.0, 0.0)
    qo = dg1o - 1.0 / co if co > 0.0 else 0.0
    s2 = sigma * sigma
    for i in range(m):
        a_out[i] = 0.0
        pa_out[i] = 0.0
        qa_out[i] = 0.0
        cs = nx * s[i, 0] + ny * s[i, 1] + nz * s[i, 2]
        if cs <= 0.0 or nz <= 0.0:
            b_out[i] = 0.0
            continue
        b_out[i] = ((1 - wx) * (1 - wy) * btab[iy, ix, i] + wx * (1 - wy) * btab[iy, ix + 1, i]
                    + (1 - wx) * wy * btab[iy + 1, ix, i] + wx * wy * btab[iy + 1, ix + 1, i])
        if spec:
            csc = min(cs, 1.0)
            ch = min(max((cs + co) / (2.0 * sh[i]), 0.0), 1.0)
            ch2 = ch * ch
            if 1.0 - ch2 < 16.0 * s2 * ch2 and ch2 > 0.0:
                g1s, dg1s = _g1_dlog(csc, sigma)
                av = fres[i] * beckmann_d(ch2, s2) * g1s * g1o / (4.0 * co)
                a_out[i] = av
                # d ln D / d cos θ_h = 2 / (σ² cos³ θ_h) − 4 / cos θ_h; d cos θ_h = (s·t + t_z) / (2 sh)
                dd = (2.0 / (s2 * ch2 * ch) - 4.0 / ch) / (2.0 * sh[i])
                pa_out[i] = av * (dd + dg1s)
                qa_out[i] = av * (dd + qo)


@njit(cache=True)
def _kappa(e, a, b, w, k_out):
    """κ_c = max(Σ w b (e − a) / Σ w b², 0); w (m, C)."""
    m, c = e.shape
    for ch in range(c):
        num = 0.0
        den = 0.0
        for i in range(m):
            wb = w[i, ch] * b[i]
            num += wb * (e[i, ch] - a[i])
            den += wb * b[i]
        k_out[ch] = max(num / max(den, 1e-20), 0.0)


@njit(cache=True)
def _resid(e, a, b, k, keep, r_out):
    m, c = e.shape
    for i in range(m):
        for ch in range(c):
            r_out[i, ch] = (e[i, ch] - a[i] - b[i] * k[ch]) if keep[i] else 0.0


@njit(cache=True)
def _scale(r, keep, mean_e, buf, floor):
    m, c = r.shape
    cnt = 0
    for i in range(m):
        if keep[i]:
            for ch in range(c):
                buf[cnt] = abs(r[i, ch])
                cnt += 1
    med = np.median(buf[:cnt]) if cnt > 0 else 0.0
    return max(max(1.4826 * med, floor * mean_e), 1e-12)


@njit(cache=True)
def _cost(r, keep, sc):
    m, c = r.shape
    tot = 0.0
    for i in range(m):
        if keep[i]:
            for ch in range(c):
                q = r[i, ch] / sc
                tot += math.log1p(q * q)
    return tot


@njit(cache=True)
def _solve_one(e, ok, n0, s, sh, fres, btab, sigma, spec, iterations, scale_in, cast_ratio,
               floor, max_step, step_tol, ws):
    """One start for one pixel. Returns (nx, ny, nz, cost, scale, rel, n_kept, iterations);
    κ in ws.k, the kept flags in ws.keep."""
    (a, b, pa, ac, bc, k, kc, r, rc, wr, ju, jv, keep, buf, w0, qa, pc, qc) = ws
    m, c = e.shape
    nl = math.sqrt(n0[0] ** 2 + n0[1] ** 2 + n0[2] ** 2)
    if nl > 1e-12:
        nx, ny, nz = n0[0] / nl, n0[1] / nl, n0[2] / nl
    else:
        nx, ny, nz = 0.0, 0.0, 1.0
    _model(nx, ny, nz, s, sh, fres, btab, sigma, spec, a, b, pa, qa)
    for i in range(m):
        for ch in range(c):
            w0[i, ch] = 1.0 if ok[i] else 0.0
    _kappa(e, a, b, w0, k)
    g_ch = 1 if c == 3 else 0
    pmax = 0.0
    for i in range(m):
        p = a[i] + b[i] * k[g_ch]
        pmax = max(pmax, p)
    nkeep = 0
    sum_e = 0.0
    for i in range(m):
        p = a[i] + b[i] * k[g_ch]
        keep[i] = ok[i] and not (e[i, g_ch] < cast_ratio * p and p > 0.05 * pmax)
        if keep[i]:
            nkeep += 1
            for ch in range(c):
                sum_e += e[i, ch]
    mean_e = sum_e / max(nkeep * c, 1)
    for i in range(m):
        for ch in range(c):
            w0[i, ch] = 1.0 if keep[i] else 0.0
    _kappa(e, a, b, w0, k)
    _resid(e, a, b, k, keep, r)
    if nkeep < 3:
        return nx, ny, nz, 0.0, 1.0, 1.0, nkeep, 0
    rescale = scale_in <= 0.0
    # robust κ at the start (IRLS, no new model evaluation)
    for _ in range(3):
        sc = _scale(r, keep, mean_e, buf, floor) if rescale else scale_in
        for i in range(m):
            for ch in range(c):
                q = r[i, ch] / sc
                wr[i, ch] = (1.0 if keep[i] else 0.0) / (1.0 + q * q)
        _kappa(e, a, b, wr, k)
        _resid(e, a, b, k, keep, r)
    scale = _scale(r, keep, mean_e, buf, floor) if rescale else scale_in
    cost = _cost(r, keep, scale)
    lam = 1e-2
    it = 0
    for it in range(1, iterations + 1):
        if rescale and (it == 3 or it == 6):
            _resid(e, a, b, k, keep, r)
            scale = _scale(r, keep, mean_e, buf, floor)
            cost = _cost(r, keep, scale)
            lam = max(lam, 1e-2)
        # tangents
        if abs(nz) < 0.9:
            t1x, t1y, t1z = ny, -nx, 0.0          # n × z
        else:
            t1x, t1y, t1z = 0.0, nz, -ny          # n × x
        tl = math.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
        t1x, t1y, t1z = t1x / tl, t1y / tl, t1z / tl
        t2x, t2y, t2z = ny * t1z - nz * t1y, nz * t1x - nx * t1z, nx * t1y - ny * t1x
        _resid(e, a, b, k, keep, r)
        for i in range(m):
            for ch in range(c):
                q = r[i, ch] / scale
                wr[i, ch] = (1.0 if keep[i] else 0.0) / (1.0 + q * q)
        # Jacobian: the lobe's analytic derivative (`_model`), the volume part as (B / n·s)(s·t) κ
        for tt in range(2):
            if tt == 0:
                tx, ty, tz = t1x, t1y, t1z
            else:
                tx, ty, tz = t2x, t2y, t2z
            jj = ju if tt == 0 else jv
            for i in range(m):
                cs = nx * s[i, 0] + ny * s[i, 1] + nz * s[i, 2]
                bo = b[i] / max(cs, 1e-4) if cs > 1e-4 else 0.0
                st = tx * s[i, 0] + ty * s[i, 1] + tz * s[i, 2]
                da = pa[i] * st + qa[i] * tz
                for ch in range(c):
                    jj[i, ch] = da + bo * st * k[ch]
        huu = hvv = huv = gu = gv = 0.0
        for i in range(m):
            for ch in range(c):
                w = wr[i, ch]
                huu += w * ju[i, ch] * ju[i, ch]
                hvv += w * jv[i, ch] * jv[i, ch]
                huv += w * ju[i, ch] * jv[i, ch]
                gu += w * ju[i, ch] * r[i, ch]
                gv += w * jv[i, ch] * r[i, ch]
        huu_d = huu * (1 + lam) + 1e-20
        hvv_d = hvv * (1 + lam) + 1e-20
        det = huu_d * hvv_d - huv * huv
        if abs(det) <= 1e-30:
            det = 1e-30
        du = (hvv_d * gu - huv * gv) / det
        dv = (huu_d * gv - huv * gu) / det
        step = math.sqrt(du * du + dv * dv)
        shrink = min(1.0, max_step / max(step, 1e-12))
        cx = nx + du * shrink * t1x + dv * shrink * t2x
        cy = ny + du * shrink * t1y + dv * shrink * t2y
        cz = nz + du * shrink * t1z + dv * shrink * t2z
        cl = math.sqrt(cx * cx + cy * cy + cz * cz)
        if cl > 1e-12:
            cx, cy, cz = cx / cl, cy / cl, cz / cl
        else:
            cx, cy, cz = 0.0, 0.0, 1.0
        _model(cx, cy, cz, s, sh, fres, btab, sigma, spec, ac, bc, pc, qc)
        _kappa(e, ac, bc, wr, kc)
        _resid(e, ac, bc, kc, keep, rc)
        cc = _cost(rc, keep, scale)
        if cc <= cost:
            nx, ny, nz, cost = cx, cy, cz, cc
            for i in range(m):
                a[i] = ac[i]
                b[i] = bc[i]
                pa[i] = pc[i]
                qa[i] = qc[i]
            for ch in range(c):
                k[ch] = kc[ch]
            lam = max(lam / 3, 1e-4)
            if step * shrink < step_tol:
                break
        else:
            lam *= 10
            if lam > 1e3:
                break
    _resid(e, a, b, k, keep, r)
    num = 0.0
    den = 0.0
    for i in range(m):
        if keep[i]:
            for ch in range(c):
                num += r[i, ch] * r[i, ch]
                den += e[i, ch] * e[i, ch]
    rel = math.sqrt(num) / math.sqrt(den) if den > 0 else 0.0
    return nx, ny, nz, cost, scale, rel, nkeep, it


@njit(cache=True)
def _workspace(m, c):
    # a, b, pa, ac, bc, k, kc, r, rc, wr, ju, jv, keep, buf, w0, qa, pc, qc (the order `_solve_one` unpacks)
    return (np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
            np.empty(c), np.empty(c), np.empty((m, c)), np.empty((m, c)), np.empty((m, c)),
            np.empty((m, c)), np.empty((m, c)), np.empty(m, np.bool_), np.empty(m * c),
            np.empty((m, c)), np.empty(m), np.empty(m), np.empty(m))


@njit(cache=True, parallel=True)
def _refine_all(e, ok, n0, n1, has1, s, sh, fres, btab, sigma, spec, iterations, cast_ratio,
                floor, max_step, step_tol, second_above, out_n, out_k, out_used, out_cost, out_rel, out_it, chunk):
    n_pix, m, c = e.shape
    n_chunks = (n_pix + chunk - 1) // chunk
    for q in prange(n_chunks):
        ws = _workspace(m, 1)
        keep_best = np.empty(m, np.bool_)
        a_best = np.empty(m)
        b_best = np.empty(m)
        em = np.empty((m, 1))
        for p in range(q * chunk, min((q + 1) * chunk, n_pix)):
            # the normal from the channels' mean: E_c = A + B κ_c gives mean_c E_c = A + B mean_c κ_c,
            # the same model on one channel (the lobe is white), a third of the work
            for i in range(m):
                tot = 0.0
                for ch in range(c):
                    tot += e[p, i, ch]
                em[i, 0] = tot / c
            r1 = _solve_one(em, ok[p], n0[p], s, sh, fres, btab, sigma, spec, iterations, -1.0,
                            cast_ratio, floor, max_step, step_tol, ws)
            bx, by, bz, bcost, bscale, brel, bkeep, bit = r1
            keep_best[:] = ws[12]
            a_best[:] = ws[0]
            b_best[:] = ws[1]
            k_mean = ws[5][0]
            if has1[p] and bkeep >= 3 and brel >= second_above:
                r2 = _solve_one(em, ok[p], n1[p], s, sh, fres, btab, sigma, spec, iterations, bscale,
                                cast_ratio, floor, max_step, step_tol, ws)
                if r2[3] < bcost:
                    bx, by, bz, bcost, _, brel, bkeep, it2 = r2
                    bit = max(bit, it2)
                    keep_best[:] = ws[12]
                    a_best[:] = ws[0]
                    b_best[:] = ws[1]
                    k_mean = ws[5][0]
            # κ per channel at the chosen normal, with the mean channel's robust weights
            for ch in range(c):
                num = 0.0
                den = 0.0
                for i in range(m):
                    if keep_best[i]:
                        rr = (em[i, 0] - a_best[i] - b_best[i] * k_mean) / bscale
                        wgt = b_best[i] / (1.0 + rr * rr)
                        num += wgt * (e[p, i, ch] - a_best[i])
                        den += wgt * b_best[i]
                out_k[p, ch] = max(num / max(den, 1e-20), 0.0)
            out_n[p, 0], out_n[p, 1], out_n[p, 2] = bx, by, bz
            out_used[p, :] = keep_best
            out_cost[p] = bcost
            out_rel[p] = brel if bkeep >= 3 else 1.0
            out_it[p] = bit


def refine_distant_compiled(e, lights, normals, sigma, n_i, usable, iterations, extra_start=None,
                            extra_rows=None, cast_ratio=0.25, floor=0.03, max_step=0.15,
                            step_tol=2e-4, table=None, volume_model="approx", chunk=CHUNK, second_above=None):
    """Arrays in as `refine_normals_li` (distant lights (m, 3) only, at most one extra start);
    step_tol : rad, a pixel stops once an accepted step is below it.
    chunk : pixels per work item of the threaded loop (numba prange over chunks, as many threads
        as numba's NUMBA_NUM_THREADS, by default os.cpu_count()); each pixel is solved alone, so
        the result does not depend on it nor on the thread count (tests/fit/test_normals_li.py).
    Returns (normals (N, 3) f32, kappa (N, C) f32, used (N, m), cost (N,), rel (N,) f32,
    iterations (N,) int32)."""
    e = np.asarray(e, np.float32)
    n_pix, m, c = e.shape
    s = np.ascontiguousarray(lights, np.float64)
    ok = np.asarray(usable, bool) & np.all(np.isfinite(e), axis=2)
    e = np.ascontiguousarray(np.where(ok[..., None], e, np.float32(0)))
    sig = max(float(sigma), 1e-6)
    spec = bool(float(sigma) >= 1e-9 and float(n_i) != 1.0)
    sh = np.sqrt(np.maximum((1 + s[:, 2]) / 2, 1e-12))
    fres = fresnel_dielectric(sh, n_i).astype(np.float64)
    btab = volume_table(lights, sigma, n_i, volume_model=volume_model) if table is None else table
    n0 = np.ascontiguousarray(normals, np.float64)
    n1 = n0 if extra_start is None else np.ascontiguousarray(extra_start, np.float64)
    has1 = np.zeros(n_pix, bool) if extra_start is None else (
        np.ones(n_pix, bool) if extra_rows is None else np.asarray(extra_rows, bool))
    out_n = np.empty((n_pix, 3))
    out_k = np.empty((n_pix, c))
    out_used = np.empty((n_pix, m), bool)
    out_cost = np.empty(n_pix)
    out_rel = np.empty(n_pix)
    out_it = np.empty(n_pix, np.int32)
    second_above = SECOND_START_ABOVE if second_above is None else second_above
    _refine_all(e, ok, n0, n1, has1, s, sh, fres, btab, sig, spec, int(iterations), cast_ratio, floor,
                max_step, float(step_tol), float(second_above), out_n, out_k, out_used, out_cost, out_rel, out_it, int(chunk))
    return (out_n.astype(np.float32), out_k.astype(np.float32), out_used, out_cost,
            out_rel.astype(np.float32), out_it)


@njit(cache=True, parallel=True)
def _bin_kernel(images, mask, f, saturation, out):
    m, h, w, c = images.shape
    hc, wc = out.shape[1], out.shape[2]
    for i in prange(m):
        for by in range(hc):
            for bx in range(wc):
                for ch in range(c):
                    tot = 0.0
                    cnt = 0
                    for y in range(by * f, min((by + 1) * f, h)):
                        for x in range(bx * f, min((bx + 1) * f, w)):
                            v = images[i, y, x, ch]
                            if mask[y, x] and math.isfinite(v) and v < saturation:
                                tot += v
                                cnt += 1
                    out[i, by, bx, ch] = tot / cnt if 2 * cnt >= f * f else np.nan


def bin_images(images, mask, f, saturation=None):
    """(m, ceil(H/f), ceil(W/f), C) float32 block means of the masked, finite values below
    `saturation` of (m, H, W, C) images; NaN where fewer than half the block's f × f pixels count."""
    m, h, w, c = images.shape
    out = np.empty((m, -(-h // f), -(-w // f), c), np.float32)
    _bin_kernel(images, np.ascontiguousarray(mask, bool), int(f),
                np.inf if saturation is None else float(saturation), out)
    return out
