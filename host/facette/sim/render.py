"""Render what the simulated camera sees under each LED (numpy, vectorised).

For LED ``i`` driven at 1 mA for 1 µs, the photo-electrons collected by the
half-size pixel p (one RGGB cell) per channel c are

    e_i(p, c) = K · I_i(c) · f(s, o; n_p) · max(n_p · s, 0) · V_i(p) · (d0 / r)²      [e- / (mA·µs)]

with f the BRDF (1/sr) evaluated in the local frame of the normal n_p, o = +z
(orthographic camera), s the direction towards the LED (per pixel for near
lights, with the (d0/r)² fall-off), V the cast-shadow visibility from the height
field, and K = `electrons_per_mA_s` · π · 1e-6 (so that a white Lambertian
surface facing a nominal LED collects `electrons_per_mA_s` electrons per mA·s).
This is the image model of thesis eq 4.3 generalised to any BRDF (eq 2.11 with
α = 0: orthographic projection).
"""
from __future__ import annotations

import numpy as np

from facette.brdf import get as brdf_get

__all__ = ["radiance_per_led", "brdf_function", "cast_shadow_visibility", "to_local"]


def brdf_function(name):
    """The BRDF callable for `name` (a `facette.brdf.MODELS` name)."""
    return brdf_get(name)


def to_local(v, n):
    """Express vectors `v` (..., 3) in the frame of unit normals `n` (..., 3): z = n."""
    a = np.where(np.abs(n[..., :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(n, a)
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    b = np.cross(n, t)
    return np.stack([np.sum(v * t, -1), np.sum(v * b, -1), np.sum(v * n, -1)], axis=-1)


def cast_shadow_visibility(height_mm, pixel_pitch_mm, s):
    """1 where the LED is visible from the surface point, 0 where the height field
    occludes it. `s` : (3,) or (H, W, 3) unit direction(s) towards the light.
    Marches one pixel at a time towards the light in the image plane."""
    hgt = np.asarray(height_mm, float)
    hh, ww = hgt.shape
    s = np.broadcast_to(np.asarray(s, float), (hh, ww, 3))
    horiz = np.hypot(s[..., 0], s[..., 1])
    vis = np.ones((hh, ww))
    ok = horiz > 1e-9
    if not ok.any():
        return vis
    step_c = np.where(ok, s[..., 0] / np.maximum(horiz, 1e-12), 0.0)
    step_r = np.where(ok, -s[..., 1] / np.maximum(horiz, 1e-12), 0.0)   # y up, rows down
    rise = pixel_pitch_mm * s[..., 2] / np.maximum(horiz, 1e-12)          # mm per pixel step
    relief = hgt.max() - hgt.min()
    n_steps = int(np.ceil(relief / max(pixel_pitch_mm * np.min(s[..., 2][ok] / horiz[ok]), 1e-9))) + 1
    n_steps = min(n_steps, hh + ww)
    rows, cols = np.mgrid[0:hh, 0:ww].astype(float)
    eps = 1e-3 * max(relief, 1e-6)
    for k in range(1, n_steps + 1):
        r = rows + k * step_r
        c = cols + k * step_c
        inside = (r >= 0) & (r <= hh - 1) & (c >= 0) & (c <= ww - 1)
        ri = np.clip(np.rint(r).astype(int), 0, hh - 1)
        ci = np.clip(np.rint(c).astype(int), 0, ww - 1)
        blocked = inside & ok & (hgt[ri, ci] > hgt + k * rise + eps)
        vis[blocked] = 0.0
    return vis


def radiance_per_led(scene, leds, electrons_per_mA_s=20.0, shadows=True):
    """Photo-electrons per (mA·µs) for each LED, per half-size pixel and channel.

    Parameters
    ----------
    scene : facette.sim.scene.Scene
    leds : facette.sim.lights.LedArray (m LEDs)
    electrons_per_mA_s : float > 0, electrons a white Lambertian pixel facing a
        nominal LED collects per mA·s of drive (sets the exposure scale)
    shadows : bool, compute cast shadows

    Returns
    -------
    ndarray (m, H, W, 3) float64, e- per mA·µs, >= 0
    """
    if not electrons_per_mA_s > 0:
        raise ValueError(f"electrons_per_mA_s must be > 0, got {electrons_per_mA_s}")
    fn = brdf_function(scene.brdf["model"])
    params = dict(scene.brdf.get("params", {}))
    n = scene.normals
    hh, ww = scene.shape
    o_loc = to_local(np.broadcast_to([0.0, 0.0, 1.0], n.shape), n)
    x, y = scene.coordinates_mm()
    points = np.stack([x, y, scene.height_mm], axis=-1)
    k = electrons_per_mA_s * np.pi * 1e-6
    out = np.zeros((len(leds), hh, ww, 3))
    for i in range(len(leds)):
        if leds.positions_mm is not None:
            v = leds.positions_mm[i] - points
            r = np.linalg.norm(v, axis=-1, keepdims=True)
            s = v / r
            falloff = (leds.distance_mm / r[..., 0]) ** 2
        else:
            s = np.broadcast_to(leds.directions[i], n.shape)
            falloff = 1.0
        s_loc = to_local(s, n)
        # K_d enters linearly for Lambert and Cook–Torrance: evaluate at K_d = 0 and 1
        # and mix per pixel with the albedo map (approximate for the LI model).
        f0 = np.asarray(fn(s_loc, o_loc, kd=[0.0], **params))[..., 0]
        f1 = np.asarray(fn(s_loc, o_loc, kd=[1.0], **params))[..., 0]
        f = f0[..., None] + scene.albedo * (f1 - f0)[..., None]
        cos = np.clip(s_loc[..., 2], 0.0, None)
        vis = cast_shadow_visibility(scene.height_mm, scene.pixel_pitch_mm, s) if shadows else 1.0
        out[i] = k * leds.intensities[i] * (f * (cos * vis * falloff)[..., None])
    return np.clip(np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0, None)
