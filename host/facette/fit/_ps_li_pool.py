"""Neighbouring pixels' values pooled before the BRDF-aware solve, under few lights.

Under 12 lights each pixel's normal rests on 12 values: their noise and quantisation, which 96
lights average down, limit the per-pixel solve (DiLiGenT pot2, brightest value 68 of 255: li_alternating
6.8° under 96 lights, 8.6° under 12, where least squares is 13-16° under both). Each valid pixel's
values are replaced by a weighted mean of its 5 × 5 neighbourhood's (itself included), weighted by

    w = exp(−|p_i − p_j|² / h²) · exp(−r² / 2)     (r: the distance in pixels)

where p is a pixel's **profile**, its values over the lights (summed over the channels) divided by
their norm: a pixel of another orientation, across a cast shadow's edge or a fold has another
profile and little weight; an albedo change alone does not change it (a bilateral filter on the
profiles, as non-local means on patches of one pixel). h is PROFILE_H times the profiles' noise,
read from the data: the lower quartile of the norm of the profile's second difference along the rows (a
curved surface's profiles change linearly from pixel to pixel, so what is left is the noise),
over √1.5. Noise-free values (below NOISE_FLOOR) are left as they are.

Chosen on 12-light renders of a sphere on a plane (96 px, matte / satin / glossy, dark (brightest
68 of 255) and bright, 8- and 16-bit, 0.5 % noise and 0.5 DN read noise: issue 50's note of 2026-12-07); a
Gaussian mean of the images instead (σ 0.6 px) took every render 0.1-1.1° worse (the sphere's rim
and the cast shadow's edge mixed). Only under at most POOL_MAX_LIGHTS lights: under many the solve
averages the noise itself, and the pooled values' small bias (a curved surface's mean profile) is
then not worth it.

**Off by default** (`ps_li_alternating(..., pool=True)` asks for it): confirmed against on DiLiGenT,
12 lights (`facette bench diligent --lights 12`): the renders' 0.61 -> 0.34° became 7.05 -> 7.27° there
(ball 1.68 -> 1.65, buddha 8.59 -> 9.27, cat 5.17 -> 5.06, pot2 8.73 -> 9.39, reading 11.08 -> 10.98):
their errors are not the values' independent noise the renders have, and pooling blurs real detail.
"""
import numpy as np

POOL_MAX_LIGHTS = 16     # more lights than this: no pooling
PROFILE_H = 10.0         # h in units of the profiles' noise (`profiles_noise`)
NOISE_FLOOR = 1e-3       # profiles' noise below this (0.1 % of the norm): no pooling
RADIUS = 2               # the 5 × 5 neighbourhood
ROWS = 256               # output rows per block (memory: the block's values, not the image's)


def profiles_noise(profiles, valid):
    """The profiles' (m, H, W) noise: the lower quartile of the second difference's norm along the rows
    where three consecutive pixels are valid, over √1.5 (0 where none are)."""
    sd = profiles[:, :, 1:-1] - 0.5 * (profiles[:, :, :-2] + profiles[:, :, 2:])
    ok = valid[:, 1:-1] & valid[:, :-2] & valid[:, 2:]
    if not ok.any():
        return 0.0
    # the lower quartile: a curved highlight, a shadow's or an outline's edge raise their pixels'
    # second differences, not the flat quarter's (a noise-free satin sphere of radius 14 px: median
    # 0.002, lower quartile 0); for noise over 12 lights it is ~0.8 x the median
    return float(np.percentile(np.linalg.norm(sd[:, ok], axis=0), 25) / np.sqrt(1.5))


def pool_neighbours(images, mask, saturation=None):
    """(pooled images, info) of (m, H, W, C) images: the module doc's weighted means of the valid
    pixels' values (valid: in `mask`, every value finite and below `saturation`); the images as
    they are (no copy) under more than POOL_MAX_LIGHTS lights or noise-free values."""
    m, h, w, _ = images.shape
    if m > POOL_MAX_LIGHTS:
        return images, None
    tot = images.sum(axis=3)
    valid = np.isfinite(tot).all(axis=0) & (True if mask is None else mask)
    if saturation is not None:
        valid &= ~(images >= saturation).any(axis=(0, 3))
    norm = np.linalg.norm(np.where(valid, tot, 0), axis=0)
    valid &= norm > 0
    prof = np.where(valid, tot, 0) / np.where(valid, norm, 1)
    noise = profiles_noise(prof, valid)
    info = {"profile_noise": round(noise, 5), "pixels": int(valid.sum())}
    if noise < NOISE_FLOOR:
        return images, dict(info, applied=False)
    out = images.copy()
    inv_h2 = 1.0 / (PROFILE_H * noise) ** 2
    for a in range(0, h, ROWS):
        b = min(h, a + ROWS)
        out[:, a:b] = _pooled_rows(images, prof, valid, a, b, inv_h2)
    return out, dict(info, applied=True, h=round(PROFILE_H * noise, 5))


def _pooled_rows(images, prof, valid, a, b, inv_h2):
    """The pooled values of rows a:b (invalid pixels as they were)."""
    h, w = valid.shape
    acc = np.zeros((images.shape[0], b - a, w, images.shape[3]), np.float64)
    wsum = np.zeros((b - a, w))
    ra = max(a - RADIUS, 0)           # the block's rows with their neighbours' (invalid values 0)
    vals = np.where(valid[None, ra:b + RADIUS, :, None], images[:, ra:b + RADIUS], 0)
    for dy in range(-RADIUS, RADIUS + 1):
        lo, hi = max(a + dy, 0), min(b + dy, h)            # source rows
        if lo >= hi:
            continue
        t = slice(lo - dy - a, hi - dy - a)                  # their target rows in the block
        for dx in range(-RADIUS, RADIUS + 1):
            src = slice(max(dx, 0), w + min(dx, 0))
            dst = slice(max(-dx, 0), w - max(dx, 0))
            d2 = ((prof[:, lo:hi, src] - prof[:, lo - dy:hi - dy, dst]) ** 2).sum(0)
            wt = np.exp(-d2 * inv_h2 - 0.5 * (dx * dx + dy * dy)) * valid[lo:hi, src] * valid[lo - dy:hi - dy, dst]
            acc[:, t, dst] += wt[None, ..., None] * vals[:, lo - ra:hi - ra, src]
            wsum[t, dst] += wt
    pooled = (acc / np.maximum(wsum, 1e-30)[None, ..., None]).astype(images.dtype)
    return np.where(valid[None, a:b, :, None], pooled, images[:, a:b])
