"""Virtual objects for the simulated rig: height fields with normals, mask and albedo.

Everything is sampled on the grid the HDR images will have (the RAW half-size
grid: one RGB pixel per 2×2 Bayer cell), in the camera frame of DESIGN §8:
x right, y up, z towards the camera; image row 0 is the top. The camera is
orthographic and looks down −z, so heights are along +z, in mm.

Scenes are made by name (``make_scene("plaque_sphere")``); see ``SCENES``.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np

__all__ = ["Scene", "make_scene", "SCENES", "BRDF_PRESETS", "normals_from_height"]


@dataclasses.dataclass
class Scene:
    """A virtual object seen by the orthographic camera.

    Attributes
    ----------
    height_mm : ndarray (H, W) float64, mm along +z (the table is at 0)
    normals : ndarray (H, W, 3) float64, unit, camera frame
    mask : ndarray (H, W) bool, True on the object (plaque, sphere), False on the table
    albedo : ndarray (H, W, 3) float64 in [0, 1], diffuse reflectance K_d per channel
    pixel_pitch_mm : float, size of one (half-size) pixel on the object, mm
    brdf : dict, ``{"model": name, "params": {...}}`` for `facette.brdf.get(name)`;
        K_d is the per-pixel `albedo`, not a parameter here
    name : str
    """
    height_mm: np.ndarray
    normals: np.ndarray
    mask: np.ndarray
    albedo: np.ndarray
    pixel_pitch_mm: float
    brdf: dict
    name: str = ""

    @property
    def shape(self):
        """(H, W) of the half-size grid."""
        return self.height_mm.shape

    def coordinates_mm(self):
        """(x, y) in mm of every pixel centre, each (H, W); origin at the image centre."""
        h, w = self.shape
        x = (np.arange(w) - (w - 1) / 2.0) * self.pixel_pitch_mm
        y = ((h - 1) / 2.0 - np.arange(h)) * self.pixel_pitch_mm   # row 0 is the top: y up
        return np.meshgrid(x, y)

    def brdf_json(self):
        """The BRDF as a JSON string (truth.npz `brdf`, contract 3)."""
        return json.dumps({**self.brdf, "kd": "albedo (per pixel)"}, sort_keys=True)


def normals_from_height(height_mm, pixel_pitch_mm):
    """Unit normals (H, W, 3) of a height field z(x, y) sampled with row 0 at the top.

    n ∝ (−∂z/∂x, −∂z/∂y, 1); since rows go down, ∂z/∂y = −∂z/∂row / pitch.
    Central differences inside, one-sided at the border (np.gradient).
    """
    dz_drow, dz_dcol = np.gradient(np.asarray(height_mm, dtype=np.float64), pixel_pitch_mm)
    n = np.stack([-dz_dcol, dz_drow, np.ones_like(dz_dcol)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _smoothstep(edge0, edge1, x):
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _plaque(x, y, cx, cy, half_w, half_h, thickness, rng):
    """A bevelled slab with a bas-relief fossil on top: an ammonite (a ribbed
    logarithmic spiral) and a few trilobite-like segment rows. Returns (height, inside)."""
    bevel = 0.12 * min(half_w, half_h)
    # distance inside the rounded rectangle (positive inside)
    dx, dy = half_w - np.abs(x - cx), half_h - np.abs(y - cy)
    inside_d = np.minimum(dx, dy)
    slab = thickness * _smoothstep(0.0, bevel, inside_d)
    # ammonite: ribs along a spiral, a coiled rim, fading at its edge
    ax, ay = cx - 0.2 * half_w, cy + 0.05 * half_h
    r = np.hypot(x - ax, y - ay)
    theta = np.arctan2(y - ay, x - ax)
    radius = 0.62 * min(half_w, half_h)
    coil = np.log1p(r / (0.08 * radius)) / np.log(1 + 1 / 0.08)          # 0 at centre, 1 at rim
    ribs = 0.5 + 0.5 * np.cos(26.0 * theta + 40.0 * coil)
    whorls = 0.5 + 0.5 * np.cos(2 * np.pi * (3.0 * coil - theta / (2 * np.pi)))
    envelope = 1.0 - _smoothstep(0.85 * radius, radius, r)
    ammonite = envelope * (0.35 * thickness * whorls + 0.15 * thickness * ribs
                           + 0.4 * thickness * (1.0 - coil))
    # trilobite-like segments: a row of elongated bumps to the right
    tx, ty = cx + 0.62 * half_w, cy - 0.1 * half_h
    seg = np.zeros_like(x)
    for k in range(6):
        sy = ty + (k - 2.5) * 0.22 * half_h
        seg += np.exp(-(((x - tx) / (0.22 * half_w)) ** 2 + ((y - sy) / (0.07 * half_h)) ** 2))
    # sediment grain: smooth low-amplitude noise (a few random cosines)
    grain = np.zeros_like(x)
    for _ in range(6):
        kx, ky = rng.normal(0, 2.5 / half_w, 2)
        grain += np.cos(2 * np.pi * (kx * x + ky * y) * 1.5 + rng.uniform(0, 2 * np.pi))
    relief = ammonite + 0.3 * thickness * seg + 0.02 * thickness * grain
    inner = _smoothstep(bevel, 2 * bevel, inside_d)
    height = slab + inner * relief
    return height, inside_d > 0


def _sphere(x, y, cx, cy, radius):
    r2 = (x - cx) ** 2 + (y - cy) ** 2
    inside = r2 < radius ** 2
    z = np.sqrt(np.clip(radius ** 2 - r2, 0.0, None))
    n = np.stack([(x - cx), (y - cy), z], axis=-1)
    n[~inside] = (0.0, 0.0, 1.0)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return z, inside, n


def make_scene(name="plaque_sphere", shape=(48, 64), pixel_pitch_mm=None, seed=0,
               brdf=None):
    """Build a named virtual object on an (H, W) half-size grid.

    Parameters
    ----------
    name : str, one of ``SCENES``: "plaque_sphere" (default: a fossil slab in bas-
        relief and a glossy sphere beside it), "plaque", "sphere", "plane".
    shape : (H, W) of the half-size grid (the RAW image is (2H, 2W)); H, W >= 8.
    pixel_pitch_mm : float or None, mm per half-size pixel; default so that the
        scene is 120 mm wide.
    seed : int, for the small random parts (sediment grain, albedo mottling).
    brdf : dict, a name of ``BRDF_PRESETS``, or None: ``{"model": ..., "params": {...}}``;
        default "mask", the thesis's smooth specular validation material (Cook–Torrance
        σ = 0.05, n_i = 1.2, fig 4.21); "bust" is its glossy one (σ = 0.1, n_i = 1.3).
    """
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose one of {sorted(SCENES)}")
    h, w = (int(v) for v in shape)
    if h < 8 or w < 8:
        raise ValueError(f"scene shape must be at least 8×8 half-size pixels, got {shape}")
    pitch = float(pixel_pitch_mm) if pixel_pitch_mm else 120.0 / w
    if not pitch > 0:
        raise ValueError(f"pixel_pitch_mm must be > 0, got {pixel_pitch_mm}")
    if brdf is None or isinstance(brdf, str):
        key = brdf or "mask"
        if key not in BRDF_PRESETS:
            raise ValueError(f"unknown BRDF preset {key!r}; choose one of {sorted(BRDF_PRESETS)} "
                             "or give {'model': ..., 'params': {...}}")
        brdf = BRDF_PRESETS[key]
    rng = np.random.default_rng(seed)
    scene = Scene(np.zeros((h, w)), np.zeros((h, w, 3)), np.zeros((h, w), bool),
                  np.zeros((h, w, 3)), pitch,
                  {"model": brdf["model"], "params": dict(brdf.get("params", {}))},
                  name=name)
    x, y = scene.coordinates_mm()
    width_mm, height_mm = w * pitch, h * pitch
    table_albedo = np.array([0.04, 0.04, 0.045])
    height = np.zeros((h, w))
    albedo = np.broadcast_to(table_albedo, (h, w, 3)).copy()
    mask = np.zeros((h, w), bool)
    sphere_n, sphere_in = None, np.zeros((h, w), bool)

    if name in ("plaque_sphere", "plaque"):
        cx = -0.18 * width_mm if name == "plaque_sphere" else 0.0
        half_w = (0.30 if name == "plaque_sphere" else 0.42) * width_mm
        half_h = 0.40 * height_mm
        ph, pin = _plaque(x, y, cx, 0.0, half_w, half_h, 0.08 * min(half_w, half_h), rng)
        height = np.maximum(height, ph)
        mottling = 1.0 + 0.06 * np.cos(x / (0.09 * width_mm) + rng.uniform(0, 6)) \
            * np.cos(y / (0.07 * width_mm) + rng.uniform(0, 6))
        limestone = np.array([0.62, 0.54, 0.42])[None, None, :] * mottling[..., None]
        albedo[pin] = limestone[pin]
        mask |= pin
    if name in ("plaque_sphere", "sphere"):
        radius = (0.16 if name == "plaque_sphere" else 0.35) * width_mm
        radius = min(radius, 0.45 * height_mm)
        cx = 0.30 * width_mm if name == "plaque_sphere" else 0.0
        sz, sphere_in, sphere_n = _sphere(x, y, cx, 0.0, radius)
        height = np.where(sphere_in, np.maximum(height, sz), height)
        albedo[sphere_in] = (0.55, 0.25, 0.18)
        mask |= sphere_in
    if name == "plane":
        mask[:] = True
        albedo[:] = (0.5, 0.5, 0.5)

    normals = normals_from_height(height, pitch)
    if sphere_n is not None:  # analytic normals on the sphere (its rim has no finite gradient)
        normals[sphere_in] = sphere_n[sphere_in]
    scene.height_mm, scene.normals, scene.mask, scene.albedo = height, normals, mask, albedo
    return scene


SCENES = ("plaque_sphere", "plaque", "sphere", "plane")

# Materials of the thesis's validation scenes (§4.3.1, fig 4.21), and a matte one.
BRDF_PRESETS = {
    "mask": {"model": "cook_torrance", "params": {"sigma": 0.05, "n_i": 1.2}},
    "bust": {"model": "cook_torrance", "params": {"sigma": 0.1, "n_i": 1.3}},
    "lambert": {"model": "lambert", "params": {}},
}
