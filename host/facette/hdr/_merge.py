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

from dataclasses import dataclass

import numpy as np

from facette._registry import Registry
from facette.camera.sensor import SensorModel

__all__ = ["HDRResult", "merge", "merge_inverse_variance", "merge_debevec1997", "MERGE_METHODS",
           "as_sensor"]


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
    """Validate inputs; returns (stack (n,H,W,C), peaks, k (n,), t (n,), n_ph (C,), sat_signal)."""
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
    if len(shapes[0]) == 2:
        frames = [np.asarray(f)[..., None] for f in frames]
        peaks = None if peaks is None else [np.asarray(p)[..., None] for p in peaks]
    stack = np.stack([np.asarray(f, dtype=np.float32) for f in frames])
    if stack.ndim != 4:
        raise ValueError(f"frames must be (H, W) or (H, W, C) arrays, got {shapes[0]}")
    pk = stack if peaks is None else np.stack([np.asarray(p, dtype=np.float32) for p in peaks])
    if pk.shape != stack.shape:
        raise ValueError(f"peaks shape {pk.shape} differs from frames shape {stack.shape}")
    k = np.asarray(exposures, dtype=np.float64).reshape(-1)
    if k.size != len(frames):
        raise ValueError(f"{k.size} exposures given for {len(frames)} frames: give one exposure "
                         "per frame")
    if not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise ValueError(f"exposures must be finite and > 0, got {k.tolist()}")
    t = np.zeros_like(k) if times_s is None else np.asarray(times_s, dtype=np.float64).reshape(-1)
    if t.size != k.size:
        raise ValueError(f"{t.size} exposure times for {k.size} frames")
    bad = ~np.isfinite(stack)
    if bad.any():
        if invalid == "raise":
            which = sorted(set(np.nonzero(bad)[0].tolist()))
            raise ValueError(f"frame(s) {which} contain {int(bad.sum())} NaN/inf values; fix the "
                             "input or pass invalid='exclude' to treat them as missing samples")
        if invalid != "exclude":
            raise ValueError(f"invalid must be 'raise' or 'exclude', got {invalid!r}")
    c = stack.shape[-1]
    n_ph = np.ones(c) if n_photosites is None else np.asarray(n_photosites, dtype=np.float64)
    if n_ph.size != c:
        n_ph = np.broadcast_to(n_ph.reshape(-1)[:1], (c,)).copy() if n_ph.size == 1 else None
        if n_ph is None:
            raise ValueError(f"n_photosites must have one entry per channel ({c})")
    return stack, pk, bad, k, t, n_ph, saturation_dn


def _variance_dn2(sensor, signal_dn, n_ph):
    """Eq 2.13 for a value averaged over `n_ph` photosites, DN² (float32 for arrays)."""
    g = np.float32(sensor.gain_e_per_dn)
    floor = np.float32((sensor.read_noise_e / sensor.gain_e_per_dn) ** 2 + 1.0 / 12.0)
    n_ph = np.asarray(n_ph, dtype=np.float32)
    return (np.maximum(signal_dn, np.float32(0)) / g + floor) / n_ph


def _masks(sensor, stack, pk, bad, k, t, n_ph, sat_signal, saturation_sigma, black_sigma):
    """Valid-sample mask (n,H,W,C) and saturation-everywhere mask (H,W,C)."""
    sat_thr = sat_signal - saturation_sigma * np.sqrt(_variance_dn2(sensor, sat_signal, 1.0))
    saturated = (pk >= sat_thr) & ~bad
    usable = ~saturated & ~bad
    # float32 throughout the per-pixel work: half the memory traffic of float64.
    dark_dn = (sensor.dark_current_e_per_s * t / sensor.gain_e_per_dn).astype(np.float32)
    dark_dn = dark_dn[:, None, None, None]
    black_thr = dark_dn + black_sigma * np.sqrt(_variance_dn2(sensor, 0.0, n_ph))
    near_black = stack < black_thr
    # Keep near-black samples unless a longer exposure of the pixel is usable.
    order = np.argsort(k)
    longer_usable = np.zeros_like(usable)
    acc = np.zeros(stack.shape[1:], dtype=bool)
    for u in order[::-1]:
        longer_usable[u] = acc
        acc = acc | usable[u]
    valid = usable & ~(near_black & longer_usable)
    all_sat = saturated.all(axis=0)
    return valid, all_sat, dark_dn


def _finish(rad, var, valid, all_sat, k, sat_signal):
    """Apply the documented edge results to a block; returns (rad, var, n_used, all_sat)."""
    none = ~valid.any(axis=0)
    rad = np.where(none, np.nan, rad)
    var = np.where(none | ~np.isfinite(var), np.inf, var)
    # Saturated everywhere: the shortest exposure gives a lower bound.
    rad = np.where(all_sat, sat_signal / k.min(), rad)
    return rad, var, valid.sum(axis=0), all_sat


def _block_inverse_variance(sensor, stack, pk, bad, k, t, n_ph, sat_signal, saturation_sigma,
                            black_sigma, iterations):
    valid, all_sat, dark_dn = _masks(sensor, stack, pk, bad, k, t, n_ph, sat_signal,
                                     saturation_sigma, black_sigma)
    kk = k.astype(np.float32)[:, None, None, None]
    z = np.where(valid, stack - dark_dn, np.float32(0))
    e_u = z / kk
    signal = z  # first pass: the measured signal
    for _ in range(max(1, int(iterations))):
        w = np.where(valid, kk ** 2 / _variance_dn2(sensor, signal + dark_dn, n_ph), np.float32(0))
        den = w.sum(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            est = (w * e_u).sum(axis=0) / den
        # Next pass: each sample's variance predicted from the merged radiance.
        signal = np.where(np.isfinite(est), np.maximum(est, np.float32(0)), np.float32(0))[None] * kk
    with np.errstate(divide="ignore"):
        var = 1.0 / den
    return _finish(est, var, valid, all_sat, k, sat_signal)


def _block_debevec1997(sensor, stack, pk, bad, k, t, n_ph, sat_signal, saturation_sigma,
                       black_sigma):
    valid, all_sat, dark_dn = _masks(sensor, stack, pk, bad, k, t, n_ph, sat_signal,
                                     saturation_sigma, black_sigma)
    kk = k.astype(np.float32)[:, None, None, None]
    z = np.where(valid, stack - dark_dn, np.float32(0))
    hat = np.clip(np.minimum(z, np.float32(sat_signal) - z), 0, None)
    # A valid sample keeps a tiny weight so a pixel black everywhere still gets an estimate.
    w = np.where(valid, np.maximum(hat, np.float32(1e-6)), np.float32(0))
    var_e = np.where(valid, _variance_dn2(sensor, np.where(valid, stack, np.float32(0)), n_ph)
                     / kk ** 2, np.float32(0))
    den = w.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rad = (w * z / kk).sum(axis=0) / den
        var = (w ** 2 * var_e).sum(axis=0) / den ** 2
    return _finish(rad, var, valid, all_sat, k, sat_signal)


def _run_blocks(block_fn, frames, exposures, sensor, times_s, peaks, n_photosites,
                saturation_dn, invalid, method, rows_per_block=64, **kw):
    sensor = as_sensor(sensor)
    stack, pk, bad, k, t, n_ph, sat_file = _prepare(frames, exposures, times_s, peaks,
                                                    n_photosites, invalid, saturation_dn)
    sat_signal = sensor.saturation_dn - sensor.black_level_dn
    if sat_file is not None:
        sat_signal = min(sat_signal, float(sat_file))
    h = stack.shape[1]
    rad = np.empty(stack.shape[1:], np.float32)
    var = np.empty_like(rad)
    n_used = np.empty(stack.shape[1:], np.uint8)
    all_sat = np.empty(stack.shape[1:], bool)
    # Row blocks keep the float64 temporaries small (a 12 MP set would need GBs at once).
    for r0 in range(0, h, rows_per_block):
        sl = slice(r0, min(h, r0 + rows_per_block))
        out = block_fn(sensor, stack[:, sl], pk[:, sl], bad[:, sl], k, t, n_ph, sat_signal, **kw)
        rad[sl], var[sl], n_used[sl], all_sat[sl] = out
    return HDRResult(radiance=rad, variance=var, n_used=n_used, saturated=all_sat, method=method)


def merge_inverse_variance(frames, exposures, sensor=None, *, times_s=None, peaks=None,
                           n_photosites=None, saturation_dn=None, iterations=2,
                           saturation_sigma=3.0, black_sigma=3.0, invalid="raise"):
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

    Returns
    -------
    HDRResult: radiance = Σ_u w_u E_u / Σ_u w_u with E_u = (z_u − dark_u)/k_u and
    w_u = 1/Var(E_u) = k_u² / Var(z_u), Var(z_u) from eq 2.13; variance = 1 / Σ_u w_u.

    Notes
    -----
    Thesis eq 2.14 with ω = 1/Var(E_u), and eq 2.13 for Var.
    """
    return _run_blocks(_block_inverse_variance, frames, exposures, sensor, times_s, peaks,
                       n_photosites, saturation_dn, invalid, "inverse_variance",
                       saturation_sigma=saturation_sigma, black_sigma=black_sigma,
                       iterations=iterations)


def merge_debevec1997(frames, exposures, sensor=None, *, times_s=None, peaks=None,
                      n_photosites=None, saturation_dn=None, saturation_sigma=3.0,
                      black_sigma=3.0, invalid="raise"):
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
                       n_photosites, saturation_dn, invalid, "debevec1997",
                       saturation_sigma=saturation_sigma, black_sigma=black_sigma)


MERGE_METHODS = Registry("HDR merge method")
MERGE_METHODS.add("inverse_variance", merge_inverse_variance)
MERGE_METHODS.add("debevec1997", merge_debevec1997)


def merge(frames, exposures, sensor=None, method="inverse_variance", **kwargs):
    """Merge bracketed frames with the method named `method` (see `MERGE_METHODS`)."""
    return MERGE_METHODS[method](frames, exposures, sensor, **kwargs)
