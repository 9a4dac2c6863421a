"""Spectralon calibration: relative LED intensities, flat field, LED current gains.

The thesis (§4.3.2, condition 4) calibrates the rig with a Spectralon target so
that the LEDs' intensity ratios are known and corrected. A flat white diffuser of
certified reflectance ρ (per channel) on the object plane, lit by LED i, gives the
radiance (thesis eq 4.3 with n = target normal)

    E_i(x) = ρ/π · I_i · k_i(x) · (n · s_i(x)) · F(x)

with I_i the LED's irradiance at the field centre, k_i the near-light fall-off
(|P_i|²/|P_i − X|², 1 for a distant light), s_i the direction to the LED and F the
camera's own flat field (vignetting, pixel response). Inverting this gives I_i per
channel (`spectralon_intensities`) and F (`flat_field`).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from facette.calib.targets import light_vectors, pixel_grid_mm

__all__ = ["SpectralonResult", "spectralon_intensities", "flat_field", "led_current_gains",
           "target_mask", "apply_flat_field"]


@dataclasses.dataclass
class SpectralonResult:
    """intensities (m, 3) relative; absolute (m, 3) in image units per unit irradiance
    (the pre-normalisation values); nonuniformity (m,) relative spatial std of each
    corrected image over the target (what the model leaves unexplained)."""
    intensities: np.ndarray
    absolute: np.ndarray
    nonuniformity: np.ndarray


def _check_stack(images):
    img = np.asarray(images)
    if img.dtype != np.float32:     # float32 stays float32: full-size HDR stacks are large
        img = img.astype(np.float64)
    if img.ndim == 3:
        img = img[None]
    if img.ndim != 4 or img.shape[-1] != 3:
        raise ValueError(f"images must have shape (m, H, W, 3) (one HDR image per LED), got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("images contain NaN or inf: merge the HDR images with saturation masking "
                         "first, or pass a mask that excludes the bad pixels")
    return img


def target_mask(images, low=0.5, border=0.05):
    """Pixels that see the target: brighter than `low` × the median of the mean image,
    minus a `border` fraction of the frame on each side (target edges, lens rim).
    Returns bool (H, W)."""
    img = _check_stack(images)
    mean = img.mean(axis=(0, 3))
    m = mean > low * np.median(mean)
    h, w = m.shape
    bh, bw = int(round(border * h)), int(round(border * w))
    frame = np.zeros_like(m)
    frame[bh:h - bh, bw:w - bw] = True
    return m & frame


class _Geometry:
    """cos(incidence) × fall-off of each light at every pixel: ``geo[i]`` is (H, W)
    (or a scalar for a distant light), computed one light at a time."""

    def __init__(self, shape, directions, positions_mm, pixel_pitch_mm, normal):
        self.n = np.asarray(normal, float) / np.linalg.norm(normal)
        self.positions = None if positions_mm is None else np.asarray(positions_mm, float)
        if self.positions is None:
            d = np.asarray(directions, float)
            self.cos = np.clip((d / np.linalg.norm(d, axis=1, keepdims=True)) @ self.n, 0, None)
            self.m = len(d)
            return
        if pixel_pitch_mm is None:
            raise ValueError("near-light positions need pixel_pitch_mm to place the pixels in mm")
        x, y = pixel_grid_mm(shape, pixel_pitch_mm)
        n = self.n
        self.pts = np.stack([x, y, -(n[0] * x + n[1] * y) / n[2]], -1)
        self.m = len(self.positions)

    def __len__(self):
        return self.m

    def __getitem__(self, i):
        if self.positions is None:
            return self.cos[i]
        s, k = light_vectors(self.pts, position_mm=self.positions[i])
        return np.clip(s @ self.n, 0, None) * k


def spectralon_intensities(images, directions=None, reflectance=(0.99, 0.99, 0.99), mask=None,
                           positions_mm=None, pixel_pitch_mm=None, normal=(0.0, 0.0, 1.0),
                           flat=None, normalise="channel"):
    """Relative intensity of each LED per channel from Spectralon images (thesis §4.3.2).

    Parameters
    ----------
    images : ndarray (m, H, W, 3)
        Linear HDR radiance of the target under each LED (any common unit).
    directions : ndarray (m, 3)
        Unit light directions, camera frame (distant lights). Ignored for the
        geometry when `positions_mm` is given.
    reflectance : (3,) certified reflectance per channel, in (0, 1]
        (`facette.calib.targets.channel_reflectance`).
    mask : bool (H, W) or None — target pixels (default `target_mask`).
    positions_mm : (m, 3) or None — near-light LED positions (1/r² and per-pixel cosine).
    pixel_pitch_mm : float — object-plane pixel size, needed with positions.
    normal : (3,) target normal (camera frame), default facing the camera.
    flat : (H, W, 3) or None — the camera flat field to divide out first.
    normalise : "channel" (each channel's mean over LEDs = 1, the profile's
        convention) or "green" (green mean 1; R and B keep their ratio to green, so
        dividing by the intensities also white-balances against the certified white).

    Returns
    -------
    SpectralonResult
        I_i = π · mean_x(E_i / (k_i cos_i F)) / ρ, normalised.
    """
    img = _check_stack(images)
    m, h, w, _ = img.shape
    if directions is None and positions_mm is None:
        raise ValueError("give the light directions (m, 3) or the LED positions_mm (m, 3)")
    nl = len(positions_mm if positions_mm is not None else directions)
    if nl != m:
        raise ValueError(f"{m} images but {nl} lights: give one Spectralon image per LED")
    rho = np.broadcast_to(np.asarray(reflectance, float), (3,))
    if np.any((rho <= 0) | (rho > 1)):
        raise ValueError(f"reflectance must lie in (0, 1], got {rho}")
    if mask is None:
        mask = target_mask(img)
    mask = np.asarray(mask, bool)
    if mask.shape != (h, w) or mask.sum() < 10:
        raise ValueError(f"the target mask has {int(mask.sum())} pixels (shape {mask.shape}); the "
                         "Spectralon must fill most of the field: place it under the camera")
    geo = _Geometry((h, w), directions, positions_mm, pixel_pitch_mm, normal)
    ff = None if flat is None else np.asarray(flat, float)[mask]
    means, nonuni = np.empty((m, 3)), np.empty(m)
    for i in range(m):                                   # one LED at a time: full-size stacks
        g = geo[i]
        g = g[mask] if np.ndim(g) else np.full(int(mask.sum()), float(g))
        if np.any(g <= 1e-3):
            raise ValueError(f"LED {i} grazes or is behind the target (cos ≤ 0.001): check the "
                             "directions and the target normal")
        vals = img[i][mask].astype(np.float64) / g[:, None]          # (N, 3)
        if ff is not None:
            vals /= ff
        means[i] = vals.mean(axis=0)
        nonuni[i] = vals[:, 1].std() / vals[:, 1].mean() if vals[:, 1].mean() > 0 else np.inf
    absolute = np.pi * means / rho
    if np.any(absolute <= 0):
        raise ValueError("an LED gave no light on the target (mean ≤ 0): is it connected and on?")
    if normalise == "channel":
        rel = absolute / absolute.mean(axis=0, keepdims=True)
    elif normalise == "green":
        rel = absolute / absolute[:, 1].mean()
    else:
        raise ValueError(f"normalise must be 'channel' or 'green', got {normalise!r}")
    return SpectralonResult(rel, absolute, nonuni)


def _poly_terms(degree):
    return [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]


def _poly_uv(h, w):
    """Normalised coordinates: u (W,) across, v (H,) down, both in about [−1, 1]."""
    return (np.arange(w) - (w - 1) / 2) / (w / 2), (np.arange(h) - (h - 1) / 2) / (h / 2)


def _poly_fit(values, mask, degree, max_samples=200_000):
    """Least-squares polynomial surface Σ c_ij u^i v^j through values[mask] (H, W), evaluated
    everywhere. Fitted on at most `max_samples` pixels (a regular subsample)."""
    h, w = values.shape
    u, v = _poly_uv(h, w)
    rr, cc = np.nonzero(mask)
    step = max(1, int(np.ceil(len(rr) / max_samples)))
    rr, cc = rr[::step], cc[::step]
    terms = _poly_terms(degree)
    A = np.stack([u[cc] ** i * v[rr] ** j for i, j in terms], -1)
    coef, *_ = np.linalg.lstsq(A, values[rr, cc], rcond=None)
    out = np.zeros((h, w))
    for (i, j), c in zip(terms, coef):
        out += c * np.outer(v ** j, u ** i)
    return out


def flat_field(images, directions=None, mask=None, positions_mm=None, pixel_pitch_mm=None,
               normal=(0.0, 0.0, 1.0), degree=None):
    """Per-pixel flat field from Spectralon images, (H, W, 3), mean 1 over the frame.

    Each LED's image is divided by its own geometry (incidence cosine and, when
    `positions_mm` is given, the 1/r² fall-off) and by its mean over the target,
    then the LEDs are averaged. So:

    - without positions (distant-light pipeline), F includes the near-light
      fall-off averaged over the LEDs (divide the scan's images by it);
    - with positions (near-light pipeline), F holds only the camera's share
      (vignetting, pixel response), since the pipeline models 1/r² itself.

    Pixels outside `mask` (and all pixels when `degree` is an int) take the value
    of a least-squares polynomial surface of that degree (default 4 outside the
    mask only), which also smooths out the target's texture and noise.
    """
    img = _check_stack(images)
    m, h, w, _ = img.shape
    if directions is None and positions_mm is None:
        directions = np.tile([0.0, 0.0, 1.0], (m, 1))
    geo = _Geometry((h, w), directions, positions_mm, pixel_pitch_mm, normal)
    if mask is None:
        mask = target_mask(img)
    mask = np.asarray(mask, bool)
    ff = np.zeros((h, w, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(m):                               # one LED at a time: full-size stacks
            g = geo[i]
            corr = img[i].astype(np.float64) / (g[..., None] if np.ndim(g) else g)
            ff += corr / corr[mask].mean(axis=0)
    ff /= m
    if degree is not None or not mask.all():
        deg = 4 if degree is None else int(degree)
        fit = np.stack([_poly_fit(ff[..., c], mask, deg) for c in range(3)], -1)
        ff = fit if degree is not None else np.where(mask[..., None], ff, fit)
    if not np.all(np.isfinite(ff)) or np.any(ff <= 0):
        raise ValueError("the flat field has non-positive or non-finite pixels: the target "
                         "does not cover the field, or some LED leaves part of it dark")
    return (ff / ff.mean(axis=(0, 1), keepdims=True)).astype(np.float32)


def led_current_gains(intensities, current_gains=None, channel=1, target="min", limits=(0.25, 1.0)):
    """Per-LED current gains that equalise the LEDs' intensities.

    LED output is taken as proportional to current, so the new gain of LED i is
    g_i · T / I_i, with T the target intensity: the dimmest LED (``"min"``: no LED
    is driven above its present current), the mean (``"mean"``), or ``"lowest"``:
    the dimmest level every LED reaches within `limits` (the dimmest LED when the
    spread allows it, else the level at which the brightest needs the lowest gain).

    Parameters
    ----------
    intensities : (m, 3) or (m,) relative intensities measured with `current_gains`.
    current_gains : (m,) gains in force during the measurement (default 1).
    channel : int channel index used (1 = green) or "mean" of the three.
    limits : (lo, hi) range the device accepts; a gain outside it is an error (the
        LED is too weak or too strong to equalise: replace it or check its wiring).

    Returns ndarray (m,).
    """
    I = np.asarray(intensities, float)
    if I.ndim == 2:
        I = I.mean(axis=1) if channel == "mean" else I[:, int(channel)]
    g0 = np.ones_like(I) if current_gains is None else np.asarray(current_gains, float)
    if g0.shape != I.shape:
        raise ValueError(f"{len(I)} intensities but {g0.size} current gains")
    if np.any(I <= 0) or np.any(g0 <= 0):
        raise ValueError("intensities and gains must be > 0")
    lo, hi = limits
    eff = I / g0                      # light per unit gain
    if target == "min":
        t = I.min()
    elif target == "mean":
        t = I.mean()
    elif target == "lowest":
        # the dimmest common level every LED reaches with a gain within [lo, hi]
        t = max(eff.min(), lo * eff.max())
    else:
        raise ValueError(f"target must be 'min', 'mean' or 'lowest', got {target!r}")
    g = g0 * t / I
    bad = np.flatnonzero((g < lo - 1e-12) | (g > hi + 1e-12))
    if bad.size:
        raise ValueError(f"LED(s) {bad.tolist()} would need gains {np.round(g[bad], 3).tolist()}, "
                         f"outside the device's range [{lo}, {hi}]: the LED is too weak or too "
                         "strong to equalise; check it (or its current) and recalibrate")
    return g


def apply_flat_field(images, flat):
    """Divide images by a profile's flat field (what a pipeline does before photometric stereo).

    images : (..., H, W, 3) linear; flat : (H, W, 3) mean 1 or None (returned unchanged).
    The flat field must have the images' resolution (the HDR half-size grid of the
    rig it was calibrated on): a mismatch means the profile belongs to another camera
    setting, and is an error rather than a silent resampling.
    """
    if flat is None:
        return images
    f = np.asarray(flat, dtype=np.float32)
    img = np.asarray(images)
    if f.ndim != 3 or f.shape != img.shape[-3:]:
        raise ValueError(f"the flat field is {f.shape} but the images are {img.shape[-3:]}: the profile "
                         "was made at another resolution; recalibrate at this one (facette calibrate)")
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise ValueError("the flat field has non-positive or non-finite values: the profile is damaged")
    return img / f
