"""The per-pixel colour pass of `facette.recon._rti.fit_ptm_lrgb`, compiled (numba): one pass over
a block of pixels where numpy made ten, each with a temporary (2144x1424, 12 lights: 0.4 CPU s
on one thread). Imported on first use; releases the GIL (the caller runs blocks on two threads)."""
import math

import numpy as np
from numba import njit

__all__ = ["ptm_colour_block", "srgb_lum_block", "srgb_scale_inplace", "srgb_table", "SRGB_STEPS", "linear_table",
           "display_inplace", "display_colour_lum_block", "brightest_above"]


@njit(cache=True, nogil=True, inline="always")
def _chroma(t0, t1, t2, rgb, peak, p):
    """The LRGB colour of a pixel's summed samples (t0, t1, t2): scaled to max channel 1, a negative
    sum taken as 0, all 0 when that maximum is not > 0; stored in rgb[p], the maximum in peak[p].
    Returns (c0, c1, c2, |c|² at least 1e-300: the projection's denominator)."""
    pk = max(max(t0, t1), t2)
    if pk > 0:
        c0, c1, c2 = max(t0, 0.0) / pk, max(t1, 0.0) / pk, max(t2, 0.0) / pk
    else:
        c0 = c1 = c2 = 0.0
    rgb[p, 0], rgb[p, 1], rgb[p, 2] = c0, c1, c2
    peak[p] = pk
    return c0, c1, c2, max(c0 * c0 + c1 * c1 + c2 * c2, 1e-300)


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
        p = start + j
        c0, c1, c2, c_sq = _chroma(t0, t1, t2, rgb, peak, p)
        for li in range(m):
            a, b, c = e[li, j, 0], e[li, j, 1], e[li, j, 2]
            if math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
                lum[li, p] = (a * c0 + b * c1 + c * c2) / c_sq
            else:
                lum[li, p] = np.nan


# sRGB encoding by a table: srgb(i / SRGB_STEPS), interpolated linearly (largest error 2e-5,
# near the curve's knee; a byte is 4e-3), ~10x cheaper than the power on 12 MP x 12 lights
SRGB_STEPS = 4096


def srgb_table():
    """(SRGB_STEPS + 1,) float64: the sRGB encoding (IEC 61966-2-1) of i / SRGB_STEPS."""
    from facette.recon._rti import srgb_encode
    return srgb_encode(np.linspace(0.0, 1.0, SRGB_STEPS + 1))


def linear_table():
    """The identity as a table of `srgb_table`'s size: the kernels' clipping to [0, 1] alone."""
    return np.linspace(0.0, 1.0, SRGB_STEPS + 1)


@njit(cache=True, nogil=True, inline="always")
def _encode(x, lut):
    if not x > 0.0:            # also NaN: callers test finiteness first
        return 0.0
    if x >= 1.0:
        return 1.0
    t = x * (lut.shape[0] - 1)
    i = int(t)
    f = t - i
    return lut[i] + f * (lut[i + 1] - lut[i])


@njit(cache=True, nogil=True)
def srgb_scale_inplace(e, scale, lut):
    """e (any shape, C-contiguous float) <- sRGB(clip(e · scale, 0, 1)) in place; NaN stays NaN."""
    flat = e.reshape(-1)
    for k in range(flat.shape[0]):
        v = flat[k]
        if math.isfinite(v):
            flat[k] = _encode(v * scale, lut)


@njit(cache=True, nogil=True)
def srgb_lum_block(e, rgb, lum, start, scale, lut):
    """For the pixels start .. start + e.shape[1] (e : (m, n, 3) linear values, NaN = unknown;
    rgb (pixels, 3) their display colour): lum (m, pixels), each sample's sRGB encoding of
    e · scale (clipped to [0, 1]) projected on the colour; NaN where a channel is unknown."""
    m, n = e.shape[0], e.shape[1]
    for j in range(n):
        p = start + j
        c0, c1, c2 = rgb[p, 0], rgb[p, 1], rgb[p, 2]
        c_sq = max(c0 * c0 + c1 * c1 + c2 * c2, 1e-30)
        for li in range(m):
            a, b, c = e[li, j, 0], e[li, j, 1], e[li, j, 2]
            if math.isfinite(a) and math.isfinite(b) and math.isfinite(c):
                lum[li, p] = (_encode(a * scale, lut) * c0 + _encode(b * scale, lut) * c1
                              + _encode(c * scale, lut) * c2) / c_sq
            else:
                lum[li, p] = np.nan


@njit(cache=True, nogil=True)
def display_inplace(e, scale, lut):
    """e (any shape, C-contiguous float) <- lut(clip(e · scale, 0, 1)) in place, NaN (a value above
    the top of the range: clipped) -> lut's top: the value a photograph shows, clipping included."""
    flat = e.reshape(-1)
    top = lut[lut.shape[0] - 1]
    for k in range(flat.shape[0]):
        v = flat[k]
        flat[k] = _encode(v * scale, lut) if math.isfinite(v) else top


@njit(cache=True, nogil=True)
def display_colour_lum_block(e, rgb, peak, lum, start, scale, lut):
    """The LRGB split of the displayed values lut(clip(e · scale, 0, 1)) (NaN: clipped, the top) of
    the pixels start .. start + e.shape[1] (e : (m, n, 3)): rgb (pixels, 3) the colour of their sum
    scaled to max channel 1 (0 when that maximum is 0), peak (pixels,) that maximum, lum (m, pixels)
    each displayed sample projected on the colour (least squares: L · rgb is nearest the sample)."""
    m, n = e.shape[0], e.shape[1]
    top = lut[lut.shape[0] - 1]
    d = np.empty((m, 3))
    for j in range(n):
        t0 = t1 = t2 = 0.0
        for li in range(m):
            for c in range(3):
                v = e[li, j, c]
                d[li, c] = _encode(v * scale, lut) if math.isfinite(v) else top
            t0 += d[li, 0]
            t1 += d[li, 1]
            t2 += d[li, 2]
        p = start + j
        c0, c1, c2, c_sq = _chroma(t0, t1, t2, rgb, peak, p)      # displayed sums are >= 0: as they are
        for li in range(m):
            lum[li, p] = (d[li, 0] * c0 + d[li, 1] * c1 + d[li, 2] * c2) / c_sq


@njit(cache=True, nogil=True)
def brightest_above(e, mask, floor, out):
    """The brightest channel of the samples e (m, b, W, 3) of the pixels where mask (b, W): those
    above `floor` (and > 0) written to out[:k]; returns (k, samples looked at, samples with a NaN
    channel). What `np.max(e[:, mask], axis=-1)` and the tests after it give, in one pass without
    the (m, pixels, 3) copy (`pipeline._rti_exposure.HDRWhite`: 1.2 CPU s at 3 MP x 12 lights)."""
    m, b, w = e.shape[0], e.shape[1], e.shape[2]
    k = n = unknown = 0
    for li in range(m):
        for r in range(b):
            for c in range(w):
                if not mask[r, c]:
                    continue
                n += 1
                x, y, z = e[li, r, c, 0], e[li, r, c, 1], e[li, r, c, 2]
                if math.isnan(x) or math.isnan(y) or math.isnan(z):
                    unknown += 1
                    continue
                t = max(max(x, y), z)
                if t > 0 and t > floor:
                    out[k] = t
                    k += 1
    return k, n, unknown
