"""The simulated rig's LEDs: the thesis geometry with per-LED errors.

The rig of thesis §4.3.2 has 12 LEDs about 1.5 m from the object: zenith θ = 30°
at azimuth φ = 0°, 60°, …, 300° and θ = 15° at φ = 30°, 90°, …, 330°. LED channel
``i`` of the device is ``facette.calib.nominal_light_directions()[i]``.
The simulator's LEDs deviate from the nominal ones (direction and intensity
errors) so that calibration has something to find.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from facette.calib import nominal_light_directions

__all__ = ["LedArray", "thesis_leds", "THESIS_DISTANCE_MM"]

THESIS_DISTANCE_MM = 1500.0


@dataclasses.dataclass
class LedArray:
    """True LED geometry and output of the simulated rig.

    Attributes
    ----------
    directions : ndarray (m, 3), unit, camera frame: from the object towards the LED
    intensities : ndarray (m, 3), > 0, relative radiant intensity per channel at the
        same drive current (1 = nominal)
    positions_mm : ndarray (m, 3) or None; when set, lights are near: the direction
        and the 1/r² fall-off are computed per pixel from these positions
    distance_mm : float, the distance the intensities refer to (positions case)
    """
    directions: np.ndarray
    intensities: np.ndarray
    positions_mm: np.ndarray | None = None
    distance_mm: float = THESIS_DISTANCE_MM

    def __len__(self):
        return len(self.directions)

    def truth_dict(self):
        return {"directions": self.directions.tolist(), "intensities": self.intensities.tolist(),
                "positions_mm": None if self.positions_mm is None else self.positions_mm.tolist()}


def _rotate_towards(d, angle, rng):
    """Tilt unit vector `d` by `angle` rad in a random direction."""
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    t = np.cross(d, a)
    t /= np.linalg.norm(t)
    b = np.cross(d, t)
    psi = rng.uniform(0, 2 * np.pi)
    out = np.cos(angle) * d + np.sin(angle) * (np.cos(psi) * t + np.sin(psi) * b)
    return out / np.linalg.norm(out)


def thesis_leds(direction_error_deg=0.5, intensity_error=0.05, near=False,
                distance_mm=THESIS_DISTANCE_MM, seed=0):
    """The 12 LEDs of the thesis rig with random errors.

    Parameters
    ----------
    direction_error_deg : float >= 0, RMS tilt of each LED from its nominal direction, degrees
    intensity_error : float >= 0, relative RMS error of each LED's output (per channel,
        mostly common to R, G, B), dimensionless
    near : bool, model the LEDs as points at `distance_mm` (per-pixel direction and 1/r²)
    distance_mm : float > 0, LED distance from the object centre, mm (thesis: ~1.5 m)
    seed : int
    """
    if direction_error_deg < 0 or intensity_error < 0 or not distance_mm > 0:
        raise ValueError("direction_error_deg and intensity_error must be >= 0 and distance_mm > 0")
    rng = np.random.default_rng(seed)
    nominal = nominal_light_directions()
    dirs = np.array([_rotate_towards(d, np.deg2rad(direction_error_deg) * abs(rng.normal()), rng)
                     for d in nominal])
    common = 1.0 + intensity_error * rng.normal(size=(len(dirs), 1))
    tint = 1.0 + 0.2 * intensity_error * rng.normal(size=(len(dirs), 3))
    intens = np.clip(common * tint, 0.2, None)
    pos = dirs * distance_mm if near else None
    return LedArray(dirs, intens, pos, float(distance_mm))
