"""`process`'s normals where photometric stereo measured none (no light above the noise: a bare
metal between its highlights, a cavity's floor). Photometric stereo solves only the pixels whose
data carry a normal (`pipeline._quality.carried`); the others are interpolated from the measured ones around them
(`facette.recon.fill_normals`, on a bare metal kept out of its lobes' reach: `metal_cones`) when
an output shows the shape, and said in the notes. mask.png marks them grey (128,
`facette.io.png.write_mask`: the object, its normal interpolated; 255 measured; 0 outside). The
reflectance samples and the BRDF fit read photometric stereo's own valid pixels, never these.
"""
import time

import numpy as np

from facette._memory import disk_array, release
from facette.fit import is_metal
from facette.recon import fill_normals

__all__ = ["normals_of", "fill_in_rows", "metal_cones", "SHAPE_OUTPUTS", "DARK_STEP", "FILL_ROWS"]

SHAPE_OUTPUTS = frozenset({"normals", "mask", "height", "mesh", "gltf", "report"})   # what shows the shape
DARK_STEP = 8      # metal_cones reads the noise floor on every 8th dark pixel


def normals_of(res, inp, ps):
    """res.normals, albedo, mask and filled from photometric stereo's result `ps` (a PSResult) on
    `inp` (a PSInput): res.mask the measured pixels of the input mask and the filled ones, res.filled
    the (H, W) bool map of the filled ones (None when none were)."""
    measured = ps.valid & inp.mask
    res.normals, res.albedo, res.filled = ps.normal, ps.albedo, None
    if SHAPE_OUTPUTS & set(res.options.get("outputs", SHAPE_OUTPUTS)) and _has_gap(ps.normal, measured, inp.mask):
        t0 = time.perf_counter()
        cones = metal_cones(inp, ps, measured)
        normals, filled = fill_in_rows(ps.normal, measured, inp.mask, avoid=cones)
        if filled.any():
            res.normals, res.filled = normals, filled
            res.timings["fill"] = time.perf_counter() - t0
            n = int(filled.sum())
            res.notes.append(
                f"normals interpolated at {n:,} pixels ({100 * n / max(int(inp.mask.sum()), 1):.1f} % of the object) "
                "that no light reached above the noise (a bare metal between its highlights, shadow in every "
                "photograph): harmonic from the measured normals around them"
                + ("" if cones is None else f", kept {np.degrees(np.arccos(cones[1])):.0f}° or more from every "
                   "light's half vector where the metal's lobe would have lit them")
                + ", grey in mask.png, left out of the reflectance samples and the BRDF fit")
    res.mask = measured if res.filled is None else measured | res.filled


# rows a piece of the fill takes at least (it grows to the next row no gap crosses): its working set,
# ~40 bytes per pixel of the piece (the fill's indices and copies), not of the image
FILL_ROWS = 256


def fill_in_rows(normals, measured, region, avoid=None, rows=FILL_ROWS):
    """`fill_normals` a piece of rows at a time, the pieces cut between rows that no piece of the gap
    crosses (4-neighbours, as its harmonic fill joins them), each with one row of its neighbours'
    measured normals around it (their gap pixels left out: not joined to this piece's): the same
    equations as the whole image's, solved per piece. normals may be a map on disk: the copy is then
    one too, written a piece at a time. Returns (normals, filled) as `fill_normals`."""
    h = region.shape[0]
    gap = np.zeros(region.shape, bool)
    for r0 in range(0, h, rows):
        ok = measured[r0:r0 + rows] & np.isfinite(np.asarray(normals[r0:r0 + rows])).all(-1)
        release(normals)
        gap[r0:r0 + rows] = region[r0:r0 + rows] & ~ok
    joined = (gap[:-1] & gap[1:]).any(1)           # joined[r]: the gap crosses from row r to row r + 1
    on_disk = isinstance(normals, np.memmap)
    out = disk_array(normals.shape, np.float32) if on_disk else np.array(normals, np.float32, copy=True)
    filled = np.zeros(region.shape, bool)
    r0 = 0
    while r0 < h:
        r1 = min(h, r0 + rows)
        while r1 < h and joined[r1 - 1]:
            r1 += 1
        if on_disk:
            out[r0:r1] = normals[r0:r1]
        if gap[r0:r1].any():
            a, b = max(0, r0 - 1), min(h, r1 + 1)
            own = np.zeros(b - a, bool)
            own[r0 - a:r1 - a] = True
            piece_region = region[a:b] & (own[:, None] | ~gap[a:b])      # the context rows' gap: not this piece's
            cones = None if avoid is None else (avoid[0], avoid[1], avoid[2][a:b])
            part, more = fill_normals(np.asarray(normals[a:b]), measured[a:b], piece_region, avoid=cones)
            out[r0:r1] = part[r0 - a:r1 - a]
            filled[r0:r1] = more[r0 - a:r1 - a]
        release(normals)
        release(out)
        r0 = r1
    return out, filled


def _has_gap(normals, measured, region, rows=256):
    """True when `fill_normals` would have a pixel to fill: one of `region` without a finite measured
    normal. Read a band of rows at a time: over bands the normals are a map on disk, which a whole
    read would make resident (12 bytes per pixel, 1.2 GB at 100 MP; most captures have no gap)."""
    for r0 in range(0, region.shape[0], rows):
        ok = measured[r0:r0 + rows] & np.isfinite(np.asarray(normals[r0:r0 + rows])).all(-1)
        release(normals)
        if (region[r0:r0 + rows] & ~ok).any():
            return True
    return False


def metal_cones(inp, ps, measured):
    """`fill_normals`' `avoid` for a bare metal, or None: the half vectors of the lights and the
    lobe's reach, on the pixels dark under every light. A metal has no diffuse part, so such a
    pixel's normal lies where no light's lobe reaches: more than θ from every half vector h_j,
    where the Beckmann lobe D ∝ exp(−tan²θ / σ²) has fallen from the lit pixels' typical peak to
    the noise floor, tan²θ = σ² ln R (R = the median over measured pixels of their brightest value,
    over the 90th percentile of the dark pixels' values, green). Only for li_alternating's
    metal lobes (every material's index a metal's), distant lights and images held whole.
    Mitsuba, 12 rig lights, over the object (plain fill → this): gold sphere θ 38°, 19.0° → 9.6°;
    aluminium sphere 54°, 6.0° → 2.7°; gold relief 27°, 9.9° → 9.7°; the gold sphere with noise at
    10⁻³ / 10⁻⁴ of its highlights θ 34° / 35°, 8.8° / 8.4°."""
    fits = [(m["sigma"], m["n_i"]) for m in (ps.info.get("materials", []) if ps.method == "li_alternating" else [])
            if m.get("sigma") is not None and m.get("n_i") is not None]
    L = inp.light_dirs
    if not fits or not all(is_metal(n_i) for _, n_i in fits) or inp.images is None or inp.usable is None or \
            np.ndim(L) != 2:
        return None
    sigma = min(s for s, _ in fits)                    # the narrower lobe: the smaller cones
    g = inp.images[..., 1 if inp.images.shape[-1] > 1 else 0]
    dark = inp.mask & ~measured & ~inp.usable.any(0) & np.isfinite(g).all(0)
    if not dark.any() or not measured.any():
        return None
    peak = float(np.median(np.where(np.isnan(g[:, measured]), np.inf, g[:, measured]).max(0)))
    floor = float(np.percentile(np.abs(g.reshape(len(g), -1)[:, np.flatnonzero(dark.ravel())[::DARK_STEP]]), 90))
    ratio = peak / floor if floor > 0 else np.inf
    if not ratio > np.e:
        return None
    # a noiseless render has no floor: the reach is where D has fallen by 10¹² (float32 images' range)
    theta = np.arctan(sigma * np.sqrt(np.log(min(ratio, 1e12))))
    h = np.asarray(L, np.float64) + [0.0, 0.0, 1.0]     # the half vectors (towards the camera: +z)
    return h / np.linalg.norm(h, axis=1, keepdims=True), float(np.cos(theta)), dark

