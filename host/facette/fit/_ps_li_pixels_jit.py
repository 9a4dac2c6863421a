"""Compiled per-pixel passes of `facette.fit._ps_li_pixels` (numba, cache=True): the highlight start
of each valid pixel, one loop over its lights instead of five whole-array passes (the Lambertian
prediction, the excess, its argmax, the mean of the usable values and the test). At 2144×1424 × 12
lights the array form took 6.4 s of `Pixels.start`'s 12.3 s over its two calls.

    brightest_excess(values, usable, normals, lights, albedo_pi) -> (has_highlight (N,), brightest (N,))
    channel_and_usable(flat, idx, channel, saturation) -> (values (N, m), usable (N, m))
    any_light_in_lobe(normals, half, cos_min) -> (N,) bool

Arithmetic in float64 where the array form mixes float32 and float64: the two agree but for a pixel
whose excess sits within rounding of the 10 % test (tests/fit/test_ps_li_pixels_jit.py).
"""
import math

import numpy as np
from numba import njit, prange

__all__ = ["brightest_excess", "channel_and_usable", "any_light_in_lobe"]


@njit(cache=True, parallel=True)
def _any_light_in_lobe(normals, half, cos_min, out):
    n_pix, m = half.shape[0], half.shape[1]
    for p in prange(n_pix):
        hit = False
        nx, ny, nz = float(normals[p, 0]), float(normals[p, 1]), float(normals[p, 2])
        for i in range(m):
            ch = nx * half[p, i, 0] + ny * half[p, i, 1] + nz * half[p, i, 2]
            if ch > cos_min:
                hit = True
                break
        out[p] = hit


def any_light_in_lobe(normals, half, cos_min):
    """(N,) bool: some light's half-vector `half` ((m, 3) or (N, m, 3), unit) within the lobe of
    the normals (N, 3), n·h > cos_min, in one pass over the pixels, n·h in float64 (the (N, m)
    product and its comparison took 0.5 s at 2.3 M pixels × 12 lights)."""
    n_pix = len(normals)
    half = np.asarray(half, np.float64)
    if half.ndim == 2:      # one direction per light: the same row for every pixel (no copy)
        half = np.broadcast_to(half, (n_pix,) + half.shape)
    out = np.empty(n_pix, bool)
    _any_light_in_lobe(np.ascontiguousarray(normals, np.float32), half, float(cos_min), out)
    return out


@njit(cache=True, parallel=True)
def _channel_and_usable(flat, idx, channel, saturation, values_out, ok_out):
    m, _, c = flat.shape
    for p in prange(idx.size):
        j = idx[p]
        for i in range(m):
            v = flat[i, j, channel]
            ok = np.isfinite(v) and v < saturation
            for ch in range(c):
                ok = ok and np.isfinite(flat[i, j, ch])
            values_out[p, i] = v
            ok_out[p, i] = ok


def channel_and_usable(flat, idx, channel, saturation):
    """flat : (m, H·W, C) images; idx : (N,) flat pixel indices. Returns ((N, m) float32 the
    values of `channel`, (N, m) bool usable: finite in every channel and, in `channel`, below
    `saturation` (None: no level)), in one pass over the pixels' values. At 2144×1424 × 12 lights
    the array form (a (m, N, C) gather, its isfinite, the transposes) took 2.2 s."""
    n_pix, m = idx.size, flat.shape[0]
    values = np.empty((n_pix, m), np.float32)
    ok = np.empty((n_pix, m), bool)
    # the level in float32, as numpy compares float32 values with a Python float (`recon._ps._usable`)
    _channel_and_usable(flat, np.asarray(idx, np.int64), int(channel),
                        np.float32(np.inf if saturation is None else saturation), values, ok)
    return values, ok


@njit(cache=True, parallel=True)
def _brightest_excess(values, usable, normals, lights, albedo_pi, has_out, brightest_out):
    n_pix, m = values.shape
    for p in prange(n_pix):
        nx, ny, nz = float(normals[p, 0]), float(normals[p, 1]), float(normals[p, 2])
        best = -np.inf
        best_i = 0
        total = 0.0
        count = 0
        for i in range(m):
            lam = (nx * lights[p, i, 0] + ny * lights[p, i, 1] + nz * lights[p, i, 2]) * albedo_pi[p]
            if usable[p, i]:
                excess = values[p, i] - lam
                total += values[p, i]
                count += 1
            else:
                excess = -np.inf - lam
            # np.argmax: the first largest, and a NaN wins (the first NaN)
            if i == 0 or (not math.isnan(best) and (excess > best or math.isnan(excess))):
                best = excess
                best_i = i
        mean = np.float32(total / count) if count else np.float32(0.0)
        has_out[p] = best > np.float32(0.1) * mean
        brightest_out[p] = best_i


def brightest_excess(values, usable, normals, lights, albedo_pi):
    """values, usable : (N, m); normals : (N, 3); lights : (m, 3) or (N, m, 3); albedo_pi : (N,)
    the initial albedo over π. Returns (has_highlight (N,) bool: the light of largest excess over
    the Lambertian prediction exceeds it by ≥ 10 % of the pixel's mean usable value; brightest (N,)
    int64: that light (0 where no light is usable))."""
    n_pix, m = values.shape
    lights = np.asarray(lights)
    if lights.ndim == 2:     # one direction per light: the same row for every pixel (no copy)
        lights = np.broadcast_to(lights, (n_pix, m, 3))
    has = np.empty(n_pix, bool)
    brightest = np.empty(n_pix, np.int64)
    _brightest_excess(values, np.asarray(usable, bool), normals, lights, np.asarray(albedo_pi), has, brightest)
    return has, brightest
