"""Compiled gather of `facette.recon._interreflect` (numba, cache=True): for every surface
element, the radiance it receives from every other one it sees, weighted by their form factor.

First call in a fresh environment compiles the kernel (a few seconds); numba caches the machine
code next to this file (__pycache__).
"""
import math

import numpy as np
from numba import njit, prange

from facette.brdf._lobe_jit import beckmann_d, fresnel_dielectric_scalar, smith_g1_beckmann

__all__ = ["gather", "OFF_SURFACE"]

OFF_SURFACE = np.float32(-1e30)     # zgrid's height off the surface: below every segment


@njit(parallel=True, fastmath=True, cache=True)
def gather(rows, cols, z, normals, radiance, zgrid, max_steps, sigma, n_i, tau):
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
    Returns (out, spec); spec is zeros when sigma is 0.
    """
    n, k_out = radiance.shape
    out = np.zeros((n, k_out), np.float32)
    spec = np.zeros((n, k_out), np.float32)
    glossy = sigma > 0 and n_i > 1
    eta = (n_i - 1.0) * (n_i + 1.0)
    through = tau.size >= 2
    for i in prange(n):
        ri, ci, zi = rows[i], cols[i], z[i]
        nxi, nyi, nzi = normals[i, 0], normals[i, 1], normals[i, 2]
        acc = np.zeros(k_out, np.float32)
        acc_s = np.zeros(k_out, np.float32)
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
            g_in = g
            if through:
                g = g * _interp(tau, cos_j / r)
                g_in = g * _interp(tau, cos_i / r)
            for k in range(k_out):
                acc[k] += g_in * radiance[j, k]
            if glossy:
                fs = _lobe(dx, dy, dz, r, nxi, nyi, nzi, sigma, eta)
                if fs > 0:
                    for k in range(k_out):
                        acc_s[k] += fs * g * radiance[j, k]
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
def _lobe(dx, dy, dz, r, nx, ny, nz, sigma, eta):
    """f_s (eq 3.10) for light arriving from direction (dx, dy, dz)/r, seen from +z, at normal n:
    F(w·h) D(h) G1(w) G1(v) / (4 (n·w)(n·v)), Beckmann D and Smith G1 (facette.brdf._lobe_jit)."""
    wx, wy, wz = dx / r, dy / r, dz / r
    hx, hy, hz = wx, wy, wz + 1.0
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn < 1e-9:
        return 0.0
    hx, hy, hz = hx / hn, hy / hn, hz / hn
    ch = nx * hx + ny * hy + nz * hz
    cw = nx * wx + ny * wy + nz * wz
    s2 = sigma * sigma
    if ch <= 0 or cw <= 0 or nz <= 0 or 1.0 - ch * ch > 16.0 * s2 * ch * ch:
        return 0.0
    f = fresnel_dielectric_scalar(wx * hx + wy * hy + wz * hz, eta)     # w·h = v·h
    g = smith_g1_beckmann(cw, sigma) * smith_g1_beckmann(nz, sigma)
    return f * beckmann_d(ch * ch, s2) * g / (4.0 * cw * nz)
