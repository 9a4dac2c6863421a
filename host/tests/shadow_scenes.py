"""Concave height fields rendered analytically with their cast shadows (for the shadow tests).

The shadows are found by marching each light's ray on the analytic heights at 1/4 pixel steps,
independently of facette.recon._shadows. A hidden light still leaves `fill` x its unhidden value
(the light the walls send into a shadow): too bright to be told by darkness alone.
"""
import numpy as np

__all__ = ["groove_scene"]


def _heights(x, y, kind):
    if kind == "groove":     # a parabolic groove along y, 0.35 of the width deep per half-width
        return -18.0 * np.maximum(0.0, 1 - ((x - 48.0) / 16.0) ** 2)
    r = np.hypot(x - 48.0, y + 48.0)             # a bowl
    return -20.0 * np.maximum(0.0, 1 - (r / 26.0) ** 2)


def groove_scene(kind="groove", size=96, lights=None, fill=0.4, albedo=0.7):
    """dict: images (m, H, W), light_dirs (m, 3), normals (H, W, 3), mask, hidden (m, H, W) truth."""
    if lights is None:
        th, ph = np.meshgrid(np.radians([20.0, 35.0, 50.0]), np.radians(np.arange(0, 360, 30.0)))
        lights = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    rows, cols = np.mgrid[0:size, 0:size].astype(float)
    x, y = cols, -rows                            # camera frame: y up, rows down
    eps = 1e-3
    zx = (_heights(x + eps, y, kind) - _heights(x - eps, y, kind)) / (2 * eps)
    zy = (_heights(x, y + eps, kind) - _heights(x, y - eps, kind)) / (2 * eps)
    n = np.stack([-zx, -zy, np.ones_like(zx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    z0 = _heights(x, y, kind)
    images, hidden = [], []
    for s in lights:
        h = np.hypot(s[0], s[1])
        hid = np.zeros((size, size), bool)
        if h > 1e-9:
            for t in np.arange(0.25, 40.0, 0.25):        # the walls are at most 40 px away
                xs, ys = x + t * s[0] / h, y + t * s[1] / h
                inside = (xs >= 0) & (xs <= size - 1) & (-ys >= 0) & (-ys <= size - 1)
                hid |= inside & (_heights(xs, ys, kind) > z0 + t * s[2] / h)
        shade = albedo * np.clip(n @ s, 0, None)
        images.append(np.where(hid, fill * shade, shade))
        hidden.append(hid)
    return {"images": np.stack(images).astype(np.float32), "light_dirs": np.asarray(lights, float),
            "normals": n.astype(np.float32), "mask": np.ones((size, size), bool), "hidden": np.stack(hidden)}
