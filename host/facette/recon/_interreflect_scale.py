"""The albedo's scale to a reflectance, estimated from the images themselves (no Spectralon).

Removing inter-reflections needs ρ, the albedo as a reflectance (how much of what reaches a wall
it sends on); a DiLiGenT folder, an RTI capture or an uncalibrated scan give the albedo times an
unknown constant c (the lights' relative intensities). The light a concave surface gathers is
proportional to ρ = albedo / c, so the scale s = 1 / c shows in the data: with too small an s the
walls still look turned towards each other and a wall's albedo grows with the light it gathers;
with too large an s too much is taken away and it shrinks. So, on the gather's cells (as
`remove_interreflections` makes them): G = the Lambertian light each cell gathers at s = 1 (linear
in s), and for each candidate s in [0, 1 / p99(albedo)] (a reflectance is at most 1) the cells'
images less s G are solved again (rank_trimmed) and log albedo regressed on the gathered share and
the tilt (1 − n_z: a glossy paint dims with tilt); the s where the share's slope crosses 0 wins
(linear between candidates; without a crossing, the smallest |slope|). Given `diffuse` (a BRDF-aware
fit's albedo, its lobe modelled: li_alternating's K_d) the growth is read on it: the slopes are moved
by the difference between its slope and the Lambertian albedo's at s = 0 (what a lobe adds to the
Lambertian albedo does not change with s; LOBE_FREE_SLOPES) and its correlation replaces the
Lambertian one (DIFFUSE_CORRELATION). The scale is identified
(SCALE_EXPLAINED, EARLY_SHARE, GATHER_CORRELATION) only when that slope starts above 0, the albedo
follows the share cell by cell (not a pattern that merely leans with it), and the removal takes most
of it away, steadily from the smallest scales on: a textured object without inter-reflections, a
dark object (too little gathered) or an albedo that is darker or brighter in the hollows for
another reason leaves it to the data's other causes, and `process` leaves the light in.
"""
import warnings

import numpy as np

from ._interreflect import IR_GRID, IR_MAX_FRACTION, _cell_lights, _cell_mean, _gather_cells, cell_grid
from ._ps_robust import ps_rank_trimmed

__all__ = ["estimate_reflectance_scale", "scale_from_images", "unidentified_info", "SCALE_CANDIDATES",
           "GATHER_QUANTILE", "SCALE_EXPLAINED", "EARLY_SHARE", "GATHER_CORRELATION",
           "DIFFUSE_CORRELATION"]

SCALE_CANDIDATES = 9      # candidate scales from 0 to the largest a reflectance allows
GATHER_QUANTILE = 0.75     # the residual is read on the cells above this quantile of gathered share
# the data identify the scale (info "identified") when the albedo grows with the gathered share as the
# images are (slope > 0 at s = 0: the sign inter-reflections leave) and the removal at the largest
# scale a reflectance allows takes at least this share of that growth away (it is the gathered light
# that makes it). Chosen on Mitsuba's concave renders (12 rig lights): where the removal helps (plaster,
# paint 0.10) the slope starts above 0 and at most 2 % of it is left (grooves in plaster 1.6 %; the
# others cross 0); where it hurts (dark paint 0.05, K_d 0.05: bowl 0.48 -> 4.62 deg, grooves
# 2.36 -> 4.26) 52 % and 70 % are left, or the slope starts below 0; 0.75 lies between (a growth the
# removal barely touches comes from something else: a sheen, a darker paint in the hollows)
SCALE_EXPLAINED = 0.75
# and the slope falls from the first scales on, as the gathered light (linear in s) makes it: by the
# middle candidate at least this share of its whole fall. A slope flat until the largest scales and
# falling only there is over-removal (values near the cap), not the light gathered: facette's satin
# sphere on a plane (no inter-reflections rendered) kept 0.35 -> 0.30 by the middle, then -0.79 (the
# removal took its normals from 1.1 to 5.2 deg); the Mitsuba concave renders (12 lights) fall
# 44-82 % of the way by the middle
EARLY_SHARE = 0.25
# and the albedo follows the gathered share cell by cell: their partial correlation (the tilt's
# linear part taken out of both) across the cells, before anything is removed, is at least this.
# Gathered light makes the albedo grow wherever the share grows; an albedo pattern that only happens
# to lean with the share (a textured relief without inter-reflections) barely correlates, and the
# slope tests above then pass on a weak lean that any removal takes away. Chosen on renders: the
# concave Mitsuba scenes the removal helps (12 rig lights, plaster and paint 0.10) correlate 0.28-0.96;
# textured reliefs rendered without inter-reflections (smooth, sharp, fine, blotched albedo; flat;
# 12 and 96 lights) 0.03-0.25, and those the slope tests alone passed 0.03-0.11 (bench size's slab
# 0.085 at 1200 x 800 and 0.107 at 64 x 48: the withdrawn rule's false positive)
GATHER_CORRELATION = 0.2
# the same correlation read on a BRDF-aware fit's diffuse albedo (`diffuse`: li_alternating's K_d, its
# lobe modelled) replaces it where one is given: the Lambertian albedo still carries what a lobe adds,
# and a lobe's share can grow where the gathered share does (a satin sphere on a plane, local shading
# only, no inter-reflections: 0.25 on the Lambertian albedo, -0.57 on K_d). Chosen on renders (12 rig
# lights; CHOSEN_ON in the note): the concave scenes the removal helps 0.41-0.95, the convex controls
# at most DIFFUSE_CONTROLS_MAX
DIFFUSE_CORRELATION = 0.3
# the slopes moved to the lobe-free albedo's (module doc): a glossy concave object whose lobe darkens
# its Lambertian albedo where it gathers most reads as one that gathers nothing (Mitsuba bowl in paint
# 0.10, 12 rig lights: Lambertian slope -0.14, K_d's +0.65, its correlation 0.92), and the crossing
# lands where the lobe-free growth is gone (craters in paint 0.10: the scale 2.03 -> 0.68, truth 1)
LOBE_FREE_SLOPES = True


def _partial_correlation(y, x, z):
    """Pearson correlation of y and x, each less its least-squares fit on [1, z]."""
    d = np.stack([np.ones_like(z), z], 1)
    ry = y - d @ np.linalg.lstsq(d, y, rcond=None)[0]
    rx = x - d @ np.linalg.lstsq(d, x, rcond=None)[0]
    den = float(np.sqrt((ry @ ry) * (rx @ rx)))
    return float(ry @ rx) / den if den > 0 else 0.0


def _cells(images, light_dirs, normals, albedo, mask, saturation, grid):
    """(i_c (m, hc, wc, 1), ld_c, n_c, a_c (hc, wc, 1), cells) of one channel, as `remove_interreflections`."""
    m = images.shape[0]
    ok, f, hc, wc, cells, n_c, a_c = cell_grid(normals, np.asarray(albedo, np.float32)[..., None], mask, grid)
    sat = np.float32(np.inf if saturation is None else saturation)
    with np.errstate(invalid="ignore"):
        i_c = np.stack([_cell_mean(images[k][..., None], (ok & (images[k] < sat))[..., None], f, hc, wc)
                        for k in range(m)])
    return i_c, _cell_lights(np.asarray(light_dirs, np.float32), ok, f, hc, wc), n_c, a_c, cells


def _diffuse_follows(diffuse, ch, normals, mask, grid, share, strong, tilt):
    """(the partial correlation (tilt removed), the slope) of log `diffuse` (a fit's albedo after its
    lobe is modelled, (H, W) or (H, W, C)) with the gathered share, over the strong cells it has."""
    d = np.asarray(diffuse, np.float32)
    d = d[..., min(ch, d.shape[-1] - 1)] if d.ndim == 3 else d
    keep = mask & np.isfinite(d) & (d > 0)
    *_, d_c = cell_grid(normals, np.where(keep, d, 0)[..., None], keep, grid)
    d_c = d_c[..., 0][strong]
    good = d_c > 0
    if good.sum() < 8:
        return 0.0, 0.0
    y, x, z = np.log(d_c[good]), share[strong][good], tilt[good]
    slope = float(np.linalg.lstsq(np.stack([np.ones_like(x), x, z], 1), y, rcond=None)[0][1])
    return _partial_correlation(y, x, z), slope


def estimate_reflectance_scale(images, light_dirs, normals, albedo, mask, saturation=None, channel=None,
                               grid=IR_GRID, candidates=SCALE_CANDIDATES, diffuse=None):
    """(scale, info): ρ = scale x albedo (module doc).

    images : (m, H, W) or (m, H, W, C) as photometric stereo takes them; channel : the one read
    (default: green of three, else the last); normals, albedo (H, W) or (H, W, C), mask : a first
    pass's. info: "scale", "max_scale" (1 / the albedo's 99th percentile), "costs" (the share's
    slope per candidate), "gathered_p95" (the gathered share at the 95th percentile at the
    chosen scale; 0 on a convex object, whose scale the data cannot tell: then max_scale / 2),
    "identified" (whether the data tell the scale, SCALE_EXPLAINED), "growth_kept" (the slope at
    the largest scale over the slope at 0) and "gather_correlation" (GATHER_CORRELATION's figure).
    """
    im = np.asarray(images)
    ch = 0
    if im.ndim == 4:
        ch = channel if channel is not None else (1 if im.shape[-1] == 3 else im.shape[-1] - 1)
        im, alb = im[..., ch], (albedo[..., min(ch, albedo.shape[-1] - 1)] if np.ndim(albedo) == 3 else albedo)
    else:
        alb = albedo[..., 0] if np.ndim(albedo) == 3 else albedo
    mask = np.asarray(mask, bool)
    lit = mask & np.isfinite(alb) & (alb > 0)
    p99 = float(np.percentile(alb[lit], 99)) if lit.any() else 1.0
    max_scale = 1.0 / max(p99, 1e-12)
    i_c, ld_c, n_c, a_c, cells = _cells(im, light_dirs, normals, alb, mask, saturation, grid)
    gathered, _ = _gather_cells(i_c, ld_c, n_c, a_c, cells)
    g1 = gathered * a_c[None] / np.float32(np.pi)            # the gathered light at scale 1
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # a cell dark under every light: NaN
        share = np.nanmedian(np.where(i_c > 0, g1 / i_c, np.nan), axis=0)[..., 0]
    info = {"max_scale": max_scale, "costs": []}
    strong = cells & np.isfinite(share)
    if strong.sum() < 8 or not np.any(share[strong] * max_scale > 0.005):
        info.update(scale=max_scale / 2, gathered_p95=0.0, identified=False, growth_kept=None, gather_correlation=None,
                    diffuse_correlation=None)
        return max_scale / 2, info
    scales = np.linspace(0.0, max_scale, int(candidates))
    x = share[strong]
    tilt = 1.0 - n_c[..., 2][strong]        # a glossy paint's diffuse light dims with the tilt: its own term
    slopes, follows = [], 0.0
    for s in scales:
        direct = i_c - np.minimum(s * g1, IR_MAX_FRACTION * np.maximum(i_c, 0))
        ps = ps_rank_trimmed(direct, ld_c, mask=cells)
        good = ps.valid[strong] & (ps.albedo[strong][..., 0] > 0)
        la = np.log(np.where(good, ps.albedo[strong][..., 0], 1.0))[good]
        design = np.stack([np.ones(good.sum()), x[good], tilt[good]], 1)
        if s == 0:          # nothing removed yet: how closely the albedo follows the gathered share
            follows = _partial_correlation(la, x[good], tilt[good])
        slopes.append(float(np.linalg.lstsq(design, la, rcond=None)[0][1]))
    lobe_free = None
    if diffuse is not None:     # the slopes read as the lobe-free albedo's (LOBE_FREE_SLOPES)
        lobe_free, lobe_free_slope = _diffuse_follows(diffuse, ch, normals, mask, grid, share, strong, tilt)
        if LOBE_FREE_SLOPES:
            slopes = [x + lobe_free_slope - slopes[0] for x in slopes]
    costs = slopes
    down = [k for k in range(len(slopes) - 1) if slopes[k] > 0 >= slopes[k + 1]]
    if down:       # the albedo no longer grows with the gathered share: linear between the two
        k = down[0]
        scale = float(scales[k] + (scales[k + 1] - scales[k]) * slopes[k] / (slopes[k] - slopes[k + 1]))
    else:
        scale = float(scales[int(np.argmin(np.abs(slopes)))])
    # no crossing above 0 (nothing gathered that the albedo shows): a scale that removes next to nothing
    scale = max(scale, 1e-3 * max_scale)
    kept = slopes[-1] / slopes[0] if slopes[0] > 0 else np.inf       # the growth the removal leaves
    info.update(scale=scale, costs=[round(c, 6) for c in costs], growth_kept=round(float(kept), 4),
                gather_correlation=round(follows, 4),
                diffuse_correlation=None if lobe_free is None else round(lobe_free, 4),
                identified=bool(slopes[0] > 0 and kept <= 1.0 - SCALE_EXPLAINED
                                and (follows >= GATHER_CORRELATION if lobe_free is None else
                                     lobe_free >= DIFFUSE_CORRELATION)
                                and slopes[0] - slopes[len(slopes) // 2] >= EARLY_SHARE * (slopes[0] - slopes[-1])),
                gathered_p95=float(np.percentile(share[cells & np.isfinite(share)] * scale, 95)))
    return scale, info


def scale_from_images(images, light_dirs, mask, saturation=None, channel=None, diffuse=None):
    """(first, scale, info): a rank_trimmed pass (`ps_rank_trimmed` with these arguments) and
    `estimate_reflectance_scale` on its normals and albedo (and `diffuse`, as it takes it)."""
    first = ps_rank_trimmed(images, light_dirs, mask=mask, saturation=saturation,
                            **({} if channel is None else {"channel": channel}))
    scale, info = estimate_reflectance_scale(images, light_dirs, first.normal, first.albedo, first.valid & mask,
                                             saturation, channel, diffuse=diffuse)
    return first, scale, info


def unidentified_info(scale, estimate):
    """The info of a removal left out because the data do not tell the scale (nothing removed)."""
    return {"applied": False, "scale_identified": False, "scale_estimate": estimate,
            "reflectance_scale": float(scale), "median_fraction": 0.0, "p95_fraction": 0.0, "passes": [],
            "grid": [0, 0], "capped": 0, "seconds": 0.0}
