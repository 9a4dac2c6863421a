"""Per-pixel loops of the capture readers, compiled (numba): one pass over the pixels where numpy
makes one pass per operation and a temporary for each (at 2144x1424 with 12 lights the median
over the lights took 1.5 CPU s as a sort, the usable test 0.1 s per light).

Imported on first use (numba takes ~0.4 s to import); the kernels release the GIL, so that
callers can run them on row blocks on their own threads.
"""
import numpy as np
from numba import njit

from facette._select_jit import median_in_place
from facette._threads import run_blocks

__all__ = ["median_over_lights", "usable_green"]


@njit(cache=True, nogil=True)
def _median_rows(a, out, r0, r1):
    m = a.shape[0]
    buf = np.empty(m, a.dtype)
    for i in range(r0, r1):
        for j in range(a.shape[2]):
            k = 0
            for li in range(m):          # the known values, then a quickselect among them
                v = a[li, i, j]
                if v == v:
                    buf[k] = v
                    k += 1
            out[i, j] = np.nan if k == 0 else median_in_place(buf, k)


def median_over_lights(a, out, rows, workers=1):
    """out[rows] = np.nanmedian(a[:, rows], axis=0), the same float values (the middle of the k
    known values, the mean of the two middle ones for even k, in a's dtype); NaN where no value
    is known. a : (m, H, W) float (any strides); out : (H, W) of a's dtype; rows : a slice;
    workers : threads, each on its share of the rows (the kernel frees the GIL)."""
    r0, r1, _ = rows.indices(a.shape[1])
    parts = workers if r1 - r0 >= 2 * workers else 1
    cuts = np.linspace(r0, r1, parts + 1).astype(int)
    run_blocks(lambda k: _median_rows(a, out, cuts[k], cuts[k + 1]), range(parts), parts)


@njit(cache=True, nogil=True)
def _usable(g, v, min_snr_sq, out):
    for i in range(g.shape[0]):
        for j in range(g.shape[1]):
            x, s = g[i, j], v[i, j]
            # NaN fails every comparison; +inf radiance or variance is not usable
            out[i, j] = (x > 0 and x < np.inf and s < np.inf and s == s
                         and x * x >= min_snr_sq * s)


def usable_green(g, v, min_snr, out):
    """out = finite(g) & finite(v) & (g > 0) & (g² >= min_snr² v), computed in g's dtype as
    numpy computes that expression. g, v : (H, W) float; out : (H, W) bool."""
    _usable(g, v, g.dtype.type(min_snr ** 2), out)
    return out
