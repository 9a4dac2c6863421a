"""Calibration targets: their specifications and synthetic renderings.

The specifications (the Spectralon certificate, the mirror and matte spheres) are
JSON files in ``calibration/targets/`` (shipped with the package, found by
`facette._data.targets_dir`). The renderings are orthographic images of the three
targets under one LED (distant or near), linear radiance per unit exposure, shape
(H, W, 3): the tests use them. The targets as the simulated rig shows them are
`facette.sim.targets`.

Geometry (docs/conventions.md): camera frame x right, y up, z towards the camera; the object
plane is z = 0; pixel (row, col) has its centre at
``x = (col - (W - 1) / 2) · pitch``, ``y = ((H - 1) / 2 - row) · pitch`` (mm).
A light is either a unit direction (distant) or a position in mm (near light); a
near light's `intensity` is the irradiance it gives at the origin on a surface
facing it, so both models agree at the centre of the field.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import ndimage

from facette._data import targets_dir

__all__ = ["TARGETS_DIR", "load_target", "channel_reflectance", "pixel_grid_mm",
           "light_vectors", "render_spectralon", "render_mirror_sphere", "render_matte_sphere",
           "CHANNEL_CENTRES_NM", "rgb_triplet"]

TARGETS_DIR = targets_dir()
# Camera channel responses, approximated as Gaussians (centre, σ) in nm: enough to
# average a certificate that varies by 1 % over the visible.
CHANNEL_CENTRES_NM = ((600.0, 35.0), (535.0, 35.0), (460.0, 30.0))


def load_target(name_or_path):
    """Load a target specification: a name in ``calibration/targets/`` (``"spectralon-99"``,
    ``"mirror-sphere"``, ``"matte-sphere"``) or a JSON file path. Returns a dict."""
    p = Path(name_or_path)
    if not p.suffix:
        p = TARGETS_DIR / f"{name_or_path}.json"
    if not p.is_file():
        known = sorted(q.stem for q in TARGETS_DIR.glob("*.json"))
        raise FileNotFoundError(f"no target specification {p}; known targets: {', '.join(known)}")
    spec = json.loads(p.read_text())
    if spec.get("kind") == "spectralon":
        wl, r = np.asarray(spec["wavelength_nm"], float), np.asarray(spec["reflectance"], float)
        if wl.shape != r.shape or wl.size < 2 or np.any(np.diff(wl) <= 0):
            raise ValueError(f"{p}: wavelength_nm must increase and match reflectance in length")
        if np.any((r <= 0) | (r > 1)):
            raise ValueError(f"{p}: reflectance values must lie in (0, 1]")
    return spec


def channel_reflectance(certificate="spectralon-99"):
    """Reflectance of a certified target per camera channel (R, G, B), shape (3,).

    The certificate's spectral reflectance averaged with Gaussian channel
    responses (`CHANNEL_CENTRES_NM`). `certificate` is a spec dict, name or path.
    """
    spec = certificate if isinstance(certificate, dict) else load_target(certificate)
    wl = np.asarray(spec["wavelength_nm"], float)
    r = np.asarray(spec["reflectance"], float)
    grid = np.linspace(wl[0], wl[-1], 301)
    rg = np.interp(grid, wl, r)
    out = []
    for c, s in CHANNEL_CENTRES_NM:
        w = np.exp(-0.5 * ((grid - c) / s) ** 2)
        out.append(float(np.sum(w * rg) / np.sum(w)))
    return np.array(out)


def pixel_grid_mm(shape, pixel_pitch_mm):
    """Object-plane coordinates of the pixel centres: (x, y) each (H, W), mm."""
    h, w = int(shape[0]), int(shape[1])
    x = (np.arange(w) - (w - 1) / 2.0) * pixel_pitch_mm
    y = ((h - 1) / 2.0 - np.arange(h)) * pixel_pitch_mm
    return np.meshgrid(x, y)


def light_vectors(points_mm, direction=None, position_mm=None):
    """Unit vectors to the light from points (..., 3) mm, and the irradiance factor.

    Distant light: the direction everywhere, factor 1. Near light at P: (P − X)/|P − X|
    and |P|²/|P − X|² (1/r² fall-off, 1 at the origin). Returns (s (..., 3), k (...)).
    """
    pts = np.asarray(points_mm, float)
    if (direction is None) == (position_mm is None):
        raise ValueError("give exactly one of direction (distant light) or position_mm (near light)")
    if direction is not None:
        d = np.asarray(direction, float)
        d = d / np.linalg.norm(d)
        return np.broadcast_to(d, pts.shape), np.ones(pts.shape[:-1])
    p = np.asarray(position_mm, float)
    v = p - pts
    r2 = np.sum(v * v, axis=-1)
    return v / np.sqrt(r2)[..., None], float(p @ p) / r2


def rgb_triplet(x):
    """A scalar or (3,) value as a (3,) float array (one value per R, G, B channel)."""
    x = np.asarray(x, float)
    return np.broadcast_to(x, (3,)).copy() if x.ndim == 0 or x.size == 1 else x.reshape(3)


def render_spectralon(shape, pixel_pitch_mm, direction=None, position_mm=None, intensity=1.0,
                      reflectance=0.99, normal=(0.0, 0.0, 1.0), vignetting=None):
    """Flat Lambertian target filling the field, plane z = 0 through the origin.

    Radiance L = ρ/π · I · k · max(0, n·s) per channel (thesis eq 4.3 for a white
    diffuser), with k the near-light fall-off (1 for a distant light). `vignetting`
    (H, W) or (H, W, 3) multiplies the image (the camera's own non-uniformity).
    Returns float64 (H, W, 3).
    """
    x, y = pixel_grid_mm(shape, pixel_pitch_mm)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    # a tilted plane through the origin: z = −(n_x x + n_y y)/n_z
    z = -(n[0] * x + n[1] * y) / n[2]
    s, k = light_vectors(np.stack([x, y, z], -1), direction, position_mm)
    cos = np.clip(s @ n, 0.0, None)
    img = (rgb_triplet(reflectance) / np.pi * rgb_triplet(intensity))[None, None, :] * (cos * k)[..., None]
    if vignetting is not None:
        v = np.asarray(vignetting, float)
        img = img * (v if v.ndim == 3 else v[..., None])
    return img


def _sphere_samples(shape, center_px, radius_px, supersample):
    """Sub-pixel sample positions (col, row) of every pixel, (H, W, S², 2)."""
    h, w = int(shape[0]), int(shape[1])
    o = (np.arange(supersample) + 0.5) / supersample - 0.5
    oy, ox = np.meshgrid(o, o, indexing="ij")
    rows, cols = np.mgrid[0:h, 0:w]
    c = cols[..., None] + ox.ravel()
    r = rows[..., None] + oy.ravel()
    u = (c - center_px[0]) / radius_px
    v = -(r - center_px[1]) / radius_px   # y up
    return u, v


def _sphere(shape, center_px, radius_px, pixel_pitch_mm, center_z_mm, supersample):
    u, v = _sphere_samples(shape, center_px, radius_px, supersample)
    rho2 = u * u + v * v
    inside = rho2 < 1.0
    nz = np.sqrt(np.clip(1.0 - rho2, 0.0, None))
    n = np.stack([u, v, nz], -1)
    h, w = int(shape[0]), int(shape[1])
    r_mm = radius_px * pixel_pitch_mm
    cx_mm = (center_px[0] - (w - 1) / 2.0) * pixel_pitch_mm
    cy_mm = ((h - 1) / 2.0 - center_px[1]) * pixel_pitch_mm
    cz = r_mm if center_z_mm is None else center_z_mm
    pts_sphere = np.array([cx_mm, cy_mm, cz]) + r_mm * n
    x = cx_mm + u * r_mm
    y = cy_mm + v * r_mm
    pts_plane = np.stack([x, y, np.zeros_like(x)], -1)
    return n, inside, pts_sphere, pts_plane


def render_mirror_sphere(shape, center_px, radius_px, pixel_pitch_mm, direction=None,
                         position_mm=None, intensity=1.0, source_radius_deg=0.5, reflectance=0.6,
                         backdrop_albedo=0.5, center_z_mm=None, supersample=4, psf_px=0.8):
    """A chrome sphere on a grey card, under one LED; orthographic view, (H, W, 3).

    Inside the silhouette the sphere reflects the direction r = 2(n·v)n − v
    (v = +z): the LED (a uniform disc of angular radius `source_radius_deg`,
    radiance I/(π α²) so its irradiance is I) where r falls in it, a dark enclosure
    elsewhere (the sphere's black collar hides the card). Outside, the card is
    Lambertian (`backdrop_albedo`). The sphere's centre is at height `center_z_mm`
    (default: its radius, resting on the plane z = 0). `supersample`² samples per
    pixel give anti-aliased edges and highlights; the lens's blur is a Gaussian of
    `psf_px` px (σ), which spreads a highlight over a few pixels as a real lens does.
    """
    n, inside, pts_s, pts_p = _sphere(shape, center_px, radius_px, pixel_pitch_mm, center_z_mm,
                                      supersample)
    refl = 2.0 * n[..., 2:3] * n - np.array([0.0, 0.0, 1.0])
    s, k = light_vectors(pts_s, direction, position_mm)
    alpha = np.deg2rad(source_radius_deg)
    hit = np.sum(refl * s, -1) >= np.cos(alpha)
    lum_sphere = np.where(inside & hit, reflectance * k / (np.pi * alpha ** 2), 0.0)
    sp, kp = light_vectors(pts_p, direction, position_mm)
    lum_card = np.where(inside, 0.0, backdrop_albedo / np.pi * np.clip(sp[..., 2], 0, None) * kp)
    lum = lum_sphere + lum_card
    if psf_px:
        # blur before integrating over the pixel, as the lens comes before the sensor
        h, w, _ = lum.shape
        fine = lum.reshape(h, w, supersample, supersample).transpose(0, 2, 1, 3)
        fine = ndimage.gaussian_filter(fine.reshape(h * supersample, w * supersample),
                                       psf_px * supersample, mode="nearest")
        lum = fine.reshape(h, supersample, w, supersample).transpose(0, 2, 1, 3).reshape(h, w, -1)
    return lum.mean(-1)[..., None] * rgb_triplet(intensity)


def render_matte_sphere(shape, center_px, radius_px, pixel_pitch_mm, direction=None,
                        position_mm=None, intensity=1.0, albedo=0.9, backdrop_albedo=0.05,
                        center_z_mm=None, supersample=2):
    """A Lambertian sphere on a dark card under one LED (no cast shadow), (H, W, 3).

    L = ρ/π · I · k · max(0, n·s) on the sphere (eq 4.3); the card likewise with
    `backdrop_albedo`.
    """
    n, inside, pts_s, pts_p = _sphere(shape, center_px, radius_px, pixel_pitch_mm, center_z_mm,
                                      supersample)
    s, k = light_vectors(pts_s, direction, position_mm)
    lum_sphere = np.where(inside, albedo / np.pi * np.clip(np.sum(n * s, -1), 0, None) * k, 0.0)
    sp, kp = light_vectors(pts_p, direction, position_mm)
    lum_card = np.where(inside, 0.0, backdrop_albedo / np.pi * np.clip(sp[..., 2], 0, None) * kp)
    lum = (lum_sphere + lum_card).mean(-1)
    return lum[..., None] * rgb_triplet(intensity)
