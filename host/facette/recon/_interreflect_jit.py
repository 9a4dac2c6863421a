"""Compiled gather of `facette.recon._interreflect` (numba, cache=True): for every surface
element, the radiance it receives from every other one it sees, weighted by their form factor.

First call in a fresh environment compiles the kernel (a few seconds); numba caches the machine
code next to this file (__pycache__).
"""
import math

import numpy as np
from numba import njit, prange

__all__ = ["gather"]


@njit(parallel=True, fastmath=True, cache=True)
def gather(rows, cols, z, normals, radiance, zgrid, max_steps, sigma=0.0, n_i=1.0):
    """out[i, k] = sum_j G_ij radiance[j, k], over the elements j that element i sees.

    rows, cols, z : (N,) float32 element positions (grid units; z up, towards the camera);
    normals : (N, 3) float32 unit normals, camera frame (x right, y up: y = -row);
    radiance : (N, K) float32 radiance leaving each element (the K images and channels);
    zgrid : (H, W) float32 heights of the grid, NaN off the surface (the visibility test);
    max_steps : samples of the segment i -> j tested against zgrid (at most one per cell).

    G_ij = cos θ_i cos θ_j A_j / r², A_j = 1 / n_z,j the surface area over one cell: the form
    factor of a small element j seen from i, times π (the radiance, not the exitance, is given).
    A segment that passes more than half a cell under the surface is occluded.
    sigma > 0 (and n_i > 1): also spec[i, k] = sum_j f_s(ω_ij, v) G_ij radiance[j, k], the light
    element i reflects towards the camera (v = +z) through a Beckmann lobe of that σ with the
    Fresnel factor of n_i and Smith's G (eq 3.10): what a glossy receiver adds to its image.
    Returns (out, spec); spec is zeros when sigma is 0.
    """
    n, k_out = radiance.shape
    out = np.zeros((n, k_out), np.float32)
    spec = np.zeros((n, k_out), np.float32)
    glossy = sigma > 0 and n_i > 1
    s2 = max(sigma * sigma, 1e-12)
    eta = (n_i - 1.0) * (n_i + 1.0)
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
                if zs == zs and zi + f * dz < zs - 0.5:
                    seen = False
                    break
            if not seen:
                continue
            r2 = dx * dx + dy * dy + dz * dz
            g = cos_i * cos_j / (r2 * r2) / max(normals[j, 2], 0.05)
            for k in range(k_out):
                acc[k] += g * radiance[j, k]
            if glossy and nzi > 0:
                fs = _lobe(dx, dy, dz, math.sqrt(r2), nxi, nyi, nzi, s2, n_i, eta)
                if fs > 0:
                    for k in range(k_out):
                        acc_s[k] += fs * g * radiance[j, k]
        out[i] = acc
        spec[i] = acc_s
    return out, spec


@njit(fastmath=True, cache=True)
def _lobe(dx, dy, dz, r, nx, ny, nz, s2, n_i, eta):
    """f_s (eq 3.10) for light arriving from direction (dx, dy, dz)/r, seen from +z, at normal n:
    F(w·h) D(h) G1(w) G1(v) / (4 (n·w)(n·v)), Beckmann D and Smith G1 of variance s2 = σ²."""
    wx, wy, wz = dx / r, dy / r, dz / r
    hx, hy, hz = wx, wy, wz + 1.0
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    if hn < 1e-9:
        return 0.0
    hx, hy, hz = hx / hn, hy / hn, hz / hn
    ch = nx * hx + ny * hy + nz * hz
    if ch <= 0:
        return 0.0
    ch2 = ch * ch
    tan2 = (1.0 - ch2) / ch2
    if tan2 > 16.0 * s2:
        return 0.0
    d = math.exp(-tan2 / s2) / (math.pi * s2 * ch2 * ch2)
    cw = nx * wx + ny * wy + nz * wz
    cv = nz
    if cw <= 0 or cv <= 0:
        return 0.0
    c = wx * hx + wy * hy + wz * hz            # w·h = v·h
    gg = math.sqrt(eta + c * c)
    gpc = gg + c
    gmc = eta / gpc
    a = gmc / gpc
    f = 0.5 * a * a * (1.0 + ((c * gpc - 1.0) / (c * gmc + 1.0)) ** 2)
    return f * d * _g1(cw, s2) * _g1(cv, s2) / (4.0 * cw * cv)


@njit(fastmath=True, cache=True)
def _g1(c, s2):
    """Smith G_1 for Beckmann (eq 3.20) at cosine c to the normal."""
    if c >= 1.0:
        return 1.0
    sn = math.sqrt(max(1.0 - c * c, 0.0))
    a = c / (math.sqrt(s2) * sn)
    lam = 0.5 * (math.exp(-a * a) / (a * math.sqrt(math.pi)) - math.erfc(a))
    return 1.0 / (1.0 + lam)
