"""The per-pixel colour pass of `facette.recon._rti.fit_ptm_lrgb`, compiled (numba): one pass over
a block of pixels where numpy made ten, each with a temporary (2144x1424, 12 lights: 0.4 CPU s
on one thread). Imported on first use; releases the GIL (the caller runs blocks on two threads)."""
import math

import numpy as np
from numba import njit

__all__ = ["ptm_colour_block"]


@njit(cache=True, nogil=True)
def ptm_colour_block(e, rgb, peak, lum, start):
    """For the pixels start .. start + e.shape[1] (e : (m, n, 3) values, NaN = unknown): rgb
    (pixels, 3), the colour of the summed known samples scaled to max channel 1 (0 when that
    maximum is not > 0); peak (pixels,) that maximum; lum (m, pixels) each sample's projection on
    the colour, NaN where any channel is unknown. Sums in float64, lights in order (as numpy's
    reduction over the first axis)."""
    m, n = e.shape[0], e.shape[1]
    for j in range(n):
        t0 = t1 = t2 = 0.0
        for li in range(m):
            a, b, c = e[li, j, 0], e[li, j, 1], e[li, j, 2]
            if math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
                t0 += a
                t1 += b
                t2 += c
        pk = max(max(t0, t1), t2)
        if pk > 0:
            c0, c1, c2 = max(t0, 0.0) / pk, max(t1, 0.0) / pk, max(t2, 0.0) / pk
        else:
            c0 = c1 = c2 = 0.0
        c_sq = max(c0 * c0 + c1 * c1 + c2 * c2, 1e-300)
        p = start + j
        rgb[p, 0], rgb[p, 1], rgb[p, 2] = c0, c1, c2
        peak[p] = pk
        for li in range(m):
            a, b, c = e[li, j, 0], e[li, j, 1], e[li, j, 2]
            if math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
                lum[li, p] = (a * c0 + b * c1 + c * c2) / c_sq
            else:
                lum[li, p] = np.nan
