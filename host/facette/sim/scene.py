"""Virtual objects for the simulated rig: height fields with normals, mask and albedo.

Everything is given on the grid the HDR images will have (the RAW half-size
grid: one RGB pixel per 2×2 Bayer cell), each pixel the mean of the object over
its footprint (see `make_scene`), in the camera frame of docs/conventions.md:
x right, y up, z towards the camera; image row 0 is the top. The camera is
orthographic and looks down −z, so heights are along +z, in mm.

Scenes are made by name (``make_scene("plaque_sphere")``); see ``SCENES``.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np

__all__ = ["Scene", "SceneSpec", "make_scene", "scene_spec", "SCENES", "BRDF_PRESETS", "normals_from_height"]


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
        """The BRDF as a JSON string (truth.npz `brdf`, docs/scan-format.md)."""
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
    return np.sqrt(np.clip(radius ** 2 - r2, 0.0, None)), inside


FOOTPRINT_STEP_MM = 0.25
"""Spacing (mm) of the sub-samples that average the surface over each pixel's footprint:
finer than the fossil's ribs where they are resolved (a sub-sample grid at most ~480 wide)."""
MAX_SUPERSAMPLE = 16


def _surface(name, x, y, width_mm, height_mm, rng):
    """(height mm, mask bool, albedo (..., 3)) of scene `name` at the points (x, y) mm."""
    table_albedo = np.array([0.04, 0.04, 0.045])
    height = np.zeros(x.shape)
    albedo = np.broadcast_to(table_albedo, x.shape + (3,)).copy()
    mask = np.zeros(x.shape, bool)
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
        sz, sphere_in = _sphere(x, y, cx, 0.0, radius)
        height = np.where(sphere_in, np.maximum(height, sz), height)
        albedo[sphere_in] = (0.55, 0.25, 0.18)
        mask |= sphere_in
    if name == "plane":
        mask[:] = True
        albedo[:] = (0.5, 0.5, 0.5)
    return height, mask, albedo


def _trapezoid_mean(a, k):
    """Mean over each pixel of a field sampled at the corners of a k×k sub-grid.

    a : (H·k + 1, W·k + 1, ...) samples at the sub-grid corners; returns (H, W, ...): the mean
    of the bilinear interpolation of the samples over each pixel (trapezoidal rule)."""
    cells = 0.25 * (a[:-1, :-1] + a[:-1, 1:] + a[1:, :-1] + a[1:, 1:])    # each sub-cell's mean
    h, w = cells.shape[0] // k, cells.shape[1] // k
    return cells.reshape(h, k, w, k, *a.shape[2:]).mean(axis=(1, 3))


def _edge_means(z, k):
    """Mean height along each pixel's left/right and top/bottom edges (trapezoidal rule).

    z : (H·k + 1, W·k + 1) heights at the sub-grid corners. Returns (vertical (H, W + 1),
    horizontal (H + 1, W)): the mean over each pixel-high stretch of the vertical lines
    x = pixel edge, and over each pixel-wide stretch of the horizontal lines."""
    v = z[:, ::k]                                   # (H·k + 1, W + 1): the vertical edge lines
    seg = 0.5 * (v[:-1] + v[1:])
    vertical = seg.reshape(-1, k, v.shape[1]).mean(axis=1)
    hz = z[::k, :]                                  # (H + 1, W·k + 1)
    seg = 0.5 * (hz[:, :-1] + hz[:, 1:])
    horizontal = seg.reshape(hz.shape[0], -1, k).mean(axis=2)
    return vertical, horizontal


def make_scene(name="plaque_sphere", shape=(48, 64), pixel_pitch_mm=None, seed=0,
               brdf=None, supersample=None):
    """Build a named virtual object on an (H, W) half-size grid.

    Each pixel is the object averaged over its footprint, as a camera pixel averages: the
    height is the mean height, the normal that of the mean slope (dz/dx, dz/dy) and the
    albedo the mean albedo over `supersample`² sub-samples; the mask is where at least half of
    the footprint is on the object. With mean slopes and mean heights, the slopes are exactly
    the derivative of the heights (box-filtered), the relation Fourier integration assumes:
    integrating the truth's own normals gives the truth's heights up to the aliasing of what
    the grid cannot resolve (0.10 mm RMS at 64×48 px, 0.010 mm at 512×384 px, against 0.92 and
    0.21 mm with the sphere's analytic normals at the pixel centres, which are vertical at its
    rim where the sampled heights step down by several pixels' worth).
    Each pixel is still rendered as one facet: radiance is not averaged over sub-pixel normals.
    The scene of a large grid can be made a band of rows at a time (`SceneSpec.rows`), each
    band equal to the same rows of the whole.

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
    supersample : int >= 1 or None, sub-samples per pixel side; None: enough for a
        sub-sample spacing of at most FOOTPRINT_STEP_MM (at most MAX_SUPERSAMPLE).
    """
    spec = scene_spec(name, shape, pixel_pitch_mm, seed, brdf, supersample)
    return spec.rows(0, spec.shape[0])


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """What `make_scene` builds, without building it: any band of rows of the scene on demand
    (`rows`), equal to the same rows of the whole. `shape` (H, W), `pixel_pitch_mm`, `brdf` and
    `name` as in `Scene`; `supersample` the sub-samples per pixel side, `seed` the random parts'."""
    name: str
    shape: tuple
    pixel_pitch_mm: float
    brdf: dict
    supersample: int
    seed: int

    def brdf_json(self):
        """The BRDF as a JSON string (truth.npz `brdf`, docs/scan-format.md)."""
        return json.dumps({**self.brdf, "kd": "albedo (per pixel)"}, sort_keys=True)

    def rows(self, r0, r1):
        """The `Scene` of pixel rows r0..r1 (r1 excluded) of the whole scene."""
        h, w = self.shape
        if not 0 <= r0 < r1 <= h:
            raise ValueError(f"rows {r0}..{r1} are not inside the scene's {h} rows")
        k, pitch = self.supersample, self.pixel_pitch_mm
        # the random parts draw a fixed count of numbers whatever the grid: the same per band
        rng = np.random.default_rng(self.seed)
        # the surface at the corners of a k×k sub-grid of every pixel (its edges included)
        sub = pitch / k
        xs = (np.arange(w * k + 1) - w * k / 2.0) * sub
        ys = (h * k / 2.0 - np.arange(r0 * k, r1 * k + 1)) * sub
        x, y = np.meshgrid(xs, ys)
        height, inside, albedo = _surface(self.name, x, y, w * pitch, h * pitch, rng)
        del x, y
        # the mean slope over a pixel is the difference of its edges' mean heights over its size
        # (exact for the interpolated surface, however steep inside: the sphere's rim included)
        vertical, horizontal = _edge_means(height, k)
        slope_x = (vertical[:, 1:] - vertical[:, :-1]) / pitch
        slope_y = (horizontal[:-1] - horizontal[1:]) / pitch          # row 0 is the top: y up
        del vertical, horizontal
        normals = np.stack([-slope_x, -slope_y, np.ones_like(slope_x)], axis=-1)
        normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
        return Scene(_trapezoid_mean(height, k), normals,
                     _trapezoid_mean(inside.astype(np.float64), k) >= 0.5,
                     _trapezoid_mean(albedo, k), pitch,
                     {"model": self.brdf["model"], "params": dict(self.brdf.get("params", {}))},
                     name=self.name)


def scene_spec(name="plaque_sphere", shape=(48, 64), pixel_pitch_mm=None, seed=0, brdf=None,
               supersample=None):
    """The `SceneSpec` of `make_scene` with these arguments (checked here)."""
    if name not in SCENES:
        raise ValueError(f"unknown scene {name!r}; choose one of {sorted(SCENES)}")
    h, w = (int(v) for v in shape)
    if h < 8 or w < 8:
        raise ValueError(f"scene shape must be at least 8×8 half-size pixels, got {shape}")
    pitch = float(pixel_pitch_mm) if pixel_pitch_mm else 120.0 / w
    if not pitch > 0:
        raise ValueError(f"pixel_pitch_mm must be > 0, got {pixel_pitch_mm}")
    if supersample is None:
        k = int(min(MAX_SUPERSAMPLE, max(1, np.ceil(pitch / FOOTPRINT_STEP_MM - 1e-9))))
    elif int(supersample) == supersample and supersample >= 1:
        k = int(supersample)
    else:
        raise ValueError(f"supersample must be a whole number >= 1, got {supersample!r}")
    if brdf is None or isinstance(brdf, str):
        key = brdf or "mask"
        if key not in BRDF_PRESETS:
            raise ValueError(f"unknown BRDF preset {key!r}; choose one of {sorted(BRDF_PRESETS)} "
                             "or give {'model': ..., 'params': {...}}")
        brdf = BRDF_PRESETS[key]
    return SceneSpec(name, (h, w), pitch, {"model": brdf["model"], "params": dict(brdf.get("params", {}))},
                     k, int(seed))


SCENES = ("plaque_sphere", "plaque", "sphere", "plane")

# Materials of the thesis's validation scenes (§4.3.1, fig 4.21), and a matte one.
BRDF_PRESETS = {
    "mask": {"model": "cook_torrance", "params": {"sigma": 0.05, "n_i": 1.2}},
    "bust": {"model": "cook_torrance", "params": {"sigma": 0.1, "n_i": 1.3}},
    "lambert": {"model": "lambert", "params": {}},
}
