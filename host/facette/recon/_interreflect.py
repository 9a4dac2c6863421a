"""Lambertian inter-reflections removed from photometric-stereo images (after Nayar, Ikeuchi and
Kanade 1991, "Shape from interreflections").

A concave matte surface lights itself: each image holds the direct light D, which photometric
stereo models, plus what the surface gathers from the rest of itself,

    I(x) = D(x) + (ρ(x)/π) Σ_y L(y) cos θ_x cos θ_y A_y / r²_xy        (y seen from x),

with L the radiance leaving y towards x. The images already hold every bounce, so with L taken
from the images themselves one gather gives D = I − (ρ/π) K I exactly for a Lambertian surface
of known shape; the shape comes from a first photometric-stereo pass. That pass is biased by the
same inter-reflections (a crater's walls look turned towards each other), so between gathers the
shape is re-estimated from the corrected light (`passes`). On Mitsuba's path-traced scenes in
plaster (256 spp, the rig's 12 lights) least squares goes from 1.04 to 0.36 deg mean error on a
bas-relief, as with the true shape; rank_trimmed from 3.49 to 0.54 deg on a vase.

What is gathered: the irradiance is smooth, so it is computed on a coarse grid of cells (at
most `grid` cells along the longer side), each cell one element with the mean normal, albedo and
radiance of its pixels, its height from integrating the cell normals; it is upsampled bilinearly
and multiplied by each pixel's own albedo. Visibility: the segment between two cells is tested
against the cell heights. A highlight leaves in its mirror direction, not towards the
neighbours, so a cell's radiance is capped at 1.5 × its Lambertian value (+ 5 % of its albedo,
which keeps the light that lights its shadows); a missing value takes the Lambertian value.

Needs the albedo in reflectance units (ρ, as the rig's Spectralon calibration gives it; else
`reflectance_scale` converts). A glossy surface whose lobe is known (`lobe`) also gathers through
it: what its lobe mirrors and reflects, and its diffuse light through the interface (`lobe`,
`diffuse_through`). Left out: the surroundings (a table, the rig) outside the mask, and depth
discontinuities, which integration turns into walls: a wrong wall gathers light that is not there,
so no value loses more than `max_fraction` of itself.
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from facette.brdf import coupled_transmittance
from facette.errors import NotAReflectance

from ._integrate import integrate_frankot_chellappa1988
from ._ps_robust import ps_rank_trimmed

__all__ = ["remove_interreflections", "without_interreflections", "IR_GRID", "IR_MAX_FRACTION",
           "IR_PASSES", "IR_SKIP_P95"]

IR_GRID = 96           # cells along the longer side: 0.3 s at 64x64 cells on 2 cores (relief, 12 lights)
IR_MAX_FRACTION = 0.5  # no value loses more than this share of itself
# gathers of `remove_interreflections`, the cell shape re-estimated between them: on the Mitsuba
# vase in plaster li_alternating's error is 1.09 deg after one pass and 0.50 after up to three
# (the true shape: 0.50), the glossy vase 1.73 and 1.53, the relief 0.39 and 0.36
IR_PASSES = 3
# below this share of gathered light at the 95th percentile a removal changes nothing worth its
# time (a convex object: 0; the Mitsuba shell, the least concave scene: 5.8 %)
IR_SKIP_P95 = 0.005
_SOURCE_CAP = 1.5      # a cell's radiance at most this x its Lambertian value (+ _SOURCE_FLOOR x albedo)
_SOURCE_FLOOR = 0.05


def _block_sum(a, f, hc, wc):
    """(H, W, k) -> (hc, wc, k) float32 sums over f x f blocks (zero-padded at the far edges)."""
    h, w, k = a.shape
    if (h, w) != (hc * f, wc * f):
        a = np.pad(a, [(0, hc * f - h), (0, wc * f - w), (0, 0)])
    # rows then columns: two reductions over contiguous runs (one over both axes is 3x slower)
    rows = a.reshape(hc, f, wc * f * k).sum(axis=1, dtype=np.float32)
    return rows.reshape(hc, wc, f, k).sum(axis=2)


def _cell_mean(a, keep, f, hc, wc):
    """(H, W, k) -> (hc, wc, k): the mean of `a` over the pixels of each cell where `keep`
    ((H, W) or (H, W, k) bool), NaN where a cell has none."""
    keep = np.broadcast_to(keep if keep.ndim == 3 else keep[..., None], a.shape)
    s = _block_sum(np.where(keep, a, np.float32(0)).astype(np.float32, copy=False), f, hc, wc)
    n = _block_sum(keep.astype(np.float32), f, hc, wc)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, s / n, np.nan).astype(np.float32)


def _interp_taps(n_fine, n_cells, f):
    """(i0, i1, t): linear interpolation from cell centres ((i + 0.5) f - 0.5) to the n_fine pixels,
    value = cell[i0] (1 − t) + cell[i1] t, constant beyond the first and last centres."""
    x = (np.arange(n_fine) + 0.5) / f - 0.5
    i0 = np.clip(np.floor(x).astype(int), 0, n_cells - 1)
    i1 = np.clip(i0 + 1, 0, n_cells - 1)
    return i0, i1, np.clip(x - i0, 0, 1).astype(np.float32)


def _gather_cells(i_c, ld_c, n_c, a_c, cells, z=None, lobes=None, cell_lobe=None, spec_scale=0.0):
    """((m, hc, wc, c) radiance each cell gathers from the cells it sees (`gather`), the same
    reflected towards the camera by the cells' lobes or None), the cells' radiance capped as the
    module doc says; z : cell heights in cell units (None: integrated).

    lobes : (sigmas (R,), n_is (R,), taus (R, T)) of `_lobes`, or None (a Lambertian surface);
    cell_lobe : (hc, wc) int, each cell's lobe (−1: none). A cell with a lobe: its image radiance is
    its diffuse light let out at t(n_z) (towards the camera), less its lobe's share (towards the
    camera, times spec_scale = 1 / the reflectance scale), and it mirrors its lights towards the
    cells in front of it as far as they light it (its image over its Lambertian value, at most 1);
    what it gathers is divided by the t(n·s) its albedo holds (the mean over the lights that light
    it, weighted by n·s): the Lambertian ρ/π then turns what the gather let in into the light it
    sends to the camera."""
    m, hc, wc, c = i_c.shape
    if ld_c.ndim == 2:
        shade = np.einsum("kd,hwd->khw", ld_c, n_c)
    else:
        shade = np.moveaxis(np.einsum("hwkd,hwd->hwk", ld_c, n_c), -1, 0)
    model = a_c[None] * np.clip(shade, 0, None)[..., None]
    src = np.where(np.isfinite(i_c), i_c, model)
    rr, cc = np.nonzero(cells)
    lights = np.ascontiguousarray(np.broadcast_to(ld_c, (rr.size, *ld_c.shape)) if ld_c.ndim == 2 else ld_c[rr, cc],
                                  np.float32)
    if lobes is None:
        lobes, cell_lobe = (np.zeros(1), np.ones(1), np.ones((1, 2), np.float32)), np.full((hc, wc), -1)
    sigmas, n_is, taus = lobes
    lobe_of = np.ascontiguousarray(np.where(cells, cell_lobe, -1)[rr, cc], np.int32)
    glossy = np.zeros((m, hc, wc, c), np.float32) if (lobe_of >= 0).any() else None
    lit = np.ones((rr.size, m), np.float32)
    if glossy is not None and spec_scale > 0:
        from ._interreflect_jit import specular_towards_camera
        lobe_share = np.zeros((m, hc, wc, 1), np.float32)
        lobe_share[:, rr, cc, 0] = spec_scale * specular_towards_camera(
            np.ascontiguousarray(n_c[rr, cc], np.float32), lights, lobe_of, sigmas, n_is).T
        src = np.maximum(src - lobe_share, 0)
        seen = np.isfinite(i_c)          # a cell missing in every channel counts as lit
        mean_i = np.where(seen, i_c, 0).sum(-1) / np.maximum(seen.sum(-1), 1)
        lit = np.where(seen.any(-1), np.clip(mean_i / np.maximum(model.mean(-1), 1e-6), 0, 1), 1.0)
        lit = np.ascontiguousarray(lit[:, rr, cc].T, np.float32)
    src = np.minimum(src, _SOURCE_CAP * model + _SOURCE_FLOOR * a_c[None])
    t_of = np.ones((hc, wc), np.float32)        # the transmittance towards the camera, t(n_z)
    t_in = np.ones((hc, wc), np.float32)        # the albedo's, mean t(n·s) over the lights
    mu = np.linspace(0.0, 1.0, taus.shape[1])
    lit_s = np.clip(shade, 0, None)
    for k in range(len(sigmas)):
        here = cells & (cell_lobe == k)
        t_of[here] = np.interp(n_c[..., 2][here], mu, taus[k])
        t_in[here] = ((lit_s[:, here] * np.interp(lit_s[:, here], mu, taus[k])).sum(0)
                      / np.maximum(lit_s[:, here].sum(0), 1e-6))
    src = src / np.maximum(t_of, 1e-3)[None, ..., None]
    gathered = np.zeros((m, hc, wc, c), np.float32)
    if rr.size > 1:
        from ._interreflect_jit import OFF_SURFACE, gather        # numba loads only when this runs
        if z is None:
            z = integrate_frankot_chellappa1988(n_c, 1.0, cells)
        zgrid = np.where(cells, z, OFF_SURFACE).astype(np.float32)
        rad = np.ascontiguousarray(np.moveaxis(src[:, rr, cc, :], 1, 0).reshape(rr.size, m * c), np.float32)
        g, gs = gather(rr.astype(np.float32), cc.astype(np.float32), z[rr, cc].astype(np.float32),
                       np.ascontiguousarray(n_c[rr, cc], np.float32), rad, zgrid, 48, lobe_of,
                       np.asarray(sigmas, np.float64), np.asarray(n_is, np.float64),
                       np.ascontiguousarray(taus, np.float32), lights, lit, float(spec_scale))
        gathered[:, rr, cc, :] = np.moveaxis(g.reshape(rr.size, m, c), 1, 0)
        if glossy is not None:
            glossy[:, rr, cc, :] = np.moveaxis(gs.reshape(rr.size, m, c), 1, 0)
    gathered /= np.maximum(t_in, 1e-3)[None, ..., None]
    return gathered, glossy


def _cell_lights(ld, ok, f, hc, wc):
    """The cells' light directions: ld itself for distant lights (m, 3); for per-pixel directions
    (H, W, m, 3) the cell mean, renormalised (cells off the surface take the mean over the image)."""
    if ld.ndim == 2:
        return ld
    h, w, m, _ = ld.shape
    ld_c = np.nan_to_num(_cell_mean(ld.reshape(h, w, m * 3), ok, f, hc, wc)).reshape(hc, wc, m, 3)
    mean = ld.reshape(-1, m, 3).mean(axis=0)
    norm = np.linalg.norm(ld_c, axis=-1, keepdims=True)
    return np.where(norm > 0.5, ld_c / np.maximum(norm, 1e-9),
                    mean / np.linalg.norm(mean, axis=-1, keepdims=True)).astype(np.float32)


def _lobes(lobe, lobe_map, diffuse_through, ok, f, hc, wc):
    """(sigmas (R,), n_is (R,), taus (R, T)) and each cell's lobe (hc, wc) int (−1: none, where most
    of its pixels have none) of `remove_interreflections`' lobe options, or (None, None)."""
    if lobe is None:
        return None, None
    many = lobe_map is not None
    lobes = [tuple(map(float, q)) if q is not None else None for q in (lobe if many else [lobe])]
    through = list(diffuse_through) if np.ndim(diffuse_through) else [bool(diffuse_through)] * len(lobes)
    if len(through) != len(lobes):
        raise ValueError(f"diffuse_through: one per lobe ({len(lobes)}), got {len(through)}")
    for q in lobes:
        if q is not None and (len(q) != 2 or not (q[0] > 0 and q[1] >= 1)):
            raise ValueError(f"a lobe is (σ > 0, n_i ≥ 1), got {q}")
    sigmas = np.array([q[0] if q else 0.0 for q in lobes])
    n_is = np.array([q[1] if q else 1.0 for q in lobes])
    tables = [coupled_transmittance(*q)[1] if q is not None and thru else None for q, thru in zip(lobes, through)]
    width = max((t.size for t in tables if t is not None), default=2)     # t(μ) on even cosines
    taus = np.stack([np.ones(width) if t is None else t for t in tables]).astype(np.float32)
    if not many:
        return (sigmas, n_is, taus), np.zeros((hc, wc), np.int64)
    lab = np.asarray(lobe_map)
    if lab.shape != ok.shape:
        raise ValueError(f"lobe_map {lab.shape} must be (H, W) = {ok.shape}")
    votes = np.stack([_block_sum(((lab == k) & ok)[..., None].astype(np.float32), f, hc, wc)[..., 0]
                      for k in range(-1, len(lobes))])
    return (sigmas, n_is, taus), np.argmax(votes, axis=0) - 1


def _p95(ir, i_c, cells):
    """95th percentile of the gathered share of the cells' lit values."""
    lit = cells[None, ..., None] & np.isfinite(i_c) & (i_c > 0)
    return float(np.percentile(ir[lit] / i_c[lit], 95)) if lit.any() else 0.0


def _checked(im, shape, normals, albedo, mask, reflectance_scale, max_fraction, heights, grid, passes):
    """(mask, albedo (H, W, 1 or C)) of `remove_interreflections`' inputs; ValueError with what was
    wrong. im : the images with a channel axis; shape : as given."""
    if im.ndim != 4:
        raise ValueError(f"images must be (m, H, W) or (m, H, W, C), got shape {shape}")
    _, h, w, c = im.shape
    mask = np.asarray(mask, bool)
    if mask.shape != (h, w) or np.shape(normals) != (h, w, 3):
        raise ValueError(f"mask {mask.shape} and normals {np.shape(normals)} must match the images' "
                         f"{(h, w)} (normals with 3 components)")
    alb = np.asarray(albedo, np.float32)
    alb = alb[..., None] if alb.ndim == 2 else alb
    if alb.shape[:2] != (h, w) or alb.shape[2] not in (1, c):
        raise ValueError(f"albedo {np.shape(albedo)} must be (H, W) or (H, W, {c}) for images {shape}")
    if not (reflectance_scale > 0 and np.isfinite(reflectance_scale)):
        raise ValueError(f"reflectance_scale must be a positive number, got {reflectance_scale}")
    if not 0 < max_fraction < 1:
        raise ValueError(f"max_fraction must be in (0, 1), got {max_fraction}")
    if heights is not None and np.shape(heights) != (h, w):
        raise ValueError(f"heights {np.shape(heights)} must be (H, W) = {(h, w)}")
    if int(grid) < 4:
        raise ValueError(f"grid must be at least 4 cells, got {grid}")
    if int(passes) < 1:
        raise ValueError(f"passes must be at least 1, got {passes}")
    return mask, alb


def cell_grid(normals, albedo, mask, grid):
    """The gather's cells: (ok (H, W) the pixels with a normal, f the cell's side in pixels, hc, wc,
    cells (hc, wc) those half full and facing the camera, n_c (hc, wc, 3) their unit normals,
    a_c (hc, wc, C) their mean albedo); albedo (H, W, C)."""
    h, w = mask.shape
    ok = mask & np.all(np.isfinite(normals), -1) & (np.linalg.norm(normals, axis=-1) > 0.5)
    f = max(1, int(np.ceil(max(h, w) / int(grid))))
    hc, wc = -(-h // f), -(-w // f)
    cells = _block_sum(ok[..., None].astype(np.float32), f, hc, wc)[..., 0] >= 0.5 * f * f
    n_c = np.nan_to_num(_cell_mean(np.asarray(normals, np.float32), ok, f, hc, wc))
    n_c /= np.maximum(np.linalg.norm(n_c, axis=-1, keepdims=True), 1e-9)
    cells &= n_c[..., 2] > 0
    a_c = np.nan_to_num(_cell_mean(np.ascontiguousarray(albedo, np.float32), ok, f, hc, wc))
    return ok, f, hc, wc, cells, n_c, a_c


def remove_interreflections(images, light_dirs, normals, albedo, mask, reflectance_scale=1.0,
                            grid=IR_GRID, max_fraction=IR_MAX_FRACTION, saturation=None, heights=None,
                            passes=IR_PASSES, tol_deg=0.1, lobe=None, diffuse_through=True, lobe_map=None):
    """The images with the light the surface gathers from itself taken out (module doc).

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity (as
        photometric stereo takes them); NaN / inf are missing and stay so.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel.
    normals : (H, W, 3) and albedo : (H, W) or (H, W, C), a first photometric-stereo pass
        (`PSResult.normal`, `.albedo`); mask : (H, W) bool, the surface.
    reflectance_scale : ρ = reflectance_scale x albedo (1: the albedo is a reflectance).
    grid : cells along the longer side of the gather; max_fraction : see the module doc.
    saturation : values >= this are missing (as NaN and inf): not corrected, not gathered from.
    heights : (H, W) surface heights in pixel pitches (z towards the camera), when known; by
        default the cell normals are integrated (Frankot–Chellappa).
    passes : gathers at most; between two, the cells' shape is re-estimated (rank_trimmed on the
        cells' corrected radiance: the first shape is biased by the light being removed), until
        its median change is below `tol_deg` (degrees). No second pass when under IR_SKIP_P95 of
        the cells' values at the 95th percentile is gathered light, or with fewer than 4 lights.
    lobe : (σ, n_i) of a glossy surface (a BRDF-aware pass's fit), or None. With it, besides the
        Lambertian (ρ/π) share: the light a cell reflects towards the camera through its specular
        lobe (eq 3.10); and the light each cell's lobe mirrors from the lights towards the cells in
        front of it (a glossy wall sends its highlights across: the relief in paint's removal was
        0.92x the true inter-reflected light without it, 0.96x with it, 64 px Mitsuba renders),
        counted only as far as the cell is lit (its image over its Lambertian value, at most 1: a
        cell in a cast shadow mirrors nothing); a cell's image less its lobe's share towards the
        camera is then its diffuse part.
    diffuse_through : with `lobe`, whether the diffuse part lies under the lobe's interface (the LI
        and coupled parts: it takes light in and lets it out by the interface's transmittance
        t(θ), facette.brdf.coupled_transmittance, so light travelling along the surface, at
        grazing angles, is gathered weaker than a Lambertian surface would) or beside it (False);
        one per lobe with `lobe_map`.
    lobe_map : (H, W) int, for several materials: `lobe` is then a list of (σ, n_i) or None (a
        material without a lobe), and each pixel's entry its index in it (−1: none); a cell takes
        the lobe most of its pixels have.
    Returns (corrected images, same shape, float32; info) with info = grid (cells), cell_px,
    cells, passes (per gather: median change of the shape after it, seconds), median_fraction
    and p95_fraction (share of the lit values on the surface that was gathered light), capped
    (values limited by max_fraction), seconds.
    """
    t0 = time.perf_counter()
    images = np.asarray(images)
    grey = images.ndim == 3
    im = images[..., None] if grey else images
    mask, alb = _checked(im, images.shape, normals, albedo, mask, reflectance_scale, max_fraction, heights, grid,
                         passes)
    m, h, w, c = im.shape
    alb = np.broadcast_to(alb, (h, w, c))
    ok, f, hc, wc, cells, n_c, a_c = cell_grid(normals, alb, mask, grid)
    # cell radiance, light by light (no full-size copy of the stack); NaN, inf and clipped
    # values are missing
    sat = np.float32(np.inf if saturation is None else saturation)
    def cell_radiance(k):
        with np.errstate(invalid="ignore"):
            return _cell_mean(im[k], ok[..., None] & (im[k] < sat), f, hc, wc)
    with ThreadPoolExecutor(2) as pool:                  # numpy lets the GIL go: both cores
        i_c = np.stack(list(pool.map(cell_radiance, range(m))))                      # (m, hc, wc, c)
    ld_c = _cell_lights(np.asarray(light_dirs, np.float32), ok, f, hc, wc)
    if heights is None:
        z = None
    else:
        z = np.nan_to_num(_cell_mean(np.asarray(heights, np.float32)[..., None], ok, f, hc, wc)[..., 0]) / f
    receive = a_c * np.float32(reflectance_scale / np.pi)
    lobes, cell_lobe = _lobes(lobe, lobe_map, diffuse_through, ok, f, hc, wc)
    rows = []
    for k in range(int(passes)):
        t = time.perf_counter()
        gathered, glossy = _gather_cells(i_c, ld_c, n_c, a_c, cells, z, lobes, cell_lobe, 1.0 / reflectance_scale)
        cell_ir = gathered * receive if glossy is None else gathered * receive + glossy
        row = {}
        if k + 1 < int(passes) and m >= 4 and (k > 0 or _p95(cell_ir, i_c, cells) >= IR_SKIP_P95):
            # a better shape: rank_trimmed on the cells' corrected radiance, then gather again
            direct = i_c - np.minimum(cell_ir, max_fraction * np.maximum(i_c, 0))
            ps = ps_rank_trimmed(direct, ld_c, mask=cells)
            both = cells & ps.valid
            dot = np.clip(np.sum(n_c[both] * ps.normal[both], -1), -1, 1)
            row["median_change_deg"] = float(np.degrees(np.median(np.arccos(dot)))) if both.any() else 0.0
            n_c = np.where(both[..., None], ps.normal, n_c)
            z = None                             # the given heights were the first shape's
        row["seconds"] = time.perf_counter() - t
        rows.append(row)
        if row.get("median_change_deg", 0.0) < tol_deg:
            break

    # each light's cell light interpolated to the pixels, capped and subtracted in one compiled pass
    from ._interreflect_jit import subtract_gathered
    (r0, r1, rt), (c0, c1, ct) = _interp_taps(h, hc, f), _interp_taps(w, wc, f)
    scale = np.ascontiguousarray(alb * np.float32(reflectance_scale / np.pi) * ok[..., None], np.float32)
    no_glossy = np.zeros((0, 0, c), np.float32)
    out = np.empty((m, h, w, c), np.float32)
    # the fractions reported are read on an even sample of the surface's pixels
    sample = np.flatnonzero(ok)[:: max(1, int(ok.sum()) // 20000)]

    def remove(k):
        v = np.ascontiguousarray(im[k], np.float32)
        gl = no_glossy if glossy is None else np.ascontiguousarray(glossy[k], np.float32)
        capped = subtract_gathered(v, np.ascontiguousarray(gathered[k], np.float32), gl, r0, r1, rt, c0, c1, ct,
                                   scale, ok, np.float32(max_fraction), sat, out[k])
        vs, os_ = v.reshape(-1, c)[sample], out[k].reshape(-1, c)[sample]
        with np.errstate(invalid="ignore"):
            lit = (vs > 0) & (vs < sat)
        return capped, (vs[lit] - os_[lit]) / vs[lit]

    with ThreadPoolExecutor(2) as pool:
        done = list(pool.map(remove, range(m)))
    capped = sum(d[0] for d in done)
    fr = np.concatenate([d[1] for d in done]) if done else np.zeros(0)
    info = {"grid": [int(hc), int(wc)], "cell_px": int(f), "cells": int(cells.sum()), "passes": rows,
            "median_fraction": float(np.median(fr)) if fr.size else 0.0,
            "p95_fraction": float(np.percentile(fr, 95)) if fr.size else 0.0,
            "capped": capped, "seconds": time.perf_counter() - t0}
    return (out[..., 0] if grey else out), info



def without_interreflections(images, light_dirs, mask, saturation=None, reflectance_scale=1.0, channel=None,
                             estimate=None, **options):
    """`remove_interreflections` with its first shape from rank_trimmed on the images.

    images, light_dirs, mask, saturation, channel : as `ps_rank_trimmed` (channel: the one its
    normals are solved on; None: its default); reflectance_scale and **options : as
    `remove_interreflections`, or reflectance_scale "auto": estimated from the images
    (facette.recon._interreflect_scale, for an input without a Spectralon scale), or "identified":
    the same, and nothing removed (info "scale_identified" False) when the data do not tell it.
    Returns (images, first, info): the corrected images, or the given ones when under
    IR_SKIP_P95 of the values at the 95th percentile is gathered light (info "applied" False);
    the first pass's PSResult; the removal's info. estimate : the info of the estimate a numeric
    reflectance_scale came from (its own bound is the channel it read; "scale_estimate" in info).
    Raises NotAReflectance (an InsufficientData) when reflectance_scale x albedo is no reflectance
    (its 99th percentile above 1, as with a DiLiGenT folder's relative intensities): the wrong
    amount of light would be removed without a word.
    """
    estimated = estimate
    if isinstance(reflectance_scale, str):
        if reflectance_scale not in ("auto", "identified"):
            raise ValueError("reflectance_scale must be a positive number, 'auto' or 'identified', "
                             f"got {reflectance_scale!r}")
        from ._interreflect_scale import scale_from_images, unidentified_info
        only_identified = reflectance_scale == "identified"
        first, reflectance_scale, estimated = scale_from_images(images, light_dirs, mask, saturation, channel)
        if only_identified and not estimated["identified"]:      # the data do not tell it: nothing removed
            return images, first, unidentified_info(reflectance_scale, estimated)
    else:
        first = ps_rank_trimmed(images, light_dirs, mask=mask, saturation=saturation,
                                **({} if channel is None else {"channel": channel}))
    if estimated is None and first.valid.any():
        p99 = float(np.percentile(first.albedo[first.valid].max(axis=-1), 99)) * reflectance_scale
        if p99 > 1.0:
            raise NotAReflectance(
                f"removing inter-reflections needs the albedo as a reflectance, and this one reaches "
                f"{p99:.2f} (99th percentile; a reflectance is at most 1): the light intensities are "
                "relative, not calibrated",
                hint="leave the removal out (no --interreflections), give the calibration's scale "
                     "(remove_interreflections(..., reflectance_scale=)), or let it be estimated "
                     "(reflectance_scale='auto')")
    out, info = remove_interreflections(images, light_dirs, first.normal, first.albedo, first.valid & mask,
                                        reflectance_scale=reflectance_scale, saturation=saturation, **options)
    info["applied"] = info["p95_fraction"] >= IR_SKIP_P95
    info["reflectance_scale"] = float(reflectance_scale)
    if estimated is not None:
        info["scale_estimate"] = estimated
    return (out if info["applied"] else images), first, info
