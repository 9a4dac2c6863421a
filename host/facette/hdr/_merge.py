"""HDR merge of bracketed linear RAW frames (thesis eq 2.14) with per-pixel variance.

Inputs are black-subtracted DN frames (``facette.camera.raw.RawFrame.image``) and
their exposures in any linear unit (µs, or µs·mA when the LED current defines the
exposure); the result is radiance per unit exposure (DN per that unit) and its
variance, from the sensor noise model (eq 2.13).

Methods (dispatched by name through `merge`):

- ``"inverse_variance"`` (`merge_inverse_variance`): weights 1/Var(E_u), the
  minimum-variance unbiased combination for a linear camera; the variances are
  re-evaluated from the merged estimate (Granados et al. 2010) so that noise in a
  sample does not bias its own weight.
- ``"debevec1997"`` (`merge_debevec1997`): Debevec & Malik's hat weight
  w(z) = min(z, z_sat − z) on the raw signal.

Sample exclusion and documented results at the edges (both methods):

- a sample at or near saturation (its peak photosite within `saturation_sigma`
  noise standard deviations of the saturation level) is excluded;
- a near-black sample (signal below `black_sigma` read-noise standard deviations)
  is excluded when a longer exposure of the same pixel is valid; the longest valid
  exposure is always kept, so a pixel black in every frame gets (mostly) the longest
  exposure's estimate (close to 0) with its finite variance; with hat weights,
  positive noise outliers of shorter frames bias black pixels upwards (< 1 σ/µs);
- a pixel saturated in every frame gets the lower bound z_sat / k_min as its
  radiance, variance +inf, and ``saturated = True``;
- NaN or inf samples raise ValueError (``invalid="raise"``, default) or are
  excluded (``invalid="exclude"``); a pixel with no usable sample at all gets
  radiance NaN and variance +inf.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from facette._registry import Registry
from facette._threads import run_blocks
from facette.camera.sensor import SensorModel

__all__ = ["HDRResult", "merge", "merge_inverse_variance", "merge_debevec1997", "MERGE_METHODS",
           "as_sensor", "n_workers"]


@dataclass
class HDRResult:
    """A merged HDR image.

    Attributes
    ----------
    radiance : ndarray (H, W, C) float32
        Linear radiance per unit exposure: black-subtracted DN per exposure unit.
    variance : ndarray (H, W, C) float32
        Variance of `radiance` (same unit squared); +inf where unknown.
    n_used : ndarray (H, W, C) uint8
        Frames that contributed to each value.
    saturated : ndarray (H, W, C) bool
        True where every frame was saturated (radiance is a lower bound).
    method : str
    """

    radiance: np.ndarray
    variance: np.ndarray
    n_used: np.ndarray
    saturated: np.ndarray
    method: str

    @property
    def snr(self):
        """Per-pixel SNR, radiance / sqrt(variance) (0 where the variance is infinite)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(np.isfinite(self.variance) & (self.variance > 0),
                            self.radiance / np.sqrt(self.variance), 0.0)


def as_sensor(sensor):
    """A SensorModel from a SensorModel, a profile `sensor` dict, a Profile, or None (nominal)."""
    if sensor is None:
        return SensorModel()
    if isinstance(sensor, SensorModel):
        return sensor
    if hasattr(sensor, "sensor") and not isinstance(sensor, dict):  # a calib Profile
        return SensorModel.from_profile_dict(sensor.sensor)
    if isinstance(sensor, dict):
        return SensorModel.from_profile_dict(sensor)
    raise TypeError(f"cannot use {type(sensor).__name__} as a sensor model; pass a "
                    "facette.camera.sensor.SensorModel, a profile's sensor dict or a Profile")


def _prepare(frames, exposures, times_s, peaks, n_photosites, invalid, saturation_dn):
    """Validate inputs without copying them.

    Returns (frames, peaks, bad, k (n,), t (n,), n_ph (C,), saturation_dn): frames and
    peaks as lists of n float32 arrays (H, W, C) (peaks[u] is frames[u] when none were
    given), bad the list of frame indices holding NaN/inf (only with invalid="exclude").
    """
    frames = list(frames)
    if len(frames) == 0:
        raise ValueError("no frames to merge: at least one exposure is needed")
    # RawFrame objects carry their own peaks, photosite counts and levels.
    if hasattr(frames[0], "image"):
        if peaks is None:
            peaks = [f.peak for f in frames]
        n_photosites = n_photosites if n_photosites is not None else frames[0].n_photosites
        if saturation_dn is None:
            saturation_dn = min(f.range_dn for f in frames)
        frames = [f.image for f in frames]
    shapes = [np.shape(f) for f in frames]
    if any(s != shapes[0] for s in shapes):
        detail = ", ".join(f"frame {i}: {s}" for i, s in enumerate(shapes))
        raise ValueError(f"frames have different sizes ({detail}); every exposure of a light must "
                         "come from the same camera at the same resolution")
    if len(shapes[0]) not in (2, 3):
        raise ValueError(f"frames must be (H, W) or (H, W, C) arrays, got {shapes[0]}")
    frames = [np.asarray(f, dtype=np.float32) for f in frames]
    if len(shapes[0]) == 2:
        frames = [f[..., None] for f in frames]
    if peaks is None:
        pk = frames
    else:
        pk = [np.asarray(p, dtype=np.float32) for p in peaks]
        pk = [p[..., None] if p.ndim == 2 else p for p in pk]
        if len(pk) != len(frames) or any(p.shape != frames[0].shape for p in pk):
            raise ValueError(f"peaks shape {(len(pk),) + pk[0].shape} differs from frames shape "
                             f"{(len(frames),) + frames[0].shape}")
    k = np.asarray(exposures, dtype=np.float64).reshape(-1)
    if k.size != len(frames):
        raise ValueError(f"{k.size} exposures given for {len(frames)} frames: give one exposure "
                         "per frame")
    if not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise ValueError(f"exposures must be finite and > 0, got {k.tolist()}")
    t = np.zeros_like(k) if times_s is None else np.asarray(times_s, dtype=np.float64).reshape(-1)
    if t.size != k.size:
        raise ValueError(f"{t.size} exposure times for {k.size} frames")
    if invalid not in ("raise", "exclude"):
        raise ValueError(f"invalid must be 'raise' or 'exclude', got {invalid!r}")
    # np.isfinite(x.sum()) is a fast all-finite test (a float32 sum of DN cannot overflow).
    bad = [u for u, f in enumerate(frames) if not np.isfinite(f.sum(dtype=np.float64))]
    if bad and invalid == "raise":
        count = sum(int((~np.isfinite(frames[u])).sum()) for u in bad)
        raise ValueError(f"frame(s) {bad} contain {count} NaN/inf values; fix the "
                         "input or pass invalid='exclude' to treat them as missing samples")
    c = frames[0].shape[-1]
    n_ph = np.ones(c) if n_photosites is None else np.asarray(n_photosites, dtype=np.float64)
    if n_ph.size != c:
        n_ph = np.broadcast_to(n_ph.reshape(-1)[:1], (c,)).copy() if n_ph.size == 1 else None
        if n_ph is None:
            raise ValueError(f"n_photosites must have one entry per channel ({c})")
    return frames, pk, bad, k, t, n_ph, saturation_dn


def _variance_dn2(sensor, signal_dn, n_ph):
    """Eq 2.13 for a value averaged over `n_ph` photosites, DN² (float32 for arrays)."""
    g = np.float32(sensor.gain_e_per_dn)
    floor = np.float32((sensor.read_noise_e / sensor.gain_e_per_dn) ** 2 + 1.0 / 12.0)
    n_ph = np.asarray(n_ph, dtype=np.float32)
    return (np.maximum(signal_dn, np.float32(0)) / g + floor) / n_ph


class _Samples:
    """The per-frame quantities of one row block, visited longest exposure first.

    For each frame u (in order of decreasing exposure) `valid` gives the samples the
    merge uses: not saturated (peak photosite below `sat_thr`), finite, and not near
    black unless no longer exposure of the pixel is usable. Also gathers the
    saturated-everywhere mask. One frame at a time: no (n, rows, W, C) temporaries.
    """

    def __init__(self, sensor, frames, peaks, bad, k, t, n_ph, sat_signal, saturation_sigma,
                 black_sigma, sl):
        self.order = np.argsort(k, kind="stable")[::-1]
        self.k = k.astype(np.float32)
        self.dark = (sensor.dark_current_e_per_s * t / sensor.gain_e_per_dn).astype(np.float32)
        self.z = [frames[u][sl] for u in range(len(frames))]
        sat_thr = np.float32(sat_signal - saturation_sigma
                             * np.sqrt(_variance_dn2(sensor, sat_signal, 1.0)))
        noise0 = black_sigma * np.sqrt(_variance_dn2(sensor, 0.0, n_ph))      # (C,)
        shape = self.z[0].shape
        longer_usable = np.zeros(shape, bool)
        self.all_sat = np.ones(shape, bool)
        self.valid = [None] * len(frames)
        for u in self.order:
            z = self.z[u]
            sat = peaks[u][sl] >= sat_thr
            usable = ~sat
            if u in bad:
                finite = np.isfinite(z)
                usable &= finite
                sat &= finite
                # zero the invalid samples: 0 × NaN would poison the sums
                z = self.z[u] = np.where(finite, z, np.float32(0))
            self.all_sat &= sat
            near_black = z < (self.dark[u] + noise0).astype(np.float32)
            self.valid[u] = usable & ~(near_black & longer_usable)
            longer_usable |= usable

    def any_valid(self):
        out = np.zeros(self.z[0].shape, bool)
        for v in self.valid:
            out |= v
        return out

    def n_used(self):
        out = np.zeros(self.z[0].shape, np.uint8)
        for v in self.valid:
            out += v
        return out


def _finish(rad, var, s, k, sat_signal):
    """Apply the documented edge results to a block; returns (rad, var, n_used, all_sat)."""
    none = ~s.any_valid()
    rad[none] = np.nan
    var[none | ~np.isfinite(var)] = np.inf
    # Saturated everywhere: the shortest exposure gives a lower bound.
    rad[s.all_sat] = np.float32(sat_signal / k.min())
    return rad, var, s.n_used(), s.all_sat


def _block_inverse_variance(sensor, frames, peaks, bad, k, t, n_ph, sat_signal, sl,
                            saturation_sigma, black_sigma, iterations):
    s = _Samples(sensor, frames, peaks, bad, k, t, n_ph, sat_signal, saturation_sigma,
                 black_sigma, sl)
    inv_g = np.float32(1.0 / sensor.gain_e_per_dn)
    floor = np.float32((sensor.read_noise_e / sensor.gain_e_per_dn) ** 2 + 1.0 / 12.0)
    n_ph32 = np.asarray(n_ph, dtype=np.float32)
    zero = np.float32(0)
    shape = s.z[0].shape
    # E_u = (z_u − dark_u) / k_u, and k_u²·n_ph (the numerator of w_u = 1/Var(E_u)).
    e = {u: (s.z[u] - s.dark[u]) / s.k[u] for u in s.order}
    c = {u: s.k[u] * s.k[u] * n_ph32 for u in s.order}
    w, num, den = np.empty(shape, np.float32), np.empty(shape, np.float32), np.empty(shape, np.float32)
    est = None
    for _ in range(max(1, int(iterations))):
        num.fill(0)
        den.fill(0)
        for u in s.order:
            # Eq 2.13 at the sample's expected signal: first the measured value, then
            # the merged radiance times k (Granados et al. 2010: no self-weight bias).
            if est is None:
                np.maximum(s.z[u], zero, out=w)
            else:
                np.multiply(est, s.k[u], out=w)
                w += s.dark[u]
                np.maximum(w, zero, out=w)
            w *= inv_g
            w += floor
            np.divide(c[u], w, out=w)
            w *= s.valid[u]
            den += w
            w *= e[u]
            num += w
        with np.errstate(divide="ignore", invalid="ignore"):
            est = num / den
        est[~np.isfinite(est)] = zero
        np.maximum(est, zero, out=est)
    with np.errstate(divide="ignore", invalid="ignore"):
        rad = num / den
        var = np.float32(1) / den
    return _finish(rad, var, s, k, sat_signal)


def _block_debevec1997(sensor, frames, peaks, bad, k, t, n_ph, sat_signal, sl,
                       saturation_sigma, black_sigma):
    s = _Samples(sensor, frames, peaks, bad, k, t, n_ph, sat_signal, saturation_sigma,
                 black_sigma, sl)
    zero, sat32 = np.float32(0), np.float32(sat_signal)
    num = np.zeros(s.z[0].shape, np.float32)
    den = np.zeros_like(num)
    acc_var = np.zeros_like(num)
    for u in s.order:
        ku, valid = s.k[u], s.valid[u]
        z = s.z[u] - s.dark[u]
        hat = np.clip(np.minimum(z, sat32 - z), 0, None)
        # A valid sample keeps a tiny weight so a pixel black everywhere still gets an estimate.
        w = np.where(valid, np.maximum(hat, np.float32(1e-6)), zero)
        var_e = np.where(valid, _variance_dn2(sensor, np.where(valid, s.z[u], zero), n_ph)
                         / (ku * ku), zero)
        num += w * z / ku
        den += w
        acc_var += w * w * var_e
    with np.errstate(divide="ignore", invalid="ignore"):
        rad = num / den
        var = acc_var / (den * den)
    return _finish(rad, var, s, k, sat_signal)


def _run_blocks(block_fn, frames, exposures, sensor, times_s, peaks, n_photosites,
                saturation_dn, invalid, method, workers=None, rows_per_block=None, **kw):
    sensor = as_sensor(sensor)
    frames, pk, bad, k, t, n_ph, sat_file = _prepare(frames, exposures, times_s, peaks,
                                                     n_photosites, invalid, saturation_dn)
    sat_signal = sensor.saturation_dn - sensor.black_level_dn
    if sat_file is not None:
        sat_signal = min(sat_signal, float(sat_file))
    shape = frames[0].shape
    h = shape[0]
    rad = np.empty(shape, np.float32)
    var = np.empty_like(rad)
    n_used = np.empty(shape, np.uint8)
    all_sat = np.empty(shape, bool)
    # Row blocks of ~2^16 values keep each frame's slice and the accumulators in cache;
    # numpy releases the GIL on whole-block operations, so blocks run on `workers` threads.
    rows = rows_per_block or max(1, (1 << 16) // max(1, shape[1] * shape[2]))
    blocks = [slice(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]

    def one(sl):
        rad[sl], var[sl], n_used[sl], all_sat[sl] = block_fn(sensor, frames, pk, bad, k, t, n_ph,
                                                             sat_signal, sl, **kw)

    run_blocks(one, blocks, n_workers(workers, len(blocks)))
    return HDRResult(radiance=rad, variance=var, n_used=n_used, saturated=all_sat, method=method)


def n_workers(workers, n_tasks):
    """Threads for `n_tasks` independent tasks: `workers`, or one per core (at most 4)."""
    if workers is None:
        workers = min(4, os.cpu_count() or 1)
    if int(workers) < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    return max(1, min(int(workers), n_tasks))


def merge_inverse_variance(frames, exposures, sensor=None, *, times_s=None, peaks=None,
                           n_photosites=None, saturation_dn=None, iterations=2,
                           saturation_sigma=3.0, black_sigma=3.0, invalid="raise", workers=None):
    """Noise-optimal HDR merge: inverse-variance weights from the sensor model.

    Parameters
    ----------
    frames : sequence of n arrays (H, W, C) or (H, W), or of RawFrame
        Black-subtracted linear values, DN.
    exposures : sequence of n floats > 0
        Exposure of each frame (µs, or µs·mA for LED-defined exposure).
    sensor : SensorModel, profile sensor dict, Profile or None (nominal sensor)
    times_s : sequence of n floats or None
        Shutter-open times in seconds, for the dark-current offset (None: no dark subtraction).
    peaks : sequence of n arrays or None
        Largest contributing photosite per value (RawFrame.peak); default the frames.
    n_photosites : sequence of C ints or None
        Photosites averaged per value ((1, 2, 1) for half-size RGGB).
    saturation_dn : float or None
        Black-subtracted saturation level; default from the sensor (and the files).
    iterations : int >= 1
        1: weights from the measured signal; 2+ re-evaluate them from the merged
        estimate (Granados et al. 2010), removing the bias of noisy self-weights.
    saturation_sigma, black_sigma : float
        Exclusion margins, in noise standard deviations (see the module notes).
    invalid : {"raise", "exclude"}
        What to do with NaN/inf samples.
    workers : int or None
        Threads over row blocks (None: one per core, at most 4); the result does not
        depend on it.

    Returns
    -------
    HDRResult: radiance = Σ_u w_u E_u / Σ_u w_u with E_u = (z_u − dark_u)/k_u and
    w_u = 1/Var(E_u) = k_u² / Var(z_u), Var(z_u) from eq 2.13; variance = 1 / Σ_u w_u.

    Notes
    -----
    Thesis eq 2.14 with ω = 1/Var(E_u), and eq 2.13 for Var.
    """
    return _run_blocks(_block_inverse_variance, frames, exposures, sensor, times_s, peaks,
                       n_photosites, saturation_dn, invalid, "inverse_variance", workers=workers,
                       saturation_sigma=saturation_sigma, black_sigma=black_sigma,
                       iterations=iterations)


def merge_debevec1997(frames, exposures, sensor=None, *, times_s=None, peaks=None,
                      n_photosites=None, saturation_dn=None, saturation_sigma=3.0,
                      black_sigma=3.0, invalid="raise", workers=None):
    """HDR merge with Debevec & Malik's (1997) hat weights on the raw signal.

    w(z) = min(z, z_sat − z) for black-subtracted z in [0, z_sat] (linear camera, so
    no response-curve recovery); same inputs, exclusions and result as
    `merge_inverse_variance`. The variance is propagated from the noise model:
    Σ w_u² Var(E_u) / (Σ w_u)².

    Notes
    -----
    Thesis eq 2.14 with ω the hat function [DM97].
    """
    return _run_blocks(_block_debevec1997, frames, exposures, sensor, times_s, peaks,
                       n_photosites, saturation_dn, invalid, "debevec1997", workers=workers,
                       saturation_sigma=saturation_sigma, black_sigma=black_sigma)


MERGE_METHODS = Registry("HDR merge method")
MERGE_METHODS.add("inverse_variance", merge_inverse_variance)
MERGE_METHODS.add("debevec1997", merge_debevec1997)


def merge(frames, exposures, sensor=None, method="inverse_variance", **kwargs):
    """Merge bracketed frames with the method named `method` (see `MERGE_METHODS`)."""
    return MERGE_METHODS[method](frames, exposures, sensor, **kwargs)
