"""Light directions from a matte (Lambertian) sphere: the cross-check of the mirror sphere.

On a sphere of known outline every pixel's normal n is known, and a distant LED
gives E = n · b with b = (ρ/π) I s (thesis eq 4.3) wherever n·s > 0. The lit
pixels give b by least squares: its direction is the light's, its norm the
(relative) intensity. Pixels near the terminator are left out (they carry the
most shading error, and those past it are zero).
"""
from __future__ import annotations

import numpy as np

from facette.calib.mirror_sphere import Circle, fit_sphere_outline, sphere_mask

__all__ = ["matte_sphere_directions", "lambert_fit_direction"]


def _normals(shape, circle, margin):
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w]
    u = (cols - circle.cx) / circle.r
    v = -(rows - circle.cy) / circle.r
    rho2 = u * u + v * v
    inside = rho2 < margin ** 2
    n = np.stack([u, v, np.sqrt(np.clip(1 - rho2, 0, None))], -1)
    return n, inside


def lambert_fit_direction(image, circle, margin=0.95, min_cos=0.1, iterations=3, max_pixels=50_000):
    """Fit E = n·b on the lit part of a Lambertian sphere.

    image : (H, W) or (H, W, 3) linear radiance; circle : the sphere's outline.
    Pixels within `margin` × radius, with n·b̂ > `min_cos` (iterated from the pixels
    brighter than 10 % of the peak). Returns (direction (3,), |b| per channel (3,) or
    (1,), rms residual relative to |b|).
    """
    g = np.asarray(image, float)
    g = g[..., None] if g.ndim == 2 else g
    # a sphere hundreds of pixels wide: fit on a regular grid of at most `max_pixels` of it
    step = max(1, int(np.ceil(np.sqrt(np.pi * circle.r ** 2 / max_pixels))))
    if step > 1:
        g = g[::step, ::step]
        circle = Circle(circle.cx / step, circle.cy / step, circle.r / step, circle.rms)
    n, inside = _normals(g.shape[:2], circle, margin)
    lum = g.mean(axis=2)
    sel = inside & (lum > 0.1 * lum[inside].max())
    for _ in range(iterations):
        N = n[sel]
        if len(N) < 10:
            raise ValueError("too few lit pixels on the matte sphere to fit a direction: is the LED "
                             "on, and the sphere in view?")
        b, *_ = np.linalg.lstsq(N, lum[sel], rcond=None)
        s = b / np.linalg.norm(b)
        sel = inside & (n @ s > min_cos)
    N = n[sel]
    res = lum[sel] - N @ b
    scale = np.array([np.linalg.lstsq(N, g[sel][:, c], rcond=None)[0] @ s for c in range(g.shape[2])])
    return s, scale, float(np.sqrt(np.mean(res ** 2)) / np.linalg.norm(b))


def _refine_joint(lum, circle, dirs, scale, margin=0.9, min_cos=0.15, max_pixels=4000):
    """Refine the outline and every b_i = scale_i · s_i together: the shading of all the
    images pins the sphere's centre and radius better than its blurred silhouette."""
    from scipy import optimize

    m, h, w = lum.shape
    rows, cols = np.mgrid[0:h, 0:w]
    near = np.hypot(cols - circle.cx, rows - circle.cy) < margin * circle.r
    rr, cc = rows[near].astype(float), cols[near].astype(float)
    vals = lum[:, near]
    step = max(1, int(np.ceil(len(rr) / max_pixels)))   # a regular subsample bounds the Jacobian
    rr, cc, vals = rr[::step], cc[::step], vals[:, ::step].astype(np.float64)
    b0 = dirs * scale[:, None]

    def normals(q):
        u = (cc - q[0]) / q[2]
        v = -(rr - q[1]) / q[2]
        return np.stack([u, v, np.sqrt(np.clip(1 - u * u - v * v, 0, None))], -1)

    n0 = normals([circle.cx, circle.cy, circle.r])
    use = (n0 @ (b0 / np.linalg.norm(b0, axis=1, keepdims=True)).T).T > min_cos    # (m, N)

    def res(p):
        n = normals(p[:3])
        b = p[3:].reshape(m, 3)
        return ((b @ n.T) - vals)[use]
    sol = optimize.least_squares(res, np.r_[circle.cx, circle.cy, circle.r, b0.ravel()],
                                 x_scale="jac")
    cx, cy, r = sol.x[:3]
    b = sol.x[3:].reshape(m, 3)
    return Circle(float(cx), float(cy), float(r), circle.rms), b


def matte_sphere_directions(images, circle=None, refine=True):
    """Directions (m, 3), intensities (m, C) (mean over LEDs = 1 per channel), relative
    rms residuals (m,) and the sphere's Circle, from images (m, H, W[, 3]) of a matte sphere.

    The outline (`circle`) is fitted on the brightest-anywhere image (the maximum
    over LEDs, where the whole sphere is lit) unless given; with `refine`, the
    outline and all the directions are then refined together on the shading.
    """
    img = np.asarray(images)
    if img.ndim not in (3, 4):
        raise ValueError(f"images must be (m, H, W) or (m, H, W, 3), got {img.shape}")
    if circle is None:
        ref = img.max(axis=0).astype(np.float64)
        circle = fit_sphere_outline(sphere_mask(ref, dark=False), ref)
    if not isinstance(circle, Circle):
        raise ValueError("circle must be a facette.calib.mirror_sphere.Circle")
    out = [lambert_fit_direction(im, circle) for im in img]
    if refine:
        lum = np.stack([im.mean(axis=2) if im.ndim == 3 else im for im in img])
        dirs0 = np.array([o[0] for o in out])
        scale0 = np.array([o[1].mean() for o in out])
        circle, _ = _refine_joint(lum, circle, dirs0, scale0)
        out = [lambert_fit_direction(im, circle) for im in img]
    dirs = np.array([o[0] for o in out])
    inten = np.array([o[1] for o in out])
    return dirs, inten / inten.mean(axis=0, keepdims=True), np.array([o[2] for o in out]), circle
