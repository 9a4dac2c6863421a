"""Compiled gather of `facette.recon._interreflect` (numba, cache=True): for every surface
element, the radiance it receives from every other one it sees, weighted by their form factor.

First call in a fresh environment compiles the kernel (a few seconds); numba caches the machine
code next to this file (__pycache__).
"""
import math

import numpy as np
from numba import njit, prange

from facette.brdf._lobe_jit import li_specular_half

__all__ = ["gather", "specular_towards_camera", "OFF_SURFACE"]

OFF_SURFACE = np.float32(-1e30)     # zgrid's height off the surface: below every segment


@njit(parallel=True, fastmath=True, cache=True)
def gather(rows, cols, z, normals, radiance, zgrid, max_steps, sigma, n_i, tau, lights, lit, spec_scale):
    """out[i, k] = sum_j G_ij radiance[j, k], over the elements j that element i sees.

    rows, cols, z : (N,) float32 element positions (grid units; z up, towards the camera);
    normals : (N, 3) float32 unit normals, camera frame (x right, y up: y = -row);
    radiance : (N, K) float32 radiance leaving each element (the K images and channels);
    zgrid : (H, W) float32 heights of the grid, OFF_SURFACE off the surface (the visibility test;
        not NaN: under fastmath a NaN test may be compiled away, and NaN then hid every segment);
    max_steps : samples of the segment i -> j tested against zgrid (at most one per cell).

    G_ij = cos θ_i cos θ_j A_j / r², A_j = 1 / n_z,j the surface area over one cell: the form
    factor of a small element j seen from i, times π (the radiance, not the exitance, is given).
    A segment that passes more than half a cell under the surface is occluded.
    sigma > 0 (and n_i > 1): also spec[i, k] = sum_j f_s(ω_ij, v) G_ij radiance[j, k], the light
    element i reflects towards the camera (v = +z) through a Beckmann lobe of that σ with the
    Fresnel factor of n_i and Smith's G (eq 3.10): what a glossy receiver adds to its image.
    tau : (K,) float32, the diffuse part's transmittance t(μ) on K ≥ 2 even cosines μ ∈ [0, 1], or
    (0,) for none: with it, G_ij takes t(θ_i) t(θ_j) (θ_i, θ_j the angles of the segment to each
    normal): a substrate under an interface takes light in and lets it out by t (eq 3.15's form;
    facette.brdf._coupled), so a glossy wall sends its diffuse light along the relief, at grazing
    angles, weaker than towards the camera, and its neighbour takes less of it in. spec's source
    radiance takes t(θ_j) alone (the receiver's lobe is on the interface).
    lights : (N, m, 3) float32 unit vectors towards the m lights (radiance's K = m C columns are
    light by light, C channels each); spec_scale > 0 (with sigma): each source j also sends, for
    light l, its lobe's reflection towards i, spec_scale f_s(s_l, ω_ji) (n_j·s_l), white (the
    radiance given is then the sources' diffuse part alone): a glossy wall mirrors its highlights
    onto the wall in front of it. spec_scale is 1 / the reflectance scale (images are f (n·s)).
    Returns (out, spec); spec is zeros when sigma is 0.
    """
    n, k_out = radiance.shape
    out = np.zeros((n, k_out), np.float32)
    spec = np.zeros((n, k_out), np.float32)
    glossy = sigma > 0 and n_i > 1
    eta = (n_i - 1.0) * (n_i + 1.0)
    through = tau.size >= 2
    n_l = lights.shape[1]
    n_c = k_out // n_l
    mirrors = glossy and spec_scale > 0
    for i in prange(n):
        ri, ci, zi = rows[i], cols[i], z[i]
        nxi, nyi, nzi = normals[i, 0], normals[i, 1], normals[i, 2]
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
            t_i = _interp(tau, cos_i / r) if through else 1.0
            g_d = g * _interp(tau, cos_j / r) if through else g     # the source's diffuse part, let out
            fs = _f_s(dx / r, dy / r, dz / r, 0.0, 0.0, 1.0, nxi, nyi, nzi, sigma, eta) if glossy else 0.0
            for k in range(k_out):
                acc[k] += g_d * t_i * radiance[j, k]
            if fs > 0:
                for k in range(k_out):
                    acc_s[k] += fs * g_d * radiance[j, k]
            if mirrors:
                nxj, nyj, nzj = normals[j, 0], normals[j, 1], normals[j, 2]
                for l in range(n_l):
                    sx, sy, sz = lights[j, l, 0], lights[j, l, 1], lights[j, l, 2]
                    ns = nxj * sx + nyj * sy + nzj * sz
                    sent[l] = 0.0
                    if ns > 0:      # towards i: o = -d / r
                        sent[l] = spec_scale * lit[j, l] * ns * _f_s(sx, sy, sz, -dx / r, -dy / r, -dz / r,
                                                                     nxj, nyj, nzj, sigma, eta)
                for l in range(n_l):
                    if sent[l] > 0:
                        for ch in range(n_c):
                            acc[l * n_c + ch] += g * t_i * sent[l]
                            acc_s[l * n_c + ch] += fs * g * sent[l]
        out[i] = acc
        spec[i] = acc_s
    return out, spec


@njit(fastmath=True, cache=True)
def _interp(table, mu):
    """table (K,) on K even cosines of [0, 1], read linearly at mu."""
    x = min(max(mu, 0.0), 1.0) * (table.size - 1)
    k = min(int(x), table.size - 2)
    return table[k] + (x - k) * (table[k + 1] - table[k])


@njit(fastmath=True, cache=True)
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


@njit(parallel=True, fastmath=True, cache=True)
def specular_towards_camera(normals, lights, sigma, n_i):
    """(N, m) float32: f_s(s_l, +z) (n·s_l) of each element's lobe for each light (lights as
    `gather`'s), the share of its image the lobe holds (before the images' scale)."""
    n, n_l = normals.shape[0], lights.shape[1]
    eta = (n_i - 1.0) * (n_i + 1.0)
    out = np.zeros((n, n_l), np.float32)
    if not (sigma > 0 and n_i > 1):
        return out
    for j in prange(n):
        for l in range(n_l):
            sx, sy, sz = lights[j, l, 0], lights[j, l, 1], lights[j, l, 2]
            ns = normals[j, 0] * sx + normals[j, 1] * sy + normals[j, 2] * sz
            out[j, l] = ns * _f_s(sx, sy, sz, 0.0, 0.0, 1.0, normals[j, 0], normals[j, 1], normals[j, 2], sigma, eta)
    return out
