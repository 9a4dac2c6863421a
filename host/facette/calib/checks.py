"""Checks of calibration captures: is an HDR capture of a target usable? (`check_exposure`),
and the tolerances the calibration wizard accepts (`Tolerances`).

A failed check raises `WizardError` saying what was wrong and what to do.
"""
from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["WizardError", "Tolerances", "check_exposure", "angle_deg"]


class WizardError(RuntimeError):
    """A calibration step failed its check; the message says what was wrong and what to do."""


@dataclasses.dataclass
class Tolerances:
    """Acceptance limits of the wizard's checks."""
    saturated_fraction: float = 0.002     # of the target, saturated in every exposure
    min_signal: float = 0.08              # target level at the longest exposure, of full scale
    min_coverage: float = 0.8             # Spectralon: fraction of the frame it must fill
    nonuniformity: float = 0.05           # Spectralon: residual after flat field (rel. std)
    outline_rms_px: float = 0.5           # sphere outline fit
    nominal_deg: float = 10.0             # a direction this far from nominal: miswired LED
    matte_vs_mirror_deg: float = 1.5      # cross-check (a near LED shades a 76 mm sphere unevenly: ~1°)
    gain_spread: float = 0.01             # after equalisation: max/min − 1 of the LEDs
    ptc_fit: float = 0.10                 # relative rms of the photon transfer fit
    drift_intensity: float = 0.02         # --check: relative intensity change
    drift_deg: float = 0.5                # --check: direction change


def angle_deg(a, b):
    """Angle in degrees between unit vectors a and b (..., 3)."""
    return np.degrees(np.arccos(np.clip(np.sum(np.asarray(a) * np.asarray(b), axis=-1), -1, 1)))


def _pct(x):
    """A fraction as a percentage with two significant digits, never in e-notation."""
    p = 100.0 * float(x)
    return f"{p:.0f} %" if p >= 10 else f"{p:.2g} %"


def check_exposure(images, longest_us, shortest_us, current_mA, full_scale_dn, what, mask=None,
                   tol=Tolerances()):
    """Is a target's HDR capture usable? Raises WizardError saying why not.

    images : (m, H, W, 3) radiance, DN/(µs·mA) (facette.hdr.HDR_UNIT).
    A pixel brighter than the shortest exposure's saturation level is saturated in
    every exposure (its value is a lower bound): overexposed. A target whose level
    at the longest exposure is under `min_signal` of full scale is missing (or the
    LED is off). Returns (level at the longest exposure (m,), saturated fraction (m,)).
    """
    img = np.asarray(images)
    m = len(img)
    sel = np.ones(img.shape[1:3], bool) if mask is None else np.asarray(mask, bool)
    sat_level = full_scale_dn / (shortest_us * current_mA)
    lum = img.max(axis=3)
    sat = np.array([(lum[i][sel] >= 0.95 * sat_level).mean() for i in range(m)])
    level = np.array([np.percentile(lum[i][sel], 99) for i in range(m)]) * longest_us * current_mA / full_scale_dn
    over = np.flatnonzero(sat > tol.saturated_fraction)
    if over.size:
        i = int(over[np.argmax(sat[over])])
        raise WizardError(
            f"{what}: overexposed — {_pct(sat[i])} of the image is saturated even at the shortest "
            f"exposure ({shortest_us / 1e6:g} s at {current_mA} mA) under LED(s) {over.tolist()}. "
            "Shorten the exposures (--exposures) or lower the LED current (--current), then run the "
            "step again.")
    dark = np.flatnonzero(level < tol.min_signal)
    if dark.size == m:
        raise WizardError(
            f"{what}: not found — the image is dark ({100 * level.max():.1f} % of full scale at "
            f"{longest_us / 1e6:g} s, {current_mA} mA, under every LED). Place the target under the "
            "camera (see the instruction above), check that the LEDs light and the lens cap is off, "
            "then run the step again.")
    if dark.size:
        raise WizardError(
            f"{what}: LED(s) {dark.tolist()} gave almost no light ({np.round(100 * level[dark], 1).tolist()} % "
            "of full scale): check those LEDs and their wiring (`facette device faults`), then run "
            "the step again.")
    return level, sat
