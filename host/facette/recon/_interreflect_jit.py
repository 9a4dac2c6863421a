"""Compiled gather of `facette.recon._interreflect` (numba, cache=True): for every surface
element, the radiance it receives from every other one it sees, weighted by their form factor.

First call in a fresh environment compiles the kernel (a few seconds); numba caches the machine
code next to this file (__pycache__).

No fastmath: numba compiles the brdf helpers the lobe calls (facette.brdf._lobe_jit) with the
caller's flags and caches them for every later caller, so with fastmath here Smith's G_1 lost
its last bits for the BRDF fit too, depending on which ran first after an install (a test caught
it). Without it the gather is ~20 % slower (96 × 96 cells, 12 lights: 0.65-0.71 -> 0.79-0.80 s
Lambertian, 1.26-1.31 -> 1.55-1.61 s glossy).
"""
import math

import numpy as np
from numba import njit, prange

from facette.brdf._lobe_jit import li_specular_half

__all__ = ["gather", "specular_towards_camera", "subtract_gathered", "OFF_SURFACE"]

OFF_SURFACE = np.float32(-1e30)     # zgrid's height off the surface: below every segment


@njit(parallel=True, cache=True)
def gather(rows, cols, z, normals, radiance, zgrid, max_steps, lobe_of, sigmas, n_is, taus, lights, lit, spec_scale):
    """out[i, k] = sum_j G_ij radiance[j, k], over the elements j that element i sees.

    rows, cols, z : (N,) float32 element positions (grid units; z up, towards the camera);
    normals : (N, 3) float32 unit normals, camera frame (x right, y up: y = -row);
    radiance : (N, K) float32 radiance leaving each element (the K images and channels);
    zgrid : (H, W) float32 heights of the grid, OFF_SURFACE off the surface (the visibility test;
        a finite floor, not NaN: with fastmath, once used here, a NaN test was compiled away);
    max_steps : samples of the segment i -> j tested against zgrid (at most one per cell).

    G_ij = cos θ_i cos θ_j A_j / r², A_j = 1 / n_z,j the surface area over one cell: the form
    factor of a small element j seen from i, times π (the radiance, not the exitance, is given).
    A segment that passes more than half a cell under the surface is occluded.

    Glossy elements: lobe_of (N,) int32, each element's lobe (an index into sigmas, n_is, taus; −1:
    none, a Lambertian surface); sigmas, n_is (R,) its Beckmann σ and n_i; taus (R, T) float32 its
    diffuse part's transmittance t(μ) on T ≥ 2 even cosines μ ∈ [0, 1] (all ones: a diffuse part
    beside the lobe). For an element with a lobe:
    - as a receiver, spec[i, k] = sum_j f_s(ω_ij, v) G_ij radiance[j, k], the light it reflects
      towards the camera (v = +z) through its lobe (eq 3.10; Fresnel of n_i, Smith's G);
    - its diffuse part takes light in and lets it out by t (eq 3.15's form; facette.brdf._coupled):
      G_ij takes t_i(θ_i) as a receiver and t_j(θ_j) as a source (θ the segment's angle to each
      normal), so a glossy wall sends its diffuse light along the relief, at grazing angles, weaker
      than towards the camera, and its neighbour takes less of it in; spec's source takes t_j alone;
    - as a source, with spec_scale > 0, it also sends for light l its lobe's reflection towards i,
      spec_scale lit[j, l] f_s(s_l, ω_ji) (n_j·s_l), white (the radiance given is then its diffuse
      part alone): a glossy wall mirrors its highlights onto the wall in front of it. spec_scale is
      1 / the reflectance scale (images are f (n·s)); lit (N, m) the share of the element the light
      reaches (0 in a cast shadow).
    lights : (N, m, 3) float32 unit vectors towards the m lights (radiance's K = m C columns are
    light by light, C channels each).
    Returns (out, spec).
    """
    n, k_out = radiance.shape
    out = np.zeros((n, k_out), np.float32)
    spec = np.zeros((n, k_out), np.float32)
    n_l = lights.shape[1]
    n_c = k_out // n_l
    glossy, etas = _lobe_constants(sigmas, n_is)
    for i in prange(n):
        ri, ci, zi = rows[i], cols[i], z[i]
        nxi, nyi, nzi = normals[i, 0], normals[i, 1], normals[i, 2]
        li = lobe_of[i]
        glossy_i = li >= 0 and glossy[li]
        acc = np.zeros(k_out, np.float32)
        acc_s = np.zeros(k_out, np.float32)
        sent = np.zeros(n_l, np.float32)
        for j in range(n):
            if j == i:
                continue
            dx = cols[j] - ci
            dy = ri - rows[j]
            dz = z[j] - zi
            cos_i = nxi * dx + nyi * dy + nzi * dz          # r cos θ_i
            if cos_i <= 0:
                continue
            cos_j = -(normals[j, 0] * dx + normals[j, 1] * dy + normals[j, 2] * dz)
            if cos_j <= 0:
                continue
            steps = min(int(math.sqrt(dx * dx + dy * dy)) + 1, max_steps)
            seen = True
            for t in range(1, steps):
                f = t / steps
                zs = zgrid[int(ri + f * (rows[j] - ri) + 0.5), int(ci + f * dx + 0.5)]
                if zi + f * dz < zs - 0.5:
                    seen = False
                    break
            if not seen:
                continue
            r2 = dx * dx + dy * dy + dz * dz
            g = cos_i * cos_j / (r2 * r2) / max(normals[j, 2], 0.05)
            r = math.sqrt(r2)
            lj = lobe_of[j]
            t_i = _interp(taus, li, cos_i / r) if li >= 0 else 1.0
            g_d = g * _interp(taus, lj, cos_j / r) if lj >= 0 else g     # the source's diffuse part, let out
            fs = _f_s(dx / r, dy / r, dz / r, 0.0, 0.0, 1.0, nxi, nyi, nzi, sigmas[li], etas[li]) if glossy_i else 0.0
            for k in range(k_out):
                acc[k] += g_d * t_i * radiance[j, k]
            if fs > 0:
                for k in range(k_out):
                    acc_s[k] += fs * g_d * radiance[j, k]
            if spec_scale > 0 and lj >= 0 and glossy[lj]:
                nxj, nyj, nzj = normals[j, 0], normals[j, 1], normals[j, 2]
                for l in range(n_l):
                    sx, sy, sz = lights[j, l, 0], lights[j, l, 1], lights[j, l, 2]
                    ns = nxj * sx + nyj * sy + nzj * sz
                    sent[l] = 0.0
                    if ns > 0:      # towards i: o = -d / r
                        sent[l] = spec_scale * lit[j, l] * ns * _f_s(sx, sy, sz, -dx / r, -dy / r, -dz / r,
                                                                     nxj, nyj, nzj, sigmas[lj], etas[lj])
                for l in range(n_l):
                    if sent[l] > 0:
                        for ch in range(n_c):
                            acc[l * n_c + ch] += g * t_i * sent[l]
                            acc_s[l * n_c + ch] += fs * g * sent[l]
        out[i] = acc
        spec[i] = acc_s
    return out, spec


@njit(cache=True)
def _lobe_constants(sigmas, n_is):
    """Per lobe: whether it reflects (σ > 0 and n_i > 1), and its Fresnel eta = n_i² − 1."""
    return (sigmas > 0) & (n_is > 1), (n_is - 1.0) * (n_is + 1.0)


@njit(cache=True)
def _interp(tables, row, mu):
    """tables[row] (T,) on T even cosines of [0, 1], read linearly at mu."""
    t = tables.shape[1]
    x = min(max(mu, 0.0), 1.0) * (t - 1)
    k = min(int(x), t - 2)
    return tables[row, k] + (x - k) * (tables[row, k + 1] - tables[row, k])


@njit(cache=True)
def _f_s(wx, wy, wz, ox, oy, oz, nx, ny, nz, sigma, eta):
    """f_s (eq 3.10, facette.brdf.li_specular) for light from the unit direction w leaving towards
    the unit o at the normal n; 0 below the surface and beyond 4 σ of the lobe (D < 1e-7 of its peak)."""
    cw = nx * wx + ny * wy + nz * wz
    co = nx * ox + ny * oy + nz * oz
    hx, hy, hz = wx + ox, wy + oy, wz + oz
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if cw <= 0 or co <= 0 or hn < 1e-9:
        return 0.0
    ch = (nx * hx + ny * hy + nz * hz) / hn
    if ch <= 0 or 1.0 - ch * ch > 16.0 * sigma * sigma * ch * ch:
        return 0.0
    return li_specular_half(cw, co, ch, (wx * hx + wy * hy + wz * hz) / hn, sigma, eta)


@njit(parallel=True, cache=True)
def specular_towards_camera(normals, lights, lobe_of, sigmas, n_is):
    """(N, m) float32: f_s(s_l, +z) (n·s_l) of each element's lobe (`gather`'s lobe_of, sigmas, n_is;
    0 for an element without one) for each light (lights as `gather`'s), the share of its image
    the lobe holds (before the images' scale)."""
    n, n_l = normals.shape[0], lights.shape[1]
    out = np.zeros((n, n_l), np.float32)
    glossy, etas = _lobe_constants(sigmas, n_is)
    for j in prange(n):
        lj = lobe_of[j]
        if lj < 0 or not glossy[lj]:
            continue
        for l in range(n_l):
            sx, sy, sz = lights[j, l, 0], lights[j, l, 1], lights[j, l, 2]
            ns = normals[j, 0] * sx + normals[j, 1] * sy + normals[j, 2] * sz
            out[j, l] = ns * _f_s(sx, sy, sz, 0.0, 0.0, 1.0, normals[j, 0], normals[j, 1], normals[j, 2],
                                  sigmas[lj], etas[lj])
    return out


@njit(cache=True, nogil=True)
def subtract_gathered(v, g, gl, rows0, rows1, rows_t, cols0, cols1, cols_t, scale, ok, max_fraction, sat, out):
    """One light's image `v` (h, w, c) with its gathered light taken out, into `out`; returns how
    many values the cap limited. The light at a pixel is the cells' `g` (hc, wc, c) interpolated
    bilinearly (taps of `_interp_taps`: rows0/rows1/rows_t, cols0/cols1/cols_t) times `scale`
    (h, w, c: the albedo as a reflectance over π, 0 off the surface), plus the cells' glossy light
    `gl` the same way where `ok` (gl of shape (0, 0, c): none); at most max_fraction × the value.
    A value that is not below `sat` (NaN, inf, clipped) stays as it is. One pass, no temporaries
    (the numpy passes it replaces took ~9 s for 12 lights at 12 MP × 4 channels)."""
    h, w, c = v.shape
    glossy = gl.shape[0] > 0
    capped = 0
    for y in range(h):
        i0, i1, ty = rows0[y], rows1[y], rows_t[y]
        for x in range(w):
            j0, j1, tx = cols0[x], cols1[x], cols_t[x]
            for k in range(c):
                val = v[y, x, k]
                if not val < sat:
                    out[y, x, k] = val
                    continue
                top = g[i0, j0, k] * (1 - tx) + g[i0, j1, k] * tx
                bottom = g[i1, j0, k] * (1 - tx) + g[i1, j1, k] * tx
                ir = (top * (1 - ty) + bottom * ty) * scale[y, x, k]
                if glossy and ok[y, x]:
                    top = gl[i0, j0, k] * (1 - tx) + gl[i0, j1, k] * tx
                    bottom = gl[i1, j0, k] * (1 - tx) + gl[i1, j1, k] * tx
                    ir += top * (1 - ty) + bottom * ty
                limit = max_fraction * val
                if ir > limit:
                    capped += 1
                    ir = max(limit, 0.0)
                out[y, x, k] = val - ir
    return capped
