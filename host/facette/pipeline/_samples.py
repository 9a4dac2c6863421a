"""The reflectance samples of `process` (eq 4.11): pixel block by pixel block into the
hemisphere sensor, with a uniform subset of the raw samples kept beside it; a band's sensor
(`samples_sensor`) merges into the whole image's (`process --memory`)."""
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from facette.reflect import HemisphereSensor, ReflectanceSamples, sample_grid

__all__ = ["RAW_SAMPLES_KEPT", "samples_sensor"]

RAW_SAMPLES_KEPT = 200_000   # raw samples stored next to the filtered ones (a uniform subset)


def _samples_stage(images, mask, ps, light_dirs, theta0_deg, chunk=131072, keep=RAW_SAMPLES_KEPT,
                   seed=0, workers=2):
    """Samples (eq 4.11) pixel block by pixel block into the hemisphere sensor, keeping a
    uniform random subset of the raw samples. Shadows found by the PS stage are left out.
    Blocks run on `workers` threads (numpy releases the GIL), each with its own sensor.
    Returns (FilteredReflectance, raw ReflectanceSamples)."""
    sensor, raw = samples_sensor(images, mask, ps, light_dirs, theta0_deg, chunk, keep, seed, workers)
    return sensor.result(), raw


def samples_sensor(images, mask, ps, light_dirs, theta0_deg, chunk=131072, keep=RAW_SAMPLES_KEPT,
                   seed=0, workers=2, total=None, first_pixel=0):
    """`_samples_stage` before the sensor's result: (HemisphereSensor, raw samples), so that the
    sensors of row bands merge into the whole image's. total: the samples the raw subset's
    share is drawn against (default this image's: m x its valid pixels); first_pixel: added to
    the raw samples' pixel indices (a band's first pixel in the whole image)."""
    m, h, w, c = images.shape
    pix = np.flatnonzero((ps.valid & mask).ravel())
    flat = images.reshape(m, h * w, c)
    # each pixel's c floats as one opaque item: gathering pixels is then ~4x faster
    flat = np.ascontiguousarray(flat)
    items = flat.view(np.dtype((np.void, flat.itemsize * c))).reshape(m, h * w)
    total = max(pix.size * m if total is None else total, 1)
    shadow = ps.shadow.reshape(-1, m)
    normals = ps.normal.reshape(-1, 3)
    finite = bool(np.isfinite(images).all())          # one pass instead of one per block

    def block(a):
        sensor = HemisphereSensor(theta0_deg, channels=c)
        rng = np.random.default_rng([seed, a])
        p = pix[a:a + chunk]
        s = light_dirs if light_dirs.ndim == 2 else light_dirs.reshape(h * w, m, 3)[p]
        e = np.take(items, p, axis=1).view(flat.dtype).reshape(m, -1, c)
        g = sample_grid(e, normals[p], s, shadow[p].T, check_finite=not finite)
        sensor.add_grid(g["cos_s"], g["o_x"], g["o_y"], g["cos_o"], e, g["keep"], g["scale"])
        # a uniform subset of the kept samples: draw grid positions, keep the kept ones
        size = g["keep"].size
        draw = rng.integers(0, size, int(np.ceil(size * min(1.0, keep / total))))
        draw = np.unique(draw[g["keep"].ravel()[draw]])
        li, pi_ = np.unravel_index(draw, g["keep"].shape)
        cs = g["cos_s"][li, pi_]
        s_t = np.stack([np.sqrt(np.maximum(1 - cs ** 2, 0)), np.zeros_like(cs), cs], axis=1)
        o_t = np.stack([g["o_x"][li, pi_], g["o_y"][li, pi_], g["cos_o"][pi_]], axis=1)
        f_t = e[li, pi_] * g["scale"][li, pi_][:, None]
        return sensor, ReflectanceSamples(s_t.astype(np.float32), o_t.astype(np.float32),
                                          f_t.astype(np.float32), p[pi_], li.astype(np.int16))

    starts = range(0, pix.size, chunk)
    if workers > 1 and len(starts) > 1:
        with ThreadPoolExecutor(workers) as pool:
            done = list(pool.map(block, starts))
    else:
        done = [block(a) for a in starts]
    total_sensor = HemisphereSensor(theta0_deg, channels=c)
    for sensor, _ in done:
        total_sensor.merge(sensor)
    parts = [smp for _, smp in done]
    if not parts:
        parts.append(ReflectanceSamples(*(np.zeros((0, 3), np.float32),) * 3,
                                        np.zeros(0, np.int64), np.zeros(0, np.int16)))
    raw = parts[0] if len(parts) == 1 else ReflectanceSamples(
        *(np.concatenate([getattr(q, k) for q in parts]) for k in ("s", "o", "f", "pixel", "light")))
    if first_pixel:
        raw.pixel = raw.pixel + first_pixel
    return total_sensor, raw
