"""The compiled horizon march of `facette.recon._shadows` (numba)."""
import math

import numba
import numpy as np

__all__ = ["bin_mean_kernel", "hidden_kernel", "horizon_excess_kernel", "upsample_kernel", "without_kernel"]


@numba.njit(cache=True, inline="always")
def _height_at(z, mask, y, x):
    """(inside, the bilinear height at (y, x)); not inside off the image or where a corner is off
    the mask (the march stops there)."""
    h, w = z.shape
    if y < 0.0 or x < 0.0 or y > h - 1.0 or x > w - 1.0:
        return False, z[0, 0]
    r0 = min(int(y), h - 2) if h > 1 else 0
    c0 = min(int(x), w - 2) if w > 1 else 0
    if not (mask[r0, c0] and mask[r0 + 1, c0] and mask[r0, c0 + 1] and mask[r0 + 1, c0 + 1]):
        return False, z[0, 0]
    fy = y - r0
    fx = x - c0
    return True, ((1 - fy) * ((1 - fx) * z[r0, c0] + fx * z[r0, c0 + 1])
                  + fy * ((1 - fx) * z[r0 + 1, c0] + fx * z[r0 + 1, c0 + 1]))


@numba.njit(cache=True, nogil=True, parallel=True)
def horizon_excess_kernel(z, mask, dr, dc, steps, elevation_deg, out):
    """out[r, c] = the horizon's elevation (deg) along (dr, dc) from pixel (r, c) less
    `elevation_deg`; −90 − elevation_deg where nothing rises or off the mask. The heights between
    pixels are bilinear; the march stops where it leaves the image or the mask."""
    h, w = z.shape
    for r in numba.prange(h):
        for c in range(w):
            if not mask[r, c]:
                out[r, c] = -90.0
                continue
            z0 = z[r, c]
            best = -np.inf
            for t in steps:
                inside, zq = _height_at(z, mask, r + t * dr, c + t * dc)
                if not inside:
                    break
                s = (zq - z0) / t
                if s > best:
                    best = s
            out[r, c] = (math.degrees(math.atan(best)) if best > -np.inf else -90.0) - elevation_deg


@numba.njit(cache=True, nogil=True, parallel=True)
def hidden_kernel(z, mask, dr, dc, steps, threshold, z_top, out):
    """out[r, c] = whether the surface rises above the slope `threshold` (tan of the light's
    elevation plus the margin) along (dr, dc) from pixel (r, c): `horizon_excess_kernel`'s test,
    the march stopped as soon as it is decided (a higher point found, or none of the surface, whose
    top is z_top, could rise that steeply from so far)."""
    h, w = z.shape
    for r in numba.prange(h):
        for c in range(w):
            out[r, c] = False
            if not mask[r, c]:
                continue
            z0 = z[r, c]
            for t in steps:
                if z_top - z0 <= threshold * t:
                    break
                inside, zq = _height_at(z, mask, r + t * dr, c + t * dc)
                if not inside:
                    break
                if zq - z0 > threshold * t:
                    out[r, c] = True
                    break


@numba.njit(cache=True, nogil=True, parallel=True)
def bin_mean_kernel(images, f, out):
    """out[k, i, j, c] = the mean of images[k, f i : f i + f, f j : f j + f, c] over its values that
    are not NaN (NaN where all are). images (m, H, W, C) float32, out (m, H // f, W // f, C)."""
    m, hc, wc, nc = out.shape
    for kr in numba.prange(m * hc):
        k, i = kr // hc, kr % hc
        for j in range(wc):
            for c in range(nc):
                s = 0.0
                n = 0
                for r in range(f * i, f * i + f):
                    for q in range(f * j, f * j + f):
                        v = images[k, r, q, c]
                        if not math.isnan(v):
                            s += v
                            n += 1
                out[k, i, j, c] = s / n if n else np.nan


@numba.njit(cache=True, nogil=True, parallel=True)
def without_kernel(images, hidden, fill, out):
    """out = images, `fill` in every channel where hidden: images, out (m, H, W, C) float32, hidden
    (m, H, W) bool. One pass over the stack on every core (a copy then numpy's masked `copyto`
    took 2 CPU s on 12 lights of 3 MP x 4 channels)."""
    m, h, w, nc = images.shape
    for kr in numba.prange(m * h):
        k, r = kr // h, kr % h
        for c in range(w):
            if hidden[k, r, c]:
                for q in range(nc):
                    out[k, r, c, q] = fill
            else:
                for q in range(nc):
                    out[k, r, c, q] = images[k, r, c, q]


@numba.njit(cache=True, nogil=True, parallel=True)
def upsample_kernel(hidden, f, r0, mask, out):
    """out[k, r, c] = hidden[k, (r0 + r) // f, c // f] and mask[r, c], the rows and columns past the
    last whole bin taking the last bin's: hidden (m, hc, wc) bool of f x f bins, mask and out[k]
    (h, W) bool. One pass on every core (numpy's fancy indexing of the 12 lights of 3 MP took 0.35 CPU s)."""
    m, hc, wc = hidden.shape
    h, w = mask.shape
    for kr in numba.prange(m * h):
        k, r = kr // h, kr % h
        i = min((r0 + r) // f, hc - 1)
        for c in range(w):
            out[k, r, c] = hidden[k, i, min(c // f, wc - 1)] and mask[r, c]
