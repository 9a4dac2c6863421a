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

__all__ = ["radiance_per_led", "radiance_rows", "led_reach", "brdf_function", "cast_shadow_visibility",
           "ray_reach", "merge_reach", "shadow_window", "to_local"]


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
    return _visibility(hgt, pixel_pitch_mm, s, ray_reach(hgt, pixel_pitch_mm, s))


def ray_reach(height_mm, pixel_pitch_mm, s, shape=None):
    """What a shadow march of the whole image needs to know of it: (relief mm, steps, lowest
    rise mm per step) for direction(s) `s` ((3,), or per pixel (h, W, 3) for some rows of an
    image of `shape` (H, W), default the height field's). Per-pixel directions given a band at
    a time combine with `merge_reach`."""
    hgt = np.asarray(height_mm, float)
    hh, ww = shape if shape is not None else hgt.shape
    s = np.asarray(s, float)
    horiz = np.hypot(s[..., 0], s[..., 1])
    ok = horiz > 1e-9
    if not ok.any():
        return (float(hgt.max() - hgt.min()), 0, np.inf)
    rise = pixel_pitch_mm * s[..., 2] / np.maximum(horiz, 1e-12)
    return (float(hgt.max() - hgt.min()), (hh, ww), float(np.min(s[..., 2][ok] / horiz[ok])),
            float(np.min(rise[ok])))


def merge_reach(parts, relief):
    """`ray_reach` of the whole from those of its bands (the relief of the whole given)."""
    parts = [p for p in parts if p[1] != 0]
    if not parts:
        return (relief, 0, np.inf)
    return (relief, parts[0][1], min(p[2] for p in parts), min(p[3] for p in parts))


def _n_steps(reach, pixel_pitch_mm):
    relief, shape, tan_elev = reach[0], reach[1], reach[2]
    if shape == 0:
        return 0
    n_steps = int(np.ceil(relief / max(pixel_pitch_mm * tan_elev, 1e-9))) + 1
    return min(n_steps, shape[0] + shape[1])


def shadow_window(rows, n_rows, reach, pixel_pitch_mm, s):
    """Rows (a, b) of the height field whose shadow march gives, on rows r0..r1, what the march
    of the whole gives: the band and the rows its rays read (for one direction `s`, towards the
    light only; per-pixel directions both ways)."""
    r0, r1 = rows
    steps = _n_steps(reach, pixel_pitch_mm)
    if steps == 0:
        return r0, r1
    s = np.asarray(s, float)
    if s.ndim == 1:
        horiz = float(np.hypot(s[0], s[1]))
        dr = -s[1] / max(horiz, 1e-12)
        doubled = 1
        while doubled < steps - NEAR_STEPS:
            doubled *= 2
        # the doubling reads up to `doubled` steps ahead, each bilinear read one row more
        reach_rows = int(np.ceil((NEAR_STEPS + doubled + 2) * abs(dr))) + 2 * int(np.log2(doubled)) + 8
        before, after = (2, reach_rows) if dr >= 0 else (reach_rows, 2)
    else:
        before = after = steps + 2 * NEAR_STEPS + 8
    return max(r0 - before, 0), min(r1 + after, n_rows)


def _visibility(hgt, pixel_pitch_mm, s, reach):
    """`cast_shadow_visibility` of `hgt` (some rows of an image) with the `ray_reach` of the
    whole image: equal to the whole's on the rows of `shadow_window`."""
    hh, ww = hgt.shape
    shared = np.ndim(s) == 1
    # one direction: its steps worked out once (the same arithmetic as per pixel)
    s = np.asarray(s, float).reshape(1, 1, 3) if shared else np.broadcast_to(s, (hh, ww, 3))
    horiz = np.hypot(s[..., 0], s[..., 1])
    vis = np.ones((hh, ww))
    ok = horiz > 1e-9
    if not ok.any():
        return vis
    step_c = np.where(ok, s[..., 0] / np.maximum(horiz, 1e-12), 0.0)
    step_r = np.where(ok, -s[..., 1] / np.maximum(horiz, 1e-12), 0.0)   # y up, rows down
    rise = pixel_pitch_mm * s[..., 2] / np.maximum(horiz, 1e-12)          # mm per pixel step
    relief = reach[0]
    n_steps = _n_steps(reach, pixel_pitch_mm)
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
        blocked = _march(hgt, top, step_r, step_c, rise, ok, n_steps, reach[3])
    vis[blocked & np.broadcast_to(ok, (hh, ww))] = 0.0
    return vis


def _march(hgt, top, step_r, step_c, rise, ok, n_steps, lowest_rise):
    """Shadowed pixels for per-pixel directions: the near steps read between pixels where
    something within their reach stands above the first step, the rest the nearest pixel."""
    hh, ww = hgt.shape
    rows, cols = np.mgrid[0:hh, 0:ww].astype(float)
    blocked = np.zeros((hh, ww), bool)
    reach = maximum_filter(hgt, size=2 * NEAR_STEPS + 3, mode="nearest")
    near = np.flatnonzero(ok & (reach - lowest_rise > top))
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
            if abs(r) >= hh or abs(c) >= ww:      # read wholly off the grid
                out += wa * wb * part
                continue
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
    ndarray (m, H, W, 3) float64, e- per mA·µs, >= 0 (`radiance_rows` gives any band of rows
    of one LED's, equal to the same rows of this)
    """
    _check_scale(electrons_per_mA_s)
    out = np.zeros((len(leds), *scene.shape, 3))
    for i in range(len(leds)):
        reach = led_reach(scene.height_mm, scene.pixel_pitch_mm, leds, i) if shadows else None
        out[i] = radiance_rows(scene, leds, i, 0, scene.height_mm, reach, electrons_per_mA_s)
    return out


def _check_scale(electrons_per_mA_s):
    if not electrons_per_mA_s > 0:
        raise ValueError(f"electrons_per_mA_s must be > 0, got {electrons_per_mA_s}")


def _points(height_mm, pixel_pitch_mm, r0, r1):
    """(rows, W, 3) surface points, mm, of rows r0..r1 of the height field (as
    `Scene.coordinates_mm` places the pixel centres)."""
    hh, ww = height_mm.shape
    x = (np.arange(ww) - (ww - 1) / 2.0) * pixel_pitch_mm
    y = ((hh - 1) / 2.0 - np.arange(r0, r1)) * pixel_pitch_mm
    x, y = np.meshgrid(x, y)
    return np.stack([x, y, height_mm[r0:r1]], axis=-1)


def _near_rays(leds, i, points):
    """(directions towards near LED i, (d0 / r)² fall-off) at `points` (..., 3) mm."""
    v = leds.positions_mm[i] - points
    r = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / r, (leds.distance_mm / r[..., 0]) ** 2


def led_reach(height_mm, pixel_pitch_mm, leds, i, band_rows=None):
    """`ray_reach` of LED i over the whole height field (H, W); a near LED's per-pixel
    directions are made `band_rows` rows at a time (None: all at once)."""
    hgt = np.asarray(height_mm, float)
    if leds.positions_mm is None:
        return ray_reach(hgt, pixel_pitch_mm, leds.directions[i])
    hh = hgt.shape[0]
    step = hh if band_rows is None else max(int(band_rows), 1)
    parts = []
    for r0 in range(0, hh, step):
        s, _ = _near_rays(leds, i, _points(hgt, pixel_pitch_mm, r0, min(r0 + step, hh)))
        parts.append(ray_reach(hgt[r0:r0 + step], pixel_pitch_mm, s, shape=hgt.shape))
    return merge_reach(parts, float(hgt.max() - hgt.min()))


def radiance_rows(band, leds, i, row0, height_mm, reach, electrons_per_mA_s=20.0):
    """Photo-electrons per (mA·µs) of LED i on the rows of `band`, a `Scene` of rows
    row0.. of a scene whose whole height field is `height_mm` (H, W): (rows, W, 3) float64,
    >= 0, equal to the same rows of `radiance_per_led`'s. `reach`: the LED's `led_reach` over
    the whole height field, or None for no cast shadows."""
    _check_scale(electrons_per_mA_s)
    hgt = np.asarray(height_mm, float)
    fn = brdf_function(band.brdf["model"])
    params = dict(band.brdf.get("params", {}))
    n = band.normals
    pitch = band.pixel_pitch_mm
    rows = (row0, row0 + band.shape[0])
    o_loc = to_local(np.broadcast_to([0.0, 0.0, 1.0], n.shape), n)
    k = electrons_per_mA_s * np.pi * 1e-6
    if leds.positions_mm is not None:
        s, falloff = _near_rays(leds, i, _points(hgt, pitch, *rows))
    else:
        s = np.broadcast_to(leds.directions[i], n.shape)
        falloff = 1.0
    s_loc = to_local(s, n)
    # K_d enters linearly for Lambert and Cook–Torrance: evaluate at K_d = 0 and 1
    # and mix per pixel with the albedo map (approximate for the LI model).
    f0 = np.asarray(fn(s_loc, o_loc, kd=[0.0], **params))[..., 0]
    f1 = np.asarray(fn(s_loc, o_loc, kd=[1.0], **params))[..., 0]
    f = f0[..., None] + band.albedo * (f1 - f0)[..., None]
    del f0, f1, o_loc
    cos = np.clip(s_loc[..., 2], 0.0, None)
    vis = 1.0
    if reach is not None:
        # a distant LED's one direction (not its broadcast): the shadows' fast path
        ray = leds.directions[i] if leds.positions_mm is None else None
        a, b = shadow_window(rows, hgt.shape[0], reach, pitch, ray if ray is not None else s)
        if ray is None:
            ray = s if (a, b) == rows else _near_rays(leds, i, _points(hgt, pitch, a, b))[0]
        vis = _visibility(hgt[a:b], pitch, ray, reach)[rows[0] - a:rows[1] - a]
    out = k * leds.intensities[i] * (f * (cos * vis * falloff)[..., None])
    return np.clip(np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0, None)
