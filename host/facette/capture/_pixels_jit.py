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

__all__ = ["median_over_lights", "usable_green", "radiance_and_usable", "radiance_tables"]


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


@njit(cache=True, nogil=True)
def _looked_up(raw, table, usable_table, out, usable):
    for r in range(raw.shape[0]):
        for c in range(raw.shape[1]):
            for q in range(3):
                out[r, c, q] = table[q, raw[r, c, q]]
            usable[r, c] = usable_table[raw[r, c, 1]]


def radiance_tables(dtype, intensity, levels, min_levels):
    """(table (3, values) float32, usable_table (values,) bool) of every stored value of `dtype` (uint8 or
    uint16) under a light of R G B `intensity`: io.diligent.png_radiance's value (numpy's division in its
    dtype, rounded to float32; NaN at the top of the range) and usable.usable_from_levels of the green one
    times `levels` (a numpy scalar, its dtype the product's as there)."""
    scale = 65535.0 if np.dtype(dtype) == np.uint16 else 255.0
    stored = np.arange(int(scale) + 1, dtype=dtype)
    divisor = scale * np.asarray(intensity)          # png_radiance's, in its dtype
    table = np.empty((3, stored.size), np.float32)
    for q in range(3):
        table[q] = stored / divisor[q]
    table[:, -1] = np.nan                            # the top of the range: clipped
    with np.errstate(invalid="ignore"):
        return table, table[1] * levels >= min_levels


def radiance_and_usable(raw, tables, out, usable):
    """png_radiance's `out` (R, W, 3) float32 and usable_from_levels' `usable` (R, W) of raw (R, W, 3)
    stored integers, looked up in `radiance_tables` (the same values; a 3000 x 144 band of 20 lights:
    numpy 0.115 CPU s, this 0.023), the GIL given up."""
    _looked_up(raw, tables[0], tables[1], out, usable)
