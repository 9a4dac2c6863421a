"""The tabulated volume part of `li_shading_terms` (volume_model="tables") as one compiled loop.

B(n, s) = (n·s) I(θ_s, θ_o, Δφ) for every (pixel, light): the angles from the three dot products
n·s, n·v, s·v, then the table's cosine-weighted trilinear interpolation (`VolumeTable.at_angles`,
the same nodes and weights), in one pass instead of numpy's eight temporary (N, m) arrays and
three arccos passes. The same values as the array form to float32 rounding (tested); it runs in
the model choice's volume tables and every evaluation of the BRDF fits. `transmitted_cosines`: the
quadrature of the node tables behind those tables (facette.brdf._volume).

Loaded only when the tables are evaluated (numba is imported here).
"""
import math

from numba import njit

from ._lobe_jit import fresnel_dielectric_scalar

__all__ = ["volume_terms_tables", "transmitted_cosines"]


@njit(cache=True, nogil=True)
def transmitted_cosines(u, m, eta, out):
    """out (P, K) ← (1 − F(u·m)) (u·m)⁺ for directions u (P, 3) and microfacet normals m (K, 3),
    eta = n_i² − 1: one side of the volume quadrature's integrand (`_quadrature_all_pairs`), in one
    pass where numpy's Fresnel alone took 7 ms of a node table's 20."""
    for a in range(u.shape[0]):
        ux, uy, uz = u[a, 0], u[a, 1], u[a, 2]
        for k in range(m.shape[0]):
            c = ux * m[k, 0] + uy * m[k, 1] + uz * m[k, 2]
            if c <= 0.0:
                out[a, k] = 0.0
            else:
                c = min(c, 1.0)
                out[a, k] = (1.0 - fresnel_dielectric_scalar(c, eta)) * c


@njit(cache=True)
def _cell(th, inv, cosn, x):
    """(i, f, c): the θ cell [th[i], th[i + 1]] of x (clipped to the table), the weight f of its
    upper node and the cosine interpolated with the same weights (`VolumeTable.at_angles`' axis)."""
    nt = th.size
    lo, hi = 0, nt
    while lo < hi:                     # searchsorted(th, x, side="right")
        mid = (lo + hi) // 2
        if th[mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    i = min(max(lo - 1, 0), nt - 2)
    f = min(max((x - th[i]) * inv[i], 0.0), 1.0)
    return i, f, (1.0 - f) * cosn[i] + f * cosn[i + 1]


@njit(cache=True, nogil=True)      # its callers run it on pixel blocks in threads
def volume_terms_tables(cs, co, sv, flat, th, inv, cosn, nph, inv_step, out):
    """out (N, m) float32 ← B = (n·s) I for cs = n·s (N, m), co = n·v (N,), sv = s·v (N, m)
    (a broadcast view is fine); 0 where n·s ≤ 0 or n·v ≤ 0 (or NaN). The table: `flat` its
    cosine-weighted values raveled (n_θ, n_θ, n_φ), `th` its θ nodes (rad), `inv` 1 / cell widths,
    `cosn` cos θ at the nodes (0 at 90°), nph its Δφ nodes every 1 / inv_step rad."""
    n_pix, m = cs.shape
    nt = th.size
    for p in range(n_pix):
        c_o = co[p]
        if not c_o > 0.0:
            out[p, :] = 0.0
            continue
        c_o = min(c_o, 1.0)
        sin_o = math.sqrt(max(1.0 - c_o * c_o, 0.0))
        j, fj, cj = _cell(th, inv, cosn, math.acos(c_o))
        for q in range(m):
            c_s = cs[p, q]
            if not c_s > 0.0:
                out[p, q] = 0.0
                continue
            c_s = min(c_s, 1.0)
            sin_s = math.sqrt(max(1.0 - c_s * c_s, 0.0))
            cphi = 1.0                 # Δφ undefined at the normal: any value works
            if sin_s > 1e-6 and sin_o > 1e-6:
                cphi = min(max((sv[p, q] - c_s * c_o) / (sin_s * sin_o), -1.0), 1.0)
            i, fi, ci = _cell(th, inv, cosn, math.acos(c_s))
            u = min(max(math.acos(cphi) * inv_step, 0.0), nph - 1.0)
            k = min(int(u), nph - 2)
            fk = u - k
            b = (i * nt + j) * nph + k
            v00 = flat[b] * (1.0 - fk) + flat[b + 1] * fk
            v01 = flat[b + nph] * (1.0 - fk) + flat[b + nph + 1] * fk
            b1 = b + nt * nph
            v10 = flat[b1] * (1.0 - fk) + flat[b1 + 1] * fk
            v11 = flat[b1 + nph] * (1.0 - fk) + flat[b1 + nph + 1] * fk
            num = (1.0 - fi) * ((1.0 - fj) * v00 + fj * v01) + fi * ((1.0 - fj) * v10 + fj * v11)
            den = ci * cj
            out[p, q] = c_s * (num / den) if den > 0.0 else 0.0
