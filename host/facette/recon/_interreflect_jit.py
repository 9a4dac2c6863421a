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
def gather(rows, cols, z, normals, radiance, zgrid, max_steps):
    """out[i, k] = sum_j G_ij radiance[j, k], over the elements j that element i sees.

    rows, cols, z : (N,) float32 element positions (grid units; z up, towards the camera);
    normals : (N, 3) float32 unit normals, camera frame (x right, y up: y = -row);
    radiance : (N, K) float32 radiance leaving each element (the K images and channels);
    zgrid : (H, W) float32 heights of the grid, NaN off the surface (the visibility test);
    max_steps : samples of the segment i -> j tested against zgrid (at most one per cell).

    G_ij = cos θ_i cos θ_j A_j / r², A_j = 1 / n_z,j the surface area over one cell: the form
    factor of a small element j seen from i, times π (the radiance, not the exitance, is given).
    A segment that passes more than half a cell under the surface is occluded.
    """
    n, k_out = radiance.shape
    out = np.zeros((n, k_out), np.float32)
    for i in prange(n):
        ri, ci, zi = rows[i], cols[i], z[i]
        nxi, nyi, nzi = normals[i, 0], normals[i, 1], normals[i, 2]
        acc = np.zeros(k_out, np.float32)
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
        out[i] = acc
    return out
