"""Which colour channels the normal solve sees: green, the mean of R, G, B, or their noise-weighted sum.

    channel_weights(images, mask, channels="mean", variance=None) -> (weights (3,) or None, note)
    with_solve_channel(images, weights, saturation=None) -> (m, H, W, 4) images, the solve's channel last

Every photometric-stereo method solves its normals on one channel (`channel`) and fits the albedo
(li_alternating: K_d) on every channel. `process` reduces the (m, H, W, 3) stack once, here, to the
channel the normal solve uses, and appends it as a fourth channel (index SOLVE_CHANNEL), so that
each method keeps its albedo per colour (the fourth is dropped from the result).

- "green": the green channel alone (the thesis, eq 4.7; every method's default `channel`).
- "mean": (R + G + B) / 3.
- "weighted": sum_c w_c I_c with w_c proportional to mean_c / var_c (the signal-to-noise weight that
  maximises the SNR of the sum), one weight per channel over the whole object (global, not per
  pixel: a dielectric's lobe is white, sum_c w_c = 1 keeps its amplitude one number over the
  pixels, as li_alternating's fit shares it). var_c is the given variance per channel, else it
  is estimated from the images themselves (`noise_variance`); when that fails the weights are
  the mean's, with a note. `process` always estimates it: the scan's _var.exr files are not read
  for it (the HDR merge held in memory during a scan keeps the green variance only).

A pixel's light is missing (NaN) on the solve's channel when any channel with a weight > 0 is
missing or saturated there: a light saturated in red is not used for a weighted normal.

The default ("mean") was chosen on Mitsuba renders with the camera's noise added (`facette bench
channels`; never on DiLiGenT): see CHANNELS_DEFAULT.
"""
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

__all__ = ["CHANNELS", "CHANNELS_DEFAULT", "SOLVE_CHANNEL", "channel_weights", "images_for_solve", "noise_variance",
           "results_in_rgb", "with_solve_channel"]

CHANNELS = ("green", "mean", "weighted")
# The default, chosen on renders (`facette bench channels`: 9 Mitsuba scenes, textured and coloured
# albedos, the sensor's noise added; mean error over the scenes, 2 seeds): the mean beats green for
# every method and noise level (rank_trimmed 4.84 -> 4.48 deg at 3000 e-, 4.21 -> 4.10 at 20000 e-,
# 4.04 -> 4.00 without added noise; least squares 8.73 -> 8.29, 8.54 -> 8.17, 8.48 -> 8.14;
# li_alternating 1.73 -> 1.63 at 3000 e-), and the weighted sum with its noise estimated from the images
# does not beat the mean (rank_trimmed 4.46 / 4.14 / 4.19, least squares 8.39 / 8.33 / 8.70): with
# the renders' equal channel sensitivities the weights are near (1, 2, 1) / 4, and the estimate goes
# wrong on noise that is not the sensor's (Monte Carlo). "weighted" stays an option for a camera
# whose channels' noise differs.
CHANNELS_DEFAULT = "mean"
SOLVE_CHANNEL = 3            # the reduced channel's index in `with_solve_channel`'s images
_NOISE_SAMPLES = 400_000     # pixel-light values the noise estimate looks at (a subsample beyond)


def _check(images, channels):
    if channels not in CHANNELS:
        raise ValueError(f"channels must be one of {', '.join(CHANNELS)}, got {channels!r}")
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"channel choice needs (m, H, W, 3) images, got shape {images.shape}")


def noise_variance(images, mask=None, max_samples=_NOISE_SAMPLES):
    """(3,) the noise variance of each channel, estimated from the images themselves.

    images : (m, H, W, 3) float; mask : (H, W) bool, the pixels to look at (default all).
    Each image's second differences (the 3x3 kernel [[1,-2,1],[-2,4,-2],[1,-2,1]], whose output
    has 36 times the variance of white noise and cancels smooth shading), robustly: the
    median absolute value over the masked pixels whose 3x3 neighbourhood is in the mask and
    finite, scaled to a standard deviation (Immerkaer 1996, with the median for edges and
    texture). NaN for a channel with no such pixel.
    """
    m, h, w, _ = images.shape
    if mask is None:
        mask = np.ones((h, w), bool)
    inner = mask.copy()
    inner[0, :] = inner[-1, :] = inner[:, 0] = inner[:, -1] = False
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            inner[1:-1, 1:-1] &= mask[1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx]
    ys, xs = np.nonzero(inner)
    if ys.size == 0:
        return np.full(3, np.nan)
    lights = np.arange(m)
    per_light = max(1, max_samples // m)
    if ys.size > per_light:     # a fixed subsample: the same figures on every run
        pick = np.random.default_rng(0).choice(ys.size, per_light, replace=False)
        ys, xs = ys[pick], xs[pick]
    kernel = ((1, -2, 1), (-2, 4, -2), (1, -2, 1))
    out = np.empty(3)
    for c in range(3):
        acc = np.zeros((m, ys.size), np.float64)
        for i, row in enumerate(kernel):
            for j, k in enumerate(row):
                acc += k * images[lights[:, None], ys[None] + i - 1, xs[None] + j - 1, c]
        vals = np.abs(acc[np.isfinite(acc)])
        out[c] = (1.4826 * np.median(vals) / 6.0) ** 2 if vals.size else np.nan
    return out


def channel_weights(images, mask=None, channels=CHANNELS_DEFAULT, variance=None):
    """(weights, note): the solve's channel as a weighted sum of R, G, B.

    images : (m, H, W, 3) float, linear; mask : (H, W) bool, the object (default all).
    channels : one of CHANNELS. variance : (3,) noise variance per channel in the images' unit
        (e.g. the HDR merge's), or None to estimate it (`noise_variance`); "weighted" only.
    Returns weights (3,) float32 summing to 1, or None for "green" (the methods' own channel); and a
    note (str) saying what was done ("" when there is nothing to say).
    """
    images = np.asarray(images)
    _check(images, channels)
    if channels == "green":
        return None, ""
    if channels == "mean":
        return np.full(3, 1 / 3, np.float32), ""
    m, h, w, _ = images.shape
    sel = np.ones((h, w), bool) if mask is None else np.asarray(mask, bool)
    ys, xs = np.nonzero(sel)
    if ys.size > _NOISE_SAMPLES // m:      # a fixed subsample: the same figures on every run
        pick = np.random.default_rng(1).choice(ys.size, _NOISE_SAMPLES // m, replace=False)
        ys, xs = ys[pick], xs[pick]
    vals = images[:, ys, xs].astype(np.float64)              # (m, n, 3)
    mean = np.array([np.mean(v[np.isfinite(v)]) if np.isfinite(v).any() else np.nan
                     for v in (vals[..., c] for c in range(3))])
    how = "given"
    if variance is None:
        variance, how = noise_variance(images, sel), "estimated from the images (second differences)"
    variance = np.asarray(variance, float)
    if variance.shape != (3,):
        raise ValueError(f"variance must be one value per channel, shape (3,), got {variance.shape}")
    snr = mean / variance
    if not (np.all(np.isfinite(snr)) and np.all(snr > 0)):
        return np.full(3, 1 / 3, np.float32), (
            f"channels: weighted asked, but the noise variance per channel ({how}) is not usable "
            f"({', '.join(f'{v:.3g}' for v in variance)}): the mean of R, G, B instead")
    wts = (snr / snr.sum()).astype(np.float32)
    return wts, (f"channels: normals on {wts[0]:.3f} R + {wts[1]:.3f} G + {wts[2]:.3f} B (weights mean/variance, "
                 f"the variance {how})")


def with_solve_channel(images, weights, saturation=None):
    """(m, H, W, 4) float32: R, G, B and the solve's channel sum_c weights_c I_c last (SOLVE_CHANNEL).

    NaN on the solve's channel where any channel with a weight > 0 is not finite or (when
    `saturation` is given) >= saturation: such a light is not used for that pixel's normal.
    """
    from facette.pipeline._pixels_jit import append_weighted     # numba: loaded on first use
    images = np.ascontiguousarray(images, dtype=np.float32)
    m, h, w, c = images.shape
    out = np.empty((m, h, w, c + 1), np.float32)
    with ThreadPoolExecutor(2) as pool:      # the kernel gives the GIL up: lights on two threads
        list(pool.map(lambda k: append_weighted(images, weights, saturation, out, slice(k, k + 1)), range(m)))
    return out


def images_for_solve(images, mask, options, bag, notes):
    """(images the normals are solved on, {"channels": the choice applied, "weights": [w_R, w_G, w_B]}).

    options : `process`'s (its channels, saturation, memory); bag : the
    methods' options (its "channel" set to SOLVE_CHANNEL when one is appended); notes : a list
    the notes are appended to. `images` itself for "green", for images that are not RGB, and with
    --memory (the choice was not measured there: green, with a note); else
    R, G, B with the reduced channel appended (`with_solve_channel`).
    """
    channels = options.channels
    if images.ndim != 4 or images.shape[-1] != 3:
        return images, {"channels": "single", "weights": None}
    green_with = "--memory" if options.memory else None
    if channels != "green" and green_with:
        notes.append(f"channels: {channels} asked; with {green_with} the normals are solved on green")
    if channels == "green" or green_with:
        return images, {"channels": "green", "weights": [0.0, 1.0, 0.0]}
    weights, note = channel_weights(images, mask, channels)
    if note:
        notes.append(note)
    bag["channel"] = SOLVE_CHANNEL
    return (with_solve_channel(images, weights, options.saturation),
            {"channels": channels, "weights": [round(float(x), 4) for x in weights]})


def results_in_rgb(ps, direct, solve_in, images, used):
    """(PSResult, direct images) of a solve on `images_for_solve`'s `solve_in`: the albedo's R, G, B
    only, ps.info["channels"] = `used`; `direct` (the images the method saw, the inter-reflections
    removed) without the appended channel (`images` when it is `solve_in`)."""
    if solve_in is not images:
        ps = replace(ps, albedo=np.ascontiguousarray(ps.albedo[..., :3]), info=dict(ps.info))
        direct = images if direct is solve_in else np.ascontiguousarray(direct[..., :3])
    ps.info["channels"] = used
    return ps, direct
