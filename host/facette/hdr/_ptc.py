"""Sensor noise model from dark and flat frames: the photon transfer curve (PTC).

For a pair of frames A, B taken with the same setting, the temporal noise is
Var(A − B)/2 (fixed-pattern noise cancels) and the signal is mean((A + B)/2) −
dark. Eq 2.13 predicts, per photosite and in DN,

    σ²(μ) = μ / g + σ0²,    σ0² = read² / g² + 1/12 (+ dark shot noise)

so a straight-line fit of σ² against μ over the unsaturated flats gives the gain g
(1 / slope), and the dark pairs give σ0² and hence the read noise; the mean dark
level against exposure time gives the black level (intercept) and the dark
current (slope · g). Saturation is where the PTC collapses (variance falls while
the mean stops rising). Every CFA colour of every pair is one PTC point (colour
filters change the signal, not the gain).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from facette.camera.raw import read_exposure_metadata, read_raw_mosaic
from facette.camera.sensor import SensorModel

__all__ = ["PTCResult", "estimate_sensor_ptc", "estimate_sensor_ptc_files", "ptc_points"]


@dataclass
class PTCResult:
    """Estimated sensor noise model (eq 2.12–2.13) and the fit's evidence.

    Attributes: gain_e_per_dn, read_noise_e, dark_current_e_per_s, black_level_dn,
    white_level_dn (effective clipping level, DN: the ADC white level or the full
    well, whichever comes first), full_well_e (None if no flat saturated),
    points (ndarray (n, 2): mean signal DN, temporal variance DN²), used (bool (n,)),
    fit_rms_rel (relative RMS residual of the linear PTC fit).
    """

    gain_e_per_dn: float
    read_noise_e: float
    dark_current_e_per_s: float
    black_level_dn: float
    white_level_dn: float
    full_well_e: float | None
    points: np.ndarray = field(repr=False)
    used: np.ndarray = field(repr=False)
    fit_rms_rel: float = 0.0

    def to_profile_dict(self):
        """The calibration profile's `sensor` section (`camera.sensor.SENSOR_KEYS` + full_well_e)."""
        d = {"gain_e_per_dn": float(self.gain_e_per_dn), "read_noise_e": float(self.read_noise_e),
             "dark_current_e_per_s": float(self.dark_current_e_per_s),
             "black_level_dn": int(round(self.black_level_dn)),
             "white_level_dn": int(round(self.white_level_dn))}
        if self.full_well_e is not None:
            d["full_well_e"] = float(self.full_well_e)
        return d

    def sensor_model(self, **overrides):
        """A `SensorModel` with the estimated values."""
        d = self.to_profile_dict()
        d.setdefault("full_well_e", 1e12)  # not observed: the ADC white level clips first
        d.update(overrides)
        return SensorModel.from_profile_dict(d)


def _pair_stats(a, b, colors):
    """Per CFA colour: (mean of (a+b)/2, Var(a−b)/2, max of a and b). a, b raw DN mosaics."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"a PTC pair must have equal shapes, got {a.shape} and {b.shape}")
    out = []
    for c in np.unique(colors):
        m = colors == c
        out.append((0.5 * (a[m].mean() + b[m].mean()), 0.5 * np.var(a[m] - b[m], ddof=1),
                    max(a[m].max(), b[m].max())))
    return out


def _rggb_colors(shape):
    c = np.zeros(shape, dtype=np.int8)
    c[0::2, 1::2] = 1
    c[1::2, 0::2] = 3
    c[1::2, 1::2] = 2
    return c


def ptc_points(flat_pairs, dark_level_dn, colors=None):
    """PTC points (mean signal DN above dark, temporal variance DN², max DN) of flat pairs.

    `flat_pairs`: sequence of (a, b) raw mosaics (DN, black included) taken with the
    same setting; `dark_level_dn` the dark mean at that setting (scalar or per pair).
    """
    pts = []
    dark = np.broadcast_to(np.asarray(dark_level_dn, dtype=np.float64), (len(flat_pairs),))
    for (a, b), d in zip(flat_pairs, dark):
        cols = _rggb_colors(np.shape(a)) if colors is None else colors
        pts += [(m - d, v, mx) for m, v, mx in _pair_stats(a, b, cols)]
    return np.asarray(pts, dtype=np.float64).reshape(-1, 3)


def estimate_sensor_ptc(dark_pairs, flat_pairs, white_level_dn=16383, colors=None):
    """Estimate gain, read noise, dark current, black level and saturation (PTC).

    Parameters
    ----------
    dark_pairs : sequence of (t_s, a, b)
        Pairs of dark frames (lens capped / LEDs off), raw mosaics in DN with the
        black level, at exposure time t_s seconds. At least two distinct times
        for the dark current (with one time, dark current is reported 0).
    flat_pairs : sequence of (t_s, a, b)
        Pairs of frames of a uniform target at increasing exposures, from near
        black to beyond saturation ideally (at least 3 unsaturated levels).
    white_level_dn : float
        The file's white level (ADC maximum).
    colors : ndarray (H, W) of CFA indices or None (RGGB)

    Returns
    -------
    PTCResult

    Notes
    -----
    Thesis eq 2.12–2.13; the pair-difference method is EMVA 1288's.
    """
    if len(dark_pairs) < 1:
        raise ValueError("need at least one pair of dark frames (same exposure time, no light)")
    if len(flat_pairs) < 3:
        raise ValueError(f"need at least 3 flat-field pairs at different exposures for a PTC "
                         f"fit, got {len(flat_pairs)}")
    # Dark level and noise against exposure time.
    dt = np.array([float(t) for t, _, _ in dark_pairs])
    dmean, dvar = [], []
    for t, a, b in dark_pairs:
        a = np.asarray(a, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        dmean.append(0.5 * (a.mean() + b.mean()))
        dvar.append(0.5 * np.var(a - b, ddof=1))
    dmean, dvar = np.array(dmean), np.array(dvar)
    if np.unique(dt).size >= 2:
        slope_dark, black = np.polyfit(dt, dmean, 1)
    else:
        slope_dark, black = 0.0, float(dmean.mean())

    def dark_at(t):
        return black + slope_dark * t

    pts = []
    for t, a, b in flat_pairs:
        cols = _rggb_colors(np.shape(a)) if colors is None else colors
        pts += [(m - dark_at(float(t)), v, mx, m) for m, v, mx in _pair_stats(a, b, cols)]
    pts = np.asarray(pts)
    mu, var, mx, raw_mean = pts[:, 0], pts[:, 1], pts[:, 2], pts[:, 3]
    # Clipping: a point whose brightest photosite reached the highest level seen is suspect.
    # (the plateau is spread by read noise, hence the margin of 6 dark-noise σ).
    clip_level = mx.max()
    used = (mu > 0) & (mx < clip_level - max(6.0 * np.sqrt(dvar.min()), 1.0))
    if used.sum() < 3:
        used = (mu > 0) & (mu + dark_at(0) < 0.8 * clip_level)
    if used.sum() < 3:
        raise ValueError("fewer than 3 unsaturated flat levels: add shorter flat exposures so the "
                         "PTC has a linear part to fit")
    # Fit σ² = μ/g + c, weighting by 1/σ² (variance of a sample variance ∝ σ⁴).
    for _ in range(2):
        wts = 1.0 / np.maximum(var[used], 1e-9)
        slope, icpt = np.polyfit(mu[used], var[used], 1, w=wts)
        pred = slope * mu + icpt
        # Drop points that fell off the line (onset of saturation, non-linearity).
        keep = used & (np.abs(var - pred) < 0.15 * pred)
        if keep.sum() >= 3:
            used = keep
    slope, icpt = np.polyfit(mu[used], var[used], 1, w=1.0 / np.maximum(var[used], 1e-9))
    if not slope > 0:
        raise ValueError("the photon transfer curve does not rise with signal (slope "
                         f"{slope:.3g}); check that the flats are lit and not all saturated")
    g = 1.0 / slope
    pred = slope * mu[used] + icpt
    fit_rms = float(np.sqrt(np.mean(((var[used] - pred) / pred) ** 2)))
    # Read noise from the shortest dark pair: σ0² = read²/g² + 1/12 + dark shot (D t / g).
    i0 = int(np.argmin(dt))
    dark_e = max(slope_dark * g, 0.0)
    sigma0_sq = dvar[i0] - 1.0 / 12.0 - dark_e * dt[i0] / g ** 2
    read = float(np.sqrt(max(sigma0_sq, 0.0)) * g)
    # Saturation: points whose variance collapsed below half the linear prediction.
    collapsed = (mu > 0) & (var < 0.5 * (slope * mu + icpt))
    full_well, white = None, float(white_level_dn)
    if collapsed.any():
        # The plateau (fully clipped pairs); the well holds dark electrons too.
        plateau = float(np.max(raw_mean[collapsed]))
        # Below the ADC white level, the plateau is the full well.
        if plateau < white_level_dn - 5:
            white = plateau
            full_well = float((plateau - black) * g)
    return PTCResult(gain_e_per_dn=float(g), read_noise_e=read, dark_current_e_per_s=float(dark_e),
                     black_level_dn=float(black), white_level_dn=white, full_well_e=full_well,
                     points=pts[:, :2], used=used, fit_rms_rel=fit_rms)


def estimate_sensor_ptc_files(dark_files, flat_files, **kwargs):
    """`estimate_sensor_ptc` from RAW files: consecutive files with the same exposure
    time (read from the files) form a pair; a lone file is ignored.

    dark_files, flat_files : sequences of paths, in capture order.
    """
    def pairs(files, what):
        out, pending = [], None
        white = None
        for p in files:
            mosaic, colors, black, white_p = read_raw_mosaic(p)
            t, _, _ = read_exposure_metadata(p)
            if t is None:
                raise ValueError(f"{p} records no exposure time; the PTC needs it for {what}")
            white = white_p
            if pending is not None and abs(pending[0] - t) <= 1e-9 * max(t, 1.0):
                out.append((t, pending[1], mosaic))
                pending = None
            else:
                pending = (t, mosaic, colors)
        return out, white

    darks, _ = pairs(dark_files, "dark frames")
    flats, white = pairs(flat_files, "flat frames")
    kwargs.setdefault("white_level_dn", white)
    return estimate_sensor_ptc(darks, flats, **kwargs)
