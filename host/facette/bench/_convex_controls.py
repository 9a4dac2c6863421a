"""Convex controls for `facette bench concave --controls`: textured objects with no inter-reflections
in their images, on which "auto" must identify none (their normals unchanged).

- Local-shading renders made here (Lambert and a weak Blinn-Phong highlight, attached shadows only,
  as bench size's slab): bench._large's relief slab (240 x 160 px) with albedo patterns that are
  smooth (the slab's own), sharp (a checkerboard), blotched (discs), fine (a short sinusoid) or
  flat; the slab with twice the slopes; a glossier slab; a sphere with the same patterns.
- A satin sphere lying on a plane (facette.recon.synthetic's Cook-Torrance satin, local shading, cast
  shadows, no inter-reflections): its lobe's share grows toward the rim, where the light the plane
  would send grows too (the full suite's relighting scene, the last withdrawn rule's false positive),
  at 128 x 128 and at that test's 40 x 48.
- Mitsuba 3 renders (bench._mitsuba_scenes, its textured K_d: stripes and a spot): the sphere
  (convex: path tracing adds nothing) and the relief with the direct light only (max_depth 2).
Each returns the scene as bench.concave's renders do: images, light_dirs, mask, normals (truth).
"""
import numpy as np

from facette.bench._large import relief_surface
from facette.bench._mitsuba_scenes import render_scene

__all__ = ["local_controls", "mitsuba_controls"]

KS, SHININESS = 0.04, 40.0      # bench size's slab's highlight
BASE = np.array([0.62, 0.52, 0.42])


def _pattern(kind, u, v):
    """(H, W) in [0, 1]: the albedo's variation."""
    if kind == "smooth":                    # bench size's slab's own
        return 0.5 + 0.5 * np.sin(2 * np.pi * (2.0 * u + 1.5 * v))
    if kind == "sharp":
        return ((np.floor(u * 6) + np.floor(v * 6)) % 2).astype(float)
    if kind == "fine":
        return 0.5 + 0.5 * np.sin(2 * np.pi * (9.0 * u - 7.0 * v))
    if kind == "blotch":
        rng, t = np.random.default_rng(3), np.zeros_like(u)
        for _ in range(12):
            cu, cv, r = rng.uniform(0, 1.5), rng.uniform(0, 1), rng.uniform(0.03, 0.15)
            t = np.maximum(t, ((u - cu) ** 2 + (v - cv) ** 2 < r * r).astype(float))
        return t
    return np.zeros_like(u)                 # flat


def _shade(n, rho, lights, ks):
    """(m, H, W, 3) float32: Lambert plus a Blinn-Phong highlight, attached shadows only."""
    halves = lights + np.array([0.0, 0.0, 1.0])
    halves /= np.linalg.norm(halves, axis=1, keepdims=True)
    out = []
    for l, hv in zip(lights, halves):
        nl = np.maximum(n @ l, 0.0)
        spec = ks * np.maximum(n @ hv, 0.0) ** SHININESS * (nl > 0)
        out.append(rho / np.pi * nl[..., None] + spec[..., None])
    return np.stack(out).astype(np.float32)


def _relief(kind, lights, slopes=1.0, ks=KS, w=240, h=160):
    rows, cols = np.arange(h), np.arange(w)
    _, n = relief_surface(rows, cols, min(w, h))
    if slopes != 1.0:
        n = n.copy()
        n[..., :2] *= slopes
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
    u, v = np.meshgrid((cols + 0.5) / min(w, h), (rows + 0.5) / min(w, h))
    rho = BASE * (0.55 + 0.45 * _pattern(kind, u, v))[..., None]
    return {"images": _shade(n, rho, lights, ks), "light_dirs": lights, "mask": np.ones((h, w), bool),
            "normals": n.astype(np.float32)}


def _sphere(kind, lights, side=160):
    yy, xx = np.mgrid[0:side, 0:side]
    x, y = (xx + 0.5) / side * 2 - 1, 1 - (yy + 0.5) / side * 2
    mask = x * x + y * y < 0.9 ** 2
    n = np.stack([x, y, np.sqrt(np.clip(0.81 - x * x - y * y, 0, None))], -1)
    n[~mask] = (0.0, 0.0, 1.0)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    rho = BASE * (0.55 + 0.45 * _pattern(kind, (xx + 0.5) / side, (yy + 0.5) / side))[..., None]
    im = _shade(n, rho, lights, KS)
    im[:, ~mask] = 0
    return {"images": im, "light_dirs": lights, "mask": mask, "normals": n.astype(np.float32)}


def _sphere_on_plane(lights, h, w, radius):
    from facette.recon.synthetic import render, sphere_on_plane
    sc = sphere_on_plane(h, w, radius=radius)
    return {"images": render(sc, lights, "satin", albedo=(0.7, 0.6, 0.5)), "light_dirs": lights, "mask": sc.mask,
            "normals": sc.normals.astype(np.float32)}


def local_controls(lights):
    """{name: scene} of the local-shading controls under `lights` (m, 3)."""
    out = {f"slab/{k}": _relief(k, lights) for k in ("smooth", "sharp", "blotch", "fine", "flat")}
    out["slab x2 slopes/smooth"] = _relief("smooth", lights, slopes=2.0)
    out["slab glossier/smooth"] = _relief("smooth", lights, ks=0.3)
    out.update({f"sphere/{k}": _sphere(k, lights) for k in ("smooth", "sharp", "blotch")})
    out["satin sphere on plane"] = _sphere_on_plane(lights, 128, 128, 40)
    out["satin sphere on plane 40x48"] = _sphere_on_plane(lights, 40, 48, 14)
    return out


def mitsuba_controls(lights, cache, size=128, spp=32):
    """{name: scene} of the Mitsuba controls (textured K_d) under `lights` (m, 3), cached in `cache`."""
    out = {}
    for material in ("plaster", "paint_0.10"):
        out[f"mitsuba sphere/{material}"] = render_scene("sphere", material, size=size, spp=spp, textured=True,
                                                         lights=lights, max_depth=4, cache_dir=cache)
        out[f"mitsuba relief direct/{material}"] = render_scene("relief", material, size=size, spp=spp,
                                                                textured=True, lights=lights, max_depth=2,
                                                                cache_dir=cache)
    return out
