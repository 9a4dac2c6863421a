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
from scipy.ndimage import maximum_filter

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

    A point is shadowed when the height field, read along the ray towards the light one pixel
    step at a time, rises above the ray. The first NEAR_STEPS steps read the heights between
    pixels (bilinear) at the ray's own positions: a nearest pixel half a pixel off the ray sits
    on the surface's own slope, and a dome's rim (slopes up to 26 at 4288x2848 RAW) shadowed
    itself under 36-56 % of its grazing lights where n.s > 0 says it is lit. Beyond them, for a
    light at one direction for every pixel, the highest point of the rest of the ray is found
    by doubling (the maximum over steps 1..2j from those over 1..j, read j steps ahead), in
    log2(steps) passes instead of one pass per step; per-pixel directions (near LEDs) march on.
    """
    hgt = np.asarray(height_mm, float)
    hh, ww = hgt.shape
    shared = np.ndim(s) == 1
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
    top = hgt + 1e-3 * max(relief, 1e-6)          # the ray must clear the start by this
    if shared:
        # one direction: a step is the same offset for every pixel, read as shifted slices
        dr, dc, up = float(step_r.flat[0]), float(step_c.flat[0]), float(rise.flat[0])
        blocked = np.zeros((hh, ww), bool)
        for k in range(1, min(n_steps, NEAR_STEPS) + 1):
            blocked |= _shifted(hgt, k * dr, k * dc) - k * up > top
        if n_steps > NEAR_STEPS:
            far = _highest_ahead(hgt, dr, dc, up, n_steps - NEAR_STEPS)
            blocked |= _shifted(far, NEAR_STEPS * dr, NEAR_STEPS * dc) - NEAR_STEPS * up > top
    else:
        blocked = _march(hgt, top, step_r, step_c, rise, ok, n_steps)
    vis[blocked & ok] = 0.0
    return vis


def _march(hgt, top, step_r, step_c, rise, ok, n_steps):
    """Shadowed pixels for per-pixel directions: the near steps read between pixels where
    something within their reach stands above the first step, the rest the nearest pixel."""
    hh, ww = hgt.shape
    rows, cols = np.mgrid[0:hh, 0:ww].astype(float)
    blocked = np.zeros((hh, ww), bool)
    reach = maximum_filter(hgt, size=2 * NEAR_STEPS + 3, mode="nearest")
    near = np.flatnonzero(ok & (reach - np.min(rise[ok]) > top))
    r0, c0 = rows.flat[near], cols.flat[near]
    sr, sc, up, start = step_r.flat[near], step_c.flat[near], rise.flat[near], top.flat[near]
    hit = np.zeros(near.size, bool)
    for k in range(1, min(n_steps, NEAR_STEPS) + 1):
        hit |= _read(hgt, r0 + k * sr, c0 + k * sc) - k * up > start
    blocked.flat[near] = hit
    for k in range(NEAR_STEPS + 1, n_steps + 1):
        r = np.clip(np.rint(rows + k * step_r).astype(int), -1, hh)
        c = np.clip(np.rint(cols + k * step_c).astype(int), -1, ww)
        inside = (r >= 0) & (r < hh) & (c >= 0) & (c < ww)
        ahead = np.where(inside, hgt[np.clip(r, 0, hh - 1), np.clip(c, 0, ww - 1)], _OUTSIDE)
        blocked |= ahead - k * rise > top
    return blocked


NEAR_STEPS = 16
"""Ray steps read at their own positions (see `cast_shadow_visibility`): by then the ray has
risen 16 steps, more than a pixel-wide offset on the steepest rim the simulator draws."""
_OUTSIDE = -1e300      # height of the world beyond the image: never above a ray


def _read(field, r, c):
    """field read at fractional (row, column) positions, bilinear; _OUTSIDE off the grid."""
    hh, ww = field.shape
    inside = (r >= 0) & (r <= hh - 1) & (c >= 0) & (c <= ww - 1)
    r0 = np.clip(np.floor(r).astype(int), 0, max(hh - 2, 0))
    c0 = np.clip(np.floor(c).astype(int), 0, max(ww - 2, 0))
    fr = np.clip(r - r0, 0.0, 1.0)
    fc = np.clip(c - c0, 0.0, 1.0)
    r1, c1 = np.minimum(r0 + 1, hh - 1), np.minimum(c0 + 1, ww - 1)
    top = field[r0, c0] * (1 - fc) + field[r0, c1] * fc
    bottom = field[r1, c0] * (1 - fc) + field[r1, c1] * fc
    return np.where(inside, top * (1 - fr) + bottom * fr, _OUTSIDE)


def _highest_ahead(hgt, dr, dc, rise, steps):
    """max over k = 1..K (K the power of two >= steps) of hgt(p + k d) - k rise for every
    pixel p, d = (dr, dc) one pixel step: the same maximum over k = 1..j, read j steps ahead
    and lowered by j rises, gives the one over j + 1..2j."""
    best = _shifted(hgt, dr, dc) - rise
    j = 1
    while j < steps:
        best = np.maximum(best, _shifted(best, j * dr, j * dc) - j * rise)
        j *= 2
    return best


def _shifted(field, dr, dc):
    """field read at (row + dr, column + dc) for every pixel, bilinear, _OUTSIDE off the grid
    (far below any ray): four shifted slices weighted, no gather."""
    hh, ww = field.shape
    ir, ic = int(np.floor(dr)), int(np.floor(dc))
    fr, fc = dr - ir, dc - ic
    out = np.zeros((hh, ww))
    for a, wa in ((0, 1.0 - fr), (1, fr)):
        for b, wb in ((0, 1.0 - fc), (1, fc)):
            if wa * wb == 0.0:
                continue
            part = np.full((hh, ww), _OUTSIDE)
            r, c = ir + a, ic + b
            src = field[max(r, 0):hh + min(r, 0), max(c, 0):ww + min(c, 0)]
            part[max(-r, 0):hh - max(r, 0), max(-c, 0):ww - max(c, 0)] = src
            out += wa * wb * part
    return out


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
        # a distant LED's one direction (not its broadcast): the shadows' fast path
        ray = s if leds.positions_mm is not None else leds.directions[i]
        vis = cast_shadow_visibility(scene.height_mm, scene.pixel_pitch_mm, ray) if shadows else 1.0
        out[i] = k * leds.intensities[i] * (f * (cos * vis * falloff)[..., None])
    return np.clip(np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0, None)
