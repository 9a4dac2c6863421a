"""A plain-Python reference of the compiled per-pixel solve (facette.fit._normals_li_jit), written
as it was before the kept lights were packed to the front: every light is evaluated at every step
and a light left out weighs 0. The compiled kernel must give the same numbers bit for bit (its
sums skip only exact zeros). The per-step arithmetic on those sums (`_tangent_frame`, `_damped_step`)
is the kernel's own: what this checks is the sums over every light. Slow: a few dozen pixels at most.

    refine_reference(e, ok, n0, n1, has1, s, sh, fres, btab, sigma, spec, iterations, cast_ratio,
                     floor, max_step, step_tol, second_above)
        -> (normals (N, 3), kappa (N, C), used (N, m), cost (N,), rel (N,), iterations (N,))
"""
import math

import numpy as np

from facette.brdf._lobe_jit import SMITH_G1_TABLE, smith_g1_dlog_scaled, smith_g1_dlog_tabulated
from facette.fit._normals_li_jit import _damped_step, _log_product, _tangent_frame


def _model(n, s, sh, fres, btab, sigma, spec):
    nx, ny, nz = n
    m = len(s)
    g = len(btab)
    inv = 1.0 / max(1.0 + nz, 1e-6)           # the table's stereographic coordinates
    fx = min(max((nx * inv + 1.0) * 0.5 * (g - 1), 0.0), g - 1.000001)
    fy = min(max((ny * inv + 1.0) * 0.5 * (g - 1), 0.0), g - 1.000001)
    ix, iy = int(fx), int(fy)
    wx, wy = fx - ix, fy - iy
    co = min(max(nz, 0.0), 1.0)
    g1o, dg1o = smith_g1_dlog_tabulated(co, sigma, SMITH_G1_TABLE) if spec else (0.0, 0.0)
    qo = dg1o - 1.0 / co if co > 0.0 else 0.0
    s2 = sigma * sigma
    inv_s2, inv_sigma, d_norm = 1.0 / s2, 1.0 / sigma, 1.0 / (math.pi * s2)
    inv_4co = 1.0 / (4.0 * co) if co > 0.0 else 0.0
    a, b, pa, qa = [0.0] * m, [0.0] * m, [0.0] * m, [0.0] * m
    for i in range(m):
        cs = nx * s[i][0] + ny * s[i][1] + nz * s[i][2]
        if cs <= 0.0 or nz <= 0.0:
            continue
        b[i] = ((1 - wx) * (1 - wy) * btab[iy][ix][i] + wx * (1 - wy) * btab[iy][ix + 1][i]
                + (1 - wx) * wy * btab[iy + 1][ix][i] + wx * wy * btab[iy + 1][ix + 1][i])
        if spec:
            half_sh = 0.5 / sh[i]
            ch = min(max((cs + co) * half_sh, 0.0), 1.0)
            ch2 = ch * ch
            if 1.0 - ch2 < 16.0 * s2 * ch2 and ch2 > 0.0:
                g1s, dg1s = smith_g1_dlog_scaled(min(cs, 1.0), inv_sigma, SMITH_G1_TABLE)
                ich = 1.0 / ch
                ich2 = ich * ich
                av = fres[i] * (math.exp(-(1.0 - ch2) * ich2 * inv_s2) * d_norm * ich2 * ich2) * g1s * g1o * inv_4co
                a[i] = av
                dd = (2.0 * inv_s2 * ich2 * ich - 4.0 * ich) * half_sh
                pa[i] = av * (dd + dg1s)
                qa[i] = av * (dd + qo)
    return a, b, pa, qa


def _kappa(e, a, b, w):
    num = den = 0.0
    for i in range(len(e)):
        wb = w[i] * b[i]
        num += wb * (e[i] - a[i])
        den += wb * b[i]
    return max(num / max(den, 1e-20), 0.0)


def _resid(e, a, b, k, keep):
    return [(e[i] - a[i] - b[i] * k) if keep[i] else 0.0 for i in range(len(e))]


def _scale(r, keep, mean_e, floor):
    kept = [abs(r[i]) for i in range(len(r)) if keep[i]]
    med = float(np.median(kept)) if kept else 0.0
    return max(max(1.4826 * med, floor * mean_e), 1e-12)


def _cost(r, keep, sc):
    tot, prod, inv_sc = 0.0, 1.0, 1.0 / sc
    for i in range(len(r)):
        if keep[i]:
            q = r[i] * inv_sc
            prod, tot = _log_product(prod * (1.0 + q * q), tot)
    return tot + math.log(prod)


def _total(values):
    # a plain running sum, as the kernel's loops (Python 3.12's sum() compensates)
    tot = 0.0
    for v in values:
        tot += v
    return tot


def _solve_one(e, ok, n0, s, sh, fres, btab, sigma, spec, iterations, scale_in, cast_ratio, floor, max_step,
               step_tol):
    m = len(e)
    nl = math.sqrt(n0[0] ** 2 + n0[1] ** 2 + n0[2] ** 2)
    n = (n0[0] / nl, n0[1] / nl, n0[2] / nl) if nl > 1e-12 else (0.0, 0.0, 1.0)
    a, b, pa, qa = _model(n, s, sh, fres, btab, sigma, spec)
    k = _kappa(e, a, b, [1.0 if ok[i] else 0.0 for i in range(m)])
    pmax = 0.0
    for i in range(m):
        pmax = max(pmax, a[i] + b[i] * k)
    keep = [bool(ok[i]) and not (e[i] < cast_ratio * (a[i] + b[i] * k) and a[i] + b[i] * k > 0.05 * pmax)
            for i in range(m)]
    nkeep = sum(keep)
    mean_e = _total(e[i] for i in range(m) if keep[i]) / max(nkeep, 1)
    k = _kappa(e, a, b, [1.0 if x else 0.0 for x in keep])
    r = _resid(e, a, b, k, keep)
    if nkeep < 3:
        return n, 0.0, 1.0, 1.0, keep, 0, k, a, b
    rescale = scale_in <= 0.0
    for _ in range(3):
        sc = _scale(r, keep, mean_e, floor) if rescale else scale_in
        wr = [(1.0 if keep[i] else 0.0) / (1.0 + (r[i] / sc) * (r[i] / sc)) for i in range(m)]
        k = _kappa(e, a, b, wr)
        r = _resid(e, a, b, k, keep)
    scale = _scale(r, keep, mean_e, floor) if rescale else scale_in
    cost = _cost(r, keep, scale)
    lam, it = 1e-2, 0
    nx, ny, nz = n
    for it in range(1, iterations + 1):
        if rescale and it in (3, 6):
            r = _resid(e, a, b, k, keep)
            scale = _scale(r, keep, mean_e, floor)
            cost = _cost(r, keep, scale)
            lam = max(lam, 1e-2)
        t1x, t1y, t1z, t2x, t2y, t2z = _tangent_frame(nx, ny, nz)
        r = _resid(e, a, b, k, keep)
        inv = 1.0 / scale
        wr = [(1.0 if keep[i] else 0.0) / (1.0 + (r[i] * inv) * (r[i] * inv)) for i in range(m)]
        jac = []
        for tx, ty, tz in ((t1x, t1y, t1z), (t2x, t2y, t2z)):
            col = []
            for i in range(m):
                cs = nx * s[i][0] + ny * s[i][1] + nz * s[i][2]
                bo = b[i] / max(cs, 1e-4) if cs > 1e-4 else 0.0
                st = tx * s[i][0] + ty * s[i][1] + tz * s[i][2]
                col.append((pa[i] * st + qa[i] * tz) + bo * st * k)
            jac.append(col)
        ju, jv = jac
        huu = hvv = huv = gu = gv = 0.0
        sbb = sbu = sbv = sbr = 0.0
        for i in range(m):
            w = wr[i]
            huu += w * ju[i] * ju[i]
            hvv += w * jv[i] * jv[i]
            huv += w * ju[i] * jv[i]
            gu += w * ju[i] * r[i]
            gv += w * jv[i] * r[i]
            wb = w * b[i]
            sbb += wb * b[i]
            sbu += wb * ju[i]
            sbv += wb * jv[i]
            sbr += wb * r[i]
        du, dv = _damped_step(huu, hvv, huv, gu, gv, sbb, sbu, sbv, sbr, k, lam)
        step = math.sqrt(du * du + dv * dv)
        shrink = min(1.0, max_step / max(step, 1e-12))
        cx = nx + du * shrink * t1x + dv * shrink * t2x
        cy = ny + du * shrink * t1y + dv * shrink * t2y
        cz = nz + du * shrink * t1z + dv * shrink * t2z
        cl = math.sqrt(cx * cx + cy * cy + cz * cz)
        cx, cy, cz = (cx / cl, cy / cl, cz / cl) if cl > 1e-12 else (0.0, 0.0, 1.0)
        ac, bc, pc, qc = _model((cx, cy, cz), s, sh, fres, btab, sigma, spec)
        kc = _kappa(e, ac, bc, wr)
        cc = _cost(_resid(e, ac, bc, kc, keep), keep, scale)
        if cc <= cost:
            nx, ny, nz, cost = cx, cy, cz, cc
            a, b, pa, qa, k = ac, bc, pc, qc, kc
            lam = max(lam / 3, 1e-4)
            if step * shrink < step_tol:
                break
        else:
            lam *= 10
            if lam > 1e3:
                break
    r = _resid(e, a, b, k, keep)
    num = _total(r[i] * r[i] for i in range(m) if keep[i])
    den = _total(e[i] * e[i] for i in range(m) if keep[i])
    rel = math.sqrt(num) / math.sqrt(den) if den > 0 else 0.0
    return (nx, ny, nz), cost, scale, rel, keep, it, k, a, b


def refine_reference(e, ok, n0, n1, has1, s, sh, fres, btab, sigma, spec, iterations, cast_ratio, floor,
                     max_step, step_tol, second_above):
    """The arguments of `_refine_all` (without its output arrays and chunk); its outputs returned."""
    n_pix, m, c = e.shape
    # Python floats throughout, as the kernel computes in float64 (float32 inputs widened exactly)
    s, sh, fres, btab = s.tolist(), sh.tolist(), fres.tolist(), btab.astype(np.float64).tolist()
    out = (np.empty((n_pix, 3)), np.empty((n_pix, c)), np.empty((n_pix, m), bool), np.empty(n_pix),
           np.empty(n_pix), np.empty(n_pix, np.int32))
    for p in range(n_pix):
        ep = e[p].astype(np.float64).tolist()
        em = [_total(ep[i][ch] for ch in range(c)) / c for i in range(m)]
        args = (s, sh, fres, btab, sigma, spec, iterations)
        rest = (cast_ratio, floor, max_step, step_tol)
        best = _solve_one(em, ok[p], n0[p].tolist(), *args, -1.0, *rest)
        nrm, cost, scale, rel, keep, it, k_mean, a, b = best
        if has1[p] and sum(keep) >= 3 and rel >= second_above:
            other = _solve_one(em, ok[p], n1[p].tolist(), *args, scale, *rest)
            if other[1] < cost:
                nrm, cost, _, rel, keep, it2, k_mean, a, b = other
                it = max(it, it2)
        for ch in range(c):
            num = den = 0.0
            for i in range(m):
                if keep[i]:
                    rr = (em[i] - a[i] - b[i] * k_mean) / scale
                    wgt = b[i] / (1.0 + rr * rr)
                    num += wgt * (ep[i][ch] - a[i])
                    den += wgt * b[i]
            out[1][p, ch] = max(num / max(den, 1e-20), 0.0)
        out[0][p] = nrm
        out[2][p] = keep
        out[3][p] = cost
        out[4][p] = rel if sum(keep) >= 3 else 1.0
        out[5][p] = it
    return out
