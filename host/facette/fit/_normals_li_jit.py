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

The step is variable projection's (`_damped_step`): without it the normal and κ zig-zagged (noiseless
σ 0.3 pixels: 0.8° short after 24 steps; DiLiGenT pot2's round 1: 15.2 steps a pixel, 8.9 with it).

The model values: the specular lobe A (eq 3.10) is evaluated per pixel and light (the Fresnel
factor F(s·h) is one number per distant light; Smith's G_1 from a table, within 1e-7 of it:
`smith_g1_dlog_tabulated`; the Cauchy cost Σ ln(1 + q²) as the log of running products: exp, erfc
and log1p per light were ~30 % of the solve, DiLiGenT's photometric stereo 28 -> 22 s, the same
errors to 0.01°); the volume part B(n, s_i) (eq 3.15, by the
formula eq 3.49–3.57 or the quadrature tables: `volume_model`) is smooth in the normal, so for each
light it is tabulated once per (σ, n_i) over the normals' stereographic coordinates (`_volume_table`)
and interpolated bilinearly (≤ 2e-4 of the direct evaluation at the median up to 89.5° of tilt, see
the tests). Per-pixel (near-light) directions are not tabulated: they go through the array code.

The kept lights: once a start's cast shadows are found, its solve evaluates and sums only the
lights it keeps, packed to the front of its work arrays in order (a light left out weighed 0 in
every sum, so the numbers are the same to the last bit: tests/fit/li_solve_reference.py); residual,
weights, Jacobian and normal equations are one pass, and the candidate's arrays are swapped in,
not copied. DiLiGenT reading (96 lights, a third of the values unusable), its round-1 pixels on
one thread: 0.75–0.81 of the time before.

First call in a fresh environment compiles the kernel (~10–20 s on one core); numba caches the
machine code next to this file (__pycache__), later processes load it in well under a second.
"""
import math

import numba
import numpy as np
from numba import njit, prange

from facette._select_jit import median_in_place
from facette.brdf import fresnel_dielectric
from facette.brdf._lobe_jit import SMITH_G1_TABLE, smith_g1_dlog_scaled, smith_g1_dlog_tabulated

# the B table's builder, imported here too (tests, `_normals_li` take it from this module)
from ._normals_li_table import TABLE_BLOCK, TABLE_GRID, _volume_table, volume_table  # noqa: F401

__all__ = ["volume_table", "refine_distant_compiled", "model_constants", "chunk_for", "TABLE_GRID"]

CHUNK = 256               # pixels per work item of the threaded per-pixel loop (at most)
# The extra start is tried where the first leaves a relative RMS residual ≥ this. 0: everywhere.
# Skipping it where the first start already explains the pixel is faster and was no worse on the
# DiLiGenT cat and reading, 96 lights (their round-1 pixels: 0.05 skips 61 % / 11 % of the second
# starts, mean error 5.658 -> 5.637 / 10.380 -> 10.379°), but on the Mitsuba renders, which choose,
# every threshold tried was worse (0.03: satin sphere 1.947 -> 1.975°, shell lacquer 0.571 -> 0.601,
# satin relief 1.079 -> 1.094; 0.05 and 0.08 worse still): so 0. Never applied to a metal's
# hemisphere search start (`refine_normals_li` passes 0 there).
SECOND_START_ABOVE = 0.0
# Under many lights (MANY_LIGHTS or more) the values decide the minimum: the second start is tried
# only where the first leaves a relative RMS residual >= SECOND_START_ABOVE_MANY. It doubled the
# round-1 solve on nearly every pixel (a highlight stands out somewhere under a dome). Rendered
# satin relief (`facette bench lights`, 481x466): 48 lights 16.2 -> 10.7 CPU s, 96 lights
# 22.9 -> 16.2, mean error the same to 0.001° (0.072°, 0.051°); DiLiGenT 96 lights: the note above
# (and the perf note's table). The rig's 12 lights keep SECOND_START_ABOVE.
MANY_LIGHTS = 24
SECOND_START_ABOVE_MANY = 0.05


COST_PRODUCT_MAX = 1e200   # the Cauchy cost's running product is logged and restarted above this

@njit(cache=True)
def _model(nx, ny, nz, s, sh, fres, btab, g1tab, sigma, spec, lights, n_lights, a_out, b_out, pa_out, qa_out,
           cs_out):
    """A and B for one normal and the lights `lights[:n_lights]` (indices into s) into the first
    n_lights slots of a_out, b_out, with n·s into cs_out and A's derivative along a tangent t of
    the normal as dA/dt = pa_out (s·t) + qa_out t_z (eq 3.10 differentiated: D through
    cos θ_h = n·h, G_1 through n·s and n·z, 1 / (4 n·z))."""
    g = btab.shape[0]
    # bilinear position in the B table (same for every light): (u, v) = (n_x, n_y) / (1 + n_z)
    inv = 1.0 / max(1.0 + nz, 1e-6)
    fx = (nx * inv + 1.0) * 0.5 * (g - 1)
    fy = (ny * inv + 1.0) * 0.5 * (g - 1)
    fx = min(max(fx, 0.0), g - 1.000001)
    fy = min(max(fy, 0.0), g - 1.000001)
    ix = int(fx)
    iy = int(fy)
    wx = fx - ix
    wy = fy - iy
    co = min(max(nz, 0.0), 1.0)
    g1o, dg1o = smith_g1_dlog_tabulated(co, sigma, g1tab) if spec else (0.0, 0.0)
    qo = dg1o - 1.0 / co if co > 0.0 else 0.0
    s2 = sigma * sigma
    # reciprocals taken once: a division per light and factor was a third of the lobe's time
    inv_s2 = 1.0 / s2
    inv_sigma = 1.0 / sigma
    d_norm = 1.0 / (math.pi * s2)
    inv_4co = 1.0 / (4.0 * co) if co > 0.0 else 0.0
    for t in range(n_lights):
        i = lights[t]
        a_out[t] = 0.0
        pa_out[t] = 0.0
        qa_out[t] = 0.0
        cs = nx * s[i, 0] + ny * s[i, 1] + nz * s[i, 2]
        cs_out[t] = cs
        if cs <= 0.0 or nz <= 0.0:
            b_out[t] = 0.0
            continue
        b_out[t] = ((1 - wx) * (1 - wy) * btab[iy, ix, i] + wx * (1 - wy) * btab[iy, ix + 1, i]
                    + (1 - wx) * wy * btab[iy + 1, ix, i] + wx * wy * btab[iy + 1, ix + 1, i])
        if spec:
            csc = min(cs, 1.0)
            half_sh = 0.5 / sh[i]
            ch = min(max((cs + co) * half_sh, 0.0), 1.0)
            ch2 = ch * ch
            if 1.0 - ch2 < 16.0 * s2 * ch2 and ch2 > 0.0:
                g1s, dg1s = smith_g1_dlog_scaled(csc, inv_sigma, g1tab)
                ich = 1.0 / ch
                ich2 = ich * ich
                # Beckmann D = exp(−tan² θ_h / σ²) / (π σ² cos⁴ θ_h) (`beckmann_d`, its reciprocals shared)
                av = fres[i] * (math.exp(-(1.0 - ch2) * ich2 * inv_s2) * d_norm * ich2 * ich2) * g1s * g1o * inv_4co
                a_out[t] = av
                # d ln D / d cos θ_h = 2 / (σ² cos³ θ_h) − 4 / cos θ_h; d cos θ_h = (s·t + t_z) / (2 sh)
                dd = (2.0 * inv_s2 * ich2 * ich - 4.0 * ich) * half_sh
                pa_out[t] = av * (dd + dg1s)
                qa_out[t] = av * (dd + qo)


@njit(cache=True)
def _kappa(e, a, b, w, n):
    """κ = max(Σ w b (e − a) / Σ w b², 0) over the first n values."""
    num = 0.0
    den = 0.0
    for t in range(n):
        wb = w[t] * b[t]
        num += wb * (e[t] - a[t])
        den += wb * b[t]
    return max(num / max(den, 1e-20), 0.0)


@njit(cache=True)
def _residuals(e, a, b, k, n, r_out):
    for t in range(n):
        r_out[t] = e[t] - a[t] - b[t] * k


@njit(cache=True)
def _scale(r, n, mean_e, buf, floor):
    for t in range(n):
        buf[t] = abs(r[t])
    med = median_in_place(buf, n) if n > 0 else 0.0
    return max(max(1.4826 * med, floor * mean_e), 1e-12)


@njit(cache=True)
def _log_product(prod, tot):
    """(1.0, tot + ln prod) once the running product of the Cauchy terms nears overflow, else as is."""
    if prod > COST_PRODUCT_MAX:
        return 1.0, tot + math.log(prod)
    return prod, tot


@njit(cache=True)
def _cost(e, a, b, k, n, sc):
    """Σ ln(1 + q²) over the first n values, q = (e − a − b κ) / sc, as the log of running products:
    one log per ~100 lights, not one each."""
    tot = 0.0
    prod = 1.0
    inv_sc = 1.0 / sc
    for t in range(n):
        q = (e[t] - a[t] - b[t] * k) * inv_sc
        prod, tot = _log_product(prod * (1.0 + q * q), tot)
    return tot + math.log(prod)


@njit(cache=True)
def _tangent_frame(nx, ny, nz):
    """Two unit tangents of the unit normal n: t1 = n × z (n × x near the pole), t2 = n × t1."""
    if abs(nz) < 0.9:
        t1x, t1y, t1z = ny, -nx, 0.0
    else:
        t1x, t1y, t1z = 0.0, nz, -ny
    tl = math.sqrt(t1x * t1x + t1y * t1y + t1z * t1z)
    t1x, t1y, t1z = t1x / tl, t1y / tl, t1z / tl
    return t1x, t1y, t1z, ny * t1z - nz * t1y, nz * t1x - nx * t1z, nx * t1y - ny * t1x


@njit(cache=True)
def _damped_step(huu, hvv, huv, gu, gv, sbb, sbu, sbv, sbr, k, lam):
    """(du, dv): the Levenberg–Marquardt step on the tangent angles from the weighted normal
    equations (huu, hvv, huv; gu, gv) and the κ column's sums (Σ w b², Σ w b ju, Σ w b jv, Σ w b r).
    Variable projection (Kaufman's form): κ is solved again at the candidate, so where κ > 0 the
    step is taken along the Jacobian's part that a change of κ cannot mimic."""
    if k > 0.0 and sbb > 1e-30:
        huu -= sbu * sbu / sbb
        hvv -= sbv * sbv / sbb
        huv -= sbu * sbv / sbb
        gu -= sbu * sbr / sbb
        gv -= sbv * sbr / sbb
    huu_d = huu * (1 + lam) + 1e-20
    hvv_d = hvv * (1 + lam) + 1e-20
    det = huu_d * hvv_d - huv * huv
    if abs(det) <= 1e-30:
        det = 1e-30
    return (hvv_d * gu - huv * gv) / det, (huu_d * gv - huv * gu) / det


@njit(cache=True)
def _solve_one(e_all, ok, n0, s, sh, fres, btab, g1tab, sigma, spec, iterations, scale_in, cast_ratio,
               floor, max_step, step_tol, ws):
    """One start for one pixel, one channel e_all (m,). Returns (nx, ny, nz, cost, scale, rel,
    n_kept, iterations, κ, A, B): the kept lights are ws[12][:n_kept] (indices, in order) and A, B
    their model values at the normal returned (the first n_kept slots).

    Once the cast shadows are found (at the start normal), only the kept lights are evaluated:
    they are packed to the front of the work arrays, in order. A light left out had weight 0 in
    every sum, so skipping it gives the same sums bit for bit and saves its model evaluation
    (DiLiGenT reading: a third of the values are unusable)."""
    (a, b, pa, qa, cs_, ac, bc, pc, qc, csc_, r, wr, kept, buf, e) = ws
    m = e_all.shape[0]
    nl = math.sqrt(n0[0] ** 2 + n0[1] ** 2 + n0[2] ** 2)
    if nl > 1e-12:
        nx, ny, nz = n0[0] / nl, n0[1] / nl, n0[2] / nl
    else:
        nx, ny, nz = 0.0, 0.0, 1.0
    for i in range(m):
        kept[i] = i
    _model(nx, ny, nz, s, sh, fres, btab, g1tab, sigma, spec, kept, m, a, b, pa, qa, cs_)
    for i in range(m):
        wr[i] = 1.0 if ok[i] else 0.0
    k = _kappa(e_all, a, b, wr, m)
    pmax = 0.0
    for i in range(m):
        p = a[i] + b[i] * k
        pmax = max(pmax, p)
    n, sum_e = 0, 0.0
    for i in range(m):
        p = a[i] + b[i] * k
        if ok[i] and not (e_all[i] < cast_ratio * p and p > 0.05 * pmax):
            kept[n] = i          # n ≤ i: packing in place never overwrites a light still to read
            a[n] = a[i]
            b[n] = b[i]
            pa[n] = pa[i]
            qa[n] = qa[i]
            cs_[n] = cs_[i]
            e[n] = e_all[i]
            n += 1
            sum_e += e_all[i]
    mean_e = sum_e / max(n, 1)
    for t in range(n):
        wr[t] = 1.0
    k = _kappa(e, a, b, wr, n)
    if n < 3:
        return nx, ny, nz, 0.0, 1.0, 1.0, n, 0, k, a, b
    _residuals(e, a, b, k, n, r)
    rescale = scale_in <= 0.0
    # robust κ at the start (IRLS, no new model evaluation)
    for _ in range(3):
        sc = _scale(r, n, mean_e, buf, floor) if rescale else scale_in
        for t in range(n):
            q = r[t] / sc
            wr[t] = 1.0 / (1.0 + q * q)
        k = _kappa(e, a, b, wr, n)
        _residuals(e, a, b, k, n, r)
    scale = _scale(r, n, mean_e, buf, floor) if rescale else scale_in
    cost = _cost(e, a, b, k, n, scale)
    lam, inv_scale = 1e-2, 1.0 / scale
    it = 0
    for it in range(1, iterations + 1):
        if rescale and (it == 3 or it == 6):
            _residuals(e, a, b, k, n, r)
            scale = _scale(r, n, mean_e, buf, floor)
            cost = _cost(e, a, b, k, n, scale)
            lam, inv_scale = max(lam, 1e-2), 1.0 / scale
        t1x, t1y, t1z, t2x, t2y, t2z = _tangent_frame(nx, ny, nz)
        # residual, Cauchy weight, Jacobian (the lobe's analytic derivative from `_model`, the
        # volume part as (B / n·s)(s·t) κ) and the normal equations in one pass
        huu = hvv = huv = gu = gv = 0.0
        sbb = sbu = sbv = sbr = 0.0
        for t in range(n):
            i = kept[t]
            rt = e[t] - a[t] - b[t] * k
            q = rt * inv_scale
            w = 1.0 / (1.0 + q * q)
            wr[t] = w
            cs = cs_[t]
            bo = b[t] / max(cs, 1e-4) if cs > 1e-4 else 0.0
            st = t1x * s[i, 0] + t1y * s[i, 1] + t1z * s[i, 2]
            ju = (pa[t] * st + qa[t] * t1z) + bo * st * k
            st = t2x * s[i, 0] + t2y * s[i, 1] + t2z * s[i, 2]
            jv = (pa[t] * st + qa[t] * t2z) + bo * st * k
            huu += w * ju * ju
            hvv += w * jv * jv
            huv += w * ju * jv
            gu += w * ju * rt
            gv += w * jv * rt
            wb = w * b[t]
            sbb += wb * b[t]
            sbu += wb * ju
            sbv += wb * jv
            sbr += wb * rt
        du, dv = _damped_step(huu, hvv, huv, gu, gv, sbb, sbu, sbv, sbr, k, lam)
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
        _model(cx, cy, cz, s, sh, fres, btab, g1tab, sigma, spec, kept, n, ac, bc, pc, qc, csc_)
        kc = _kappa(e, ac, bc, wr, n)
        cc = _cost(e, ac, bc, kc, n, scale)
        if cc <= cost:
            # the candidate's arrays become the current ones: swapped, not copied
            nx, ny, nz, cost = cx, cy, cz, cc
            a, ac = ac, a
            b, bc = bc, b
            pa, pc = pc, pa
            qa, qc = qc, qa
            cs_, csc_ = csc_, cs_
            k = kc
            lam = max(lam / 3, 1e-4)
            if step * shrink < step_tol:
                break
        else:
            lam *= 10
            if lam > 1e3:
                break
    num = 0.0
    den = 0.0
    for t in range(n):
        rt = e[t] - a[t] - b[t] * k
        num += rt * rt
        den += e[t] * e[t]
    rel = math.sqrt(num) / math.sqrt(den) if den > 0 else 0.0
    return nx, ny, nz, cost, scale, rel, n, it, k, a, b


@njit(cache=True)
def _workspace(m):
    # a, b, pa, qa, cs, ac, bc, pc, qc, csc, r, wr, kept, buf, e (the order `_solve_one` unpacks)
    return (np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
            np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
            np.empty(m), np.empty(m), np.empty(m, np.int64), np.empty(m), np.empty(m))


@njit(cache=True, parallel=True, nogil=True)
def _refine_all(e, usable, n0, n1, has1, s, sh, fres, btab, g1tab, sigma, spec, iterations, cast_ratio,
                floor, max_step, step_tol, second_above, out_n, out_k, out_used, out_cost, out_rel, out_it, chunk):
    n_pix, m, c = e.shape
    n_chunks = (n_pix + chunk - 1) // chunk
    for q in prange(n_chunks):
        ws = _workspace(m)
        kept_best = np.empty(m, np.int64)
        a_best = np.empty(m)
        b_best = np.empty(m)
        w_best = np.empty(m)
        em = np.empty(m)
        ok = np.empty(m, np.bool_)
        for p in range(q * chunk, min((q + 1) * chunk, n_pix)):
            # the normal from the channels' mean: E_c = A + B κ_c gives mean_c E_c = A + B mean_c κ_c,
            # the same model on one channel (the lobe is white), a third of the work. A light is
            # used where it is usable and finite in every channel; 0 elsewhere (its weight is 0)
            for i in range(m):
                good = usable[p, i]
                tot = 0.0
                for ch in range(c):
                    v = e[p, i, ch]
                    good = good and np.isfinite(v)
                    tot += v
                ok[i] = good
                em[i] = tot / c if good else 0.0
            r1 = _solve_one(em, ok, n0[p], s, sh, fres, btab, g1tab, sigma, spec, iterations, -1.0,
                            cast_ratio, floor, max_step, step_tol, ws)
            bx, by, bz, bcost, bscale, brel, bkeep, bit, k_mean, a_sol, b_sol = r1
            kept_best[:bkeep] = ws[12][:bkeep]
            a_best[:bkeep] = a_sol[:bkeep]
            b_best[:bkeep] = b_sol[:bkeep]
            if has1[p] and bkeep >= 3 and brel >= second_above:
                r2 = _solve_one(em, ok, n1[p], s, sh, fres, btab, g1tab, sigma, spec, iterations, bscale,
                                cast_ratio, floor, max_step, step_tol, ws)
                if r2[3] < bcost:
                    bx, by, bz, bcost, _, brel, bkeep, it2, k_mean, a_sol, b_sol = r2
                    bit = max(bit, it2)
                    kept_best[:bkeep] = ws[12][:bkeep]
                    a_best[:bkeep] = a_sol[:bkeep]
                    b_best[:bkeep] = b_sol[:bkeep]
            # κ per channel at the chosen normal, with the mean channel's robust weights (the
            # weights and their sum Σ w b are the channels' own: taken once, the same numbers)
            den = 0.0
            for t in range(bkeep):
                rr = (em[kept_best[t]] - a_best[t] - b_best[t] * k_mean) / bscale
                w_best[t] = b_best[t] / (1.0 + rr * rr)
                den += w_best[t] * b_best[t]
            for ch in range(c):
                num = 0.0
                for t in range(bkeep):
                    num += w_best[t] * (e[p, kept_best[t], ch] - a_best[t])
                out_k[p, ch] = max(num / max(den, 1e-20), 0.0)
            out_n[p, 0], out_n[p, 1], out_n[p, 2] = bx, by, bz
            out_used[p, :] = False
            for t in range(bkeep):
                out_used[p, kept_best[t]] = True
            out_cost[p] = bcost
            out_rel[p] = brel if bkeep >= 3 else 1.0
            out_it[p] = bit


def model_constants(lights, sigma, n_i, volume_model, table=None):
    """What the compiled solves read of the model under distant lights (m, 3): (lights float64, cos of
    each half-angle to the view, its Fresnel factor, the volume table (`table` when given), σ floored,
    whether there is a lobe)."""
    s = np.ascontiguousarray(lights, np.float64)
    sh = np.sqrt(np.maximum((1 + s[:, 2]) / 2, 1e-12))
    fres = fresnel_dielectric(sh, n_i).astype(np.float64)
    btab = volume_table(lights, sigma, n_i, volume_model=volume_model) if table is None else table
    return s, sh, fres, btab, max(float(sigma), 1e-6), bool(float(sigma) >= 1e-9 and float(n_i) != 1.0)


def chunk_for(n_pix, chunk):
    """Pixels per work item of a threaded loop: `chunk`, fewer when there are not four per thread."""
    return max(1, min(int(chunk), -(-n_pix // (4 * numba.get_num_threads()))))


def refine_distant_compiled(e, lights, normals, sigma, n_i, usable, iterations, extra_start=None,
                            extra_rows=None, cast_ratio=0.25, floor=0.03, max_step=0.15,
                            step_tol=2e-4, table=None, volume_model="approx", chunk=CHUNK, second_above=None):
    """Arrays in as `refine_normals_li` (distant lights (m, 3) only, at most one extra start);
    step_tol : rad, a pixel stops once an accepted step is below it.
    chunk : pixels per work item of the threaded loop (numba prange over chunks, as many threads
        as numba's NUMBA_NUM_THREADS, by default os.cpu_count()); each pixel is solved alone, so
        the result does not depend on it nor on the thread count (tests/fit/test_normals_li.py).
        Fewer pixels than four chunks per thread get smaller chunks: the model choice's solves
        of 125 profile pixels were one chunk, one thread.
    Returns (normals (N, 3) f32, kappa (N, C) f32, used (N, m), cost (N,), rel (N,) f32,
    iterations (N,) int32)."""
    e = np.ascontiguousarray(e, np.float32)
    n_pix, m, c = e.shape
    s = np.ascontiguousarray(lights, np.float64)
    # finiteness is tested in the kernel, pixel by pixel (the (N, m, C) isfinite and the zeroed copy
    # took 0.6 s of the 12 MP scan's full-size step)
    usable = np.ascontiguousarray(np.broadcast_to(np.asarray(usable, bool), (n_pix, m)))
    s, sh, fres, btab, sig, spec = model_constants(lights, sigma, n_i, volume_model, table)
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
    if second_above is None:
        second_above = SECOND_START_ABOVE_MANY if m >= MANY_LIGHTS else SECOND_START_ABOVE
    chunk = chunk_for(n_pix, chunk)
    _refine_all(e, usable, n0, n1, has1, s, sh, fres, btab, SMITH_G1_TABLE, sig, spec, int(iterations), cast_ratio,
                floor, max_step, float(step_tol), float(second_above), out_n, out_k, out_used, out_cost, out_rel,
                out_it, chunk)
    return (out_n.astype(np.float32), out_k.astype(np.float32), out_used, out_cost,
            out_rel.astype(np.float32), out_it)
