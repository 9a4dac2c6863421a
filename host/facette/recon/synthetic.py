"""Synthetic scenes with known normals, rendered in numpy, for tests and benchmarks.

A sphere resting on a plane, seen orthographically from +z, lit by distant lights;
Lambert or Cook-Torrance (Beckmann D, dielectric Fresnel, Torrance-Sparrow G), with
attached shadows (s.n <= 0) and the sphere's cast shadow on the plane.
"""
from dataclasses import dataclass

import numpy as np

__all__ = ["thesis_light_directions", "Scene", "sphere_on_plane", "render", "angular_error_deg"]


def thesis_light_directions():
    """The rig's 12 directions (thesis §4.2): theta 15 deg at phi 30, 90, ..., 330 and
    theta 30 deg at phi 0, 60, ..., 300, alternating. Returns (12, 3) unit vectors."""
    d = []
    for k in range(6):
        for theta, phi in ((15.0, 30.0 + 60 * k), (30.0, 60.0 * k)):
            t, p = np.radians(theta), np.radians(phi)
            d.append([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    return np.array(d)


@dataclass
class Scene:
    """normals (H, W, 3) unit; height (H, W) in pixels; mask (H, W) bool (sphere and plane);
    sphere (H, W) bool; centre (row, col) and radius in pixels."""
    normals: np.ndarray
    height: np.ndarray
    mask: np.ndarray
    sphere: np.ndarray
    centre: tuple
    radius: float


def sphere_on_plane(h=128, w=128, radius=None, border=0):
    """A hemisphere of `radius` px (default 0.35 min(h, w)) centred on a plane z = 0.

    `border` px on each side are left out of the mask (0: whole image)."""
    radius = 0.35 * min(h, w) if radius is None else float(radius)
    r, c = (h - 1) / 2, (w - 1) / 2
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = xx - c, -(yy - r)          # camera frame: y up, row 0 at the top
    d2 = x * x + y * y
    sphere = d2 < (radius * 0.999) ** 2
    z = np.where(sphere, np.sqrt(np.maximum(radius ** 2 - d2, 0)), 0.0)
    n = np.zeros((h, w, 3))
    n[..., 2] = 1.0
    n[sphere, 0] = x[sphere] / radius
    n[sphere, 1] = y[sphere] / radius
    n[sphere, 2] = z[sphere] / radius
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    mask = np.ones((h, w), bool)
    if border:
        mask[:border] = mask[-border:] = False
        mask[:, :border] = mask[:, -border:] = False
    return Scene(n, z, mask, sphere, (r, c), radius)


def _fresnel_dielectric(c, n_i):
    g2 = n_i ** 2 + c ** 2 - 1
    g = np.sqrt(np.maximum(g2, 0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1) / (c * (g - c) + 1)
    return 0.5 * a * a * (1 + b * b)


def _cook_torrance(n, s, o, kd, ks, sigma, n_i):
    """BRDF (1/sr), (..., C): kd/pi + ks * F D G / (4 (n.s)(n.o)), Beckmann D."""
    h = s + o
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    ns = np.sum(n * s, -1)
    no = np.sum(n * o, -1)
    nh = np.clip(np.sum(n * h, -1), 1e-6, 1)
    oh = np.clip(np.sum(o * h, -1), 1e-6, 1)
    tan2 = (1 - nh ** 2) / nh ** 2
    d = np.exp(-tan2 / sigma ** 2) / (np.pi * sigma ** 2 * nh ** 4)
    g = np.minimum(1, np.minimum(2 * nh * np.maximum(no, 0) / oh, 2 * nh * np.maximum(ns, 0) / oh))
    f = _fresnel_dielectric(np.sum(s * h, -1), n_i)
    with np.errstate(divide="ignore", invalid="ignore"):
        spec = np.where((ns > 0) & (no > 0), ks * f * d * g / (4 * ns * no), 0.0)
    return np.asarray(kd)[None] / np.pi + spec[..., None]


def render(scene, light_dirs, material="glossy", albedo=(0.6, 0.5, 0.4), noise=0.0,
           cast_shadows=True, rng=None, ks=1.0):
    """Images (m, H, W, 3) float32 of `scene` under unit-intensity distant lights.

    material : "matte" (Lambert), "satin" (Cook-Torrance sigma 0.15, n_i 1.3, ks 1), or
        "glossy" (sigma 0.05, n_i 1.2, ks 1: the thesis's mask, §4.3.1).
    noise : relative Gaussian noise (standard deviation as a fraction of each value).
    ks : weight of the specular term (1: a dielectric interface; larger: stronger highlights).
    E = f(s, o, n) (n.s)^+ per channel (radiance for unit irradiance, orthographic view).
    """
    rng = np.random.default_rng(0) if rng is None else rng
    params = {"matte": None, "satin": (0.15, 1.3), "glossy": (0.05, 1.2)}
    if material not in params:
        raise ValueError(f"unknown material {material!r}; choose from {', '.join(params)}")
    n = scene.normals
    o = np.array([0.0, 0.0, 1.0])
    kd = np.asarray(albedo, dtype=np.float64)
    h, w = n.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    px, py = xx - scene.centre[1], -(yy - scene.centre[0])
    imgs = []
    for s in np.asarray(light_dirs, dtype=np.float64):
        ns = np.maximum(n @ s, 0.0)
        if params[material] is None:
            f = np.broadcast_to(kd / np.pi, (h, w, 3))
        else:
            sigma, n_i = params[material]
            f = _cook_torrance(n, np.broadcast_to(s, n.shape), np.broadcast_to(o, n.shape),
                               kd, ks, sigma, n_i)
        img = f * ns[..., None]
        if cast_shadows:
            # plane point P (z = 0) is shadowed if the ray P + t s (t > 0) meets the sphere
            pz = np.zeros_like(px)
            b = px * s[0] + py * s[1] + pz * s[2]
            cc = px ** 2 + py ** 2 + pz ** 2 - scene.radius ** 2
            hit = (b * b - cc > 0) & (-b + np.sqrt(np.maximum(b * b - cc, 0)) > 0) & ~scene.sphere
            img[hit] = 0.0
        if noise:
            img = img * (1 + noise * rng.standard_normal(img.shape))
        imgs.append(np.maximum(img, 0))
    return np.stack(imgs).astype(np.float32)


def angular_error_deg(n_est, n_true, mask=None):
    """Angle (deg) between unit normal maps (..., 3); restricted to `mask` when given."""
    dot = np.clip(np.sum(n_est * n_true, axis=-1), -1, 1)
    err = np.degrees(np.arccos(dot))
    return err[mask] if mask is not None else err
