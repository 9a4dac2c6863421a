"""Light directions and LED positions from a mirror (chrome) sphere.

Orthographic camera, view direction v = (0, 0, 1) (towards the camera), camera
frame x right, y up, z to the camera; image row 0 is the top, so a pixel (col,
row) on a sphere of centre (cx, cy) and radius R (px) has the normal

    n = ((col − cx)/R, −(row − cy)/R, √(1 − ...)).

The LED seen as a highlight at n lies in the mirror direction l = 2(n·v)n − v.
A highlight located to σ px on a sphere of R px gives about 1.44°·σ·(100/R) of
direction error (REFERENCE §6).

Near-light model: the highlight is the ray from the sphere point X = C + R n
towards l; rays from two or more placements of the sphere meet at the LED
(`light_positions_from_rays`).
"""
from __future__ import annotations

import dataclasses

import cv2
import numpy as np
from scipy import ndimage, optimize

from facette.calib._sphere_rays import _normal_at, directions_from_origin, light_positions_from_rays, sphere_rays

__all__ = ["Circle", "Highlight", "fit_circle", "sphere_mask", "fit_sphere_outline",
           "find_sphere_outline", "highlight_centroid", "mirror_direction", "mirror_sphere_directions",
           "light_positions_from_rays", "sphere_rays", "directions_from_origin"]


@dataclasses.dataclass
class Circle:
    """A sphere's outline in pixels: centre (cx = column, cy = row), radius r, and
    rms the rms distance of the edge points to the circle (px)."""
    cx: float
    cy: float
    r: float
    rms: float = 0.0


@dataclasses.dataclass
class Highlight:
    """A highlight's centroid (x = column, y = row, px), its peak value, whether it
    holds saturated pixels, and its area (px)."""
    x: float
    y: float
    peak: float
    saturated: bool
    area: int


def fit_circle(points):
    """Least-squares circle through points (N, 2) as (x, y): algebraic (Kåsa) start,
    then geometric distances. Returns Circle."""
    p = np.asarray(points, float)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3:
        raise ValueError(f"need at least 3 points (N, 2) to fit a circle, got shape {p.shape}")
    A = np.c_[2 * p, np.ones(len(p))]
    b = np.sum(p * p, axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, b, rcond=None)
    r0 = np.sqrt(max(c + cx * cx + cy * cy, 1e-12))

    def res(q):
        return np.hypot(p[:, 0] - q[0], p[:, 1] - q[1]) - q[2]
    sol = optimize.least_squares(res, [cx, cy, r0], method="lm")
    cx, cy, r = sol.x
    return Circle(float(cx), float(cy), float(abs(r)), float(np.sqrt(np.mean(sol.fun ** 2))))


def sphere_mask(image, dark=True):
    """The sphere's silhouette in an image (H, W) or (H, W, 3): bool (H, W).

    The mirror sphere is dark on the lit card (`dark=True`); a matte sphere is
    bright on a dark card (`dark=False`). Otsu threshold, the largest connected
    region, holes (the highlights) filled.
    """
    g = np.asarray(image, float)
    if g.ndim == 3:
        g = g.mean(axis=2)
    if g.ndim != 2 or not np.all(np.isfinite(g)):
        raise ValueError(f"need a finite (H, W) or (H, W, 3) image, got shape {g.shape}")
    lo, hi = np.percentile(g, [1, 99])
    if hi <= lo:                      # a sphere under 1 % of the frame: use the full range
        lo, hi = float(g.min()), float(g.max())
    if hi <= lo:
        raise ValueError("the image is uniform: no sphere in view (place the sphere under the "
                         "camera, or check that the LEDs light the card)")
    # Otsu on a histogram clipped to the 1–99 % range (highlights would dominate).
    hist, edges = np.histogram(np.clip(g, lo, hi), bins=256, range=(lo, hi))
    mids = 0.5 * (edges[1:] + edges[:-1])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * mids) / np.maximum(w0, 1)
    m1 = (np.sum(hist * mids) - np.cumsum(hist * mids)) / np.maximum(w1, 1)
    t = mids[np.argmax(w0 * w1 * (m0 - m1) ** 2)]
    fg = g < t if dark else g > t
    lab, n = ndimage.label(fg)
    if n == 0:
        raise ValueError("no sphere found in the image")
    # the largest region that does not touch the frame (the card may be dark at its corners)
    sizes = ndimage.sum(fg, lab, index=np.arange(1, n + 1))
    border = set(np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]]).tolist())
    order = np.argsort(sizes)[::-1]
    pick = next((i + 1 for i in order if (i + 1) not in border), None)
    if pick is None:
        raise ValueError("the sphere touches the edge of the frame: centre it under the camera")
    return ndimage.binary_fill_holes(lab == pick)


def fit_sphere_outline(mask, image=None, min_radius_px=8):
    """Circle of a sphere's silhouette, sub-pixel.

    Edge points are taken between each inside pixel and its outside 4-neighbour:
    at the midpoint for a bare mask, or where the image crosses the level halfway
    between the sphere's and the card's typical values when `image` is given
    (sub-pixel). A geometric circle fit follows (`fit_circle`), then points further
    than 2 px from it (highlights touching the rim, dust) are dropped and it is refit.
    """
    mask = np.asarray(mask, bool)
    if mask.ndim != 2:
        raise ValueError(f"mask must be (H, W), got {mask.shape}")
    g = None
    if image is not None:
        g = np.asarray(image, float)
        g = g.mean(axis=2) if g.ndim == 3 else g
    pts = []
    h, w = mask.shape
    for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        shifted = np.zeros_like(mask)
        src = mask[max(-dr, 0):h - max(dr, 0), max(-dc, 0):w - max(dc, 0)]
        shifted[max(dr, 0):h - max(-dr, 0), max(dc, 0):w - max(-dc, 0)] = src
        # pixels outside whose neighbour at (−dr, −dc) is inside
        rr, cc = np.nonzero(shifted & ~mask)
        ri, ci = rr - dr, cc - dc
        t = np.full(rr.shape, 0.5)
        if g is not None:
            # local level: halfway between the values 2 px further in and 2 px further out,
            # so a rim whose brightness varies around the sphere is still found
            r_in = np.clip(ri - 2 * dr, 0, h - 1)
            c_in = np.clip(ci - 2 * dc, 0, w - 1)
            r_out = np.clip(rr + 2 * dr, 0, h - 1)
            c_out = np.clip(cc + 2 * dc, 0, w - 1)
            level = 0.5 * (g[r_in, c_in] + g[r_out, c_out])
            gi, go = g[ri, ci], g[rr, cc]
            with np.errstate(divide="ignore", invalid="ignore"):
                tt = (level - gi) / (go - gi)
            ok = np.isfinite(tt) & (tt >= -0.5) & (tt <= 1.5)
            t = np.where(ok, tt, 0.5)
        pts.append(np.c_[ci + t * dc, ri + t * dr])
    pts = np.concatenate(pts)
    if len(pts) < 12:
        raise ValueError("the sphere is too small in the image to fit its outline")
    c = fit_circle(pts)
    d = np.abs(np.hypot(pts[:, 0] - c.cx, pts[:, 1] - c.cy) - c.r)
    if np.any(d > 2.0) and np.sum(d <= 2.0) >= 12:
        c = fit_circle(pts[d <= 2.0])
    if c.r < min_radius_px:
        raise ValueError(f"the sphere is only {c.r:.1f} px in radius (need ≥ {min_radius_px}): "
                         "use a larger sphere or a longer focal length")
    return c


def _circle_from_card(ref, points):
    """The card method (a dark sphere on a lit card, `sphere_mask`), or None when it does not
    apply: no region off the frame's edge, a region that is not a disc (dark patches of the
    background joined to it), or one that leaves out the highlights."""
    try:
        region = sphere_mask(ref, dark=True)
        c = fit_sphere_outline(region, ref)
    except ValueError:
        return None
    rows, cols = np.nonzero(region)
    disc_area = np.pi * c.r * c.r
    inside = np.hypot(cols - c.cx, rows - c.cy) < c.r + 1.0
    # a disc: (almost) every pixel of the region within the circle, and the circle filled
    if inside.mean() < 0.99 or abs(len(rows) - disc_area) > 0.03 * disc_area + 2 * np.pi * c.r:
        return None
    if c.rms > 0.02 * c.r + 0.5 or _share_inside(c, points) < 0.9:
        return None
    return c


def _share_inside(circle, points, margin=0.98):
    if points is None or not len(points):
        return 1.0
    p = np.asarray(points, float)
    return float(np.mean(np.hypot(p[:, 0] - circle.cx, p[:, 1] - circle.cy) < margin * circle.r))


def _log_image(ref):
    """The image as 8 bits on a log scale, smoothed: a chrome sphere's faint rim on a dark
    background and a lit card's edge both give a gradient there."""
    g = np.log1p(np.maximum(ref, 0) / max(float(np.percentile(ref, 50)), 1e-6 * float(ref.max()), 1e-12))
    lo, hi = float(g.min()), float(np.percentile(g, 99.5))
    u = np.clip(255 * (g - lo) / max(hi - lo, 1e-12), 0, 255).astype(np.uint8)
    return cv2.GaussianBlur(u, (5, 5), 1.5)


def _refine_on_edges(logimg, c, search_px=4.0, n_angles=720):
    """Sub-pixel circle from the strongest radial change near a first circle `c`: for each of
    `n_angles` rays from its centre, the radius within ±`search_px` where the smoothed log image
    changes fastest, either way (a busy background is brighter than the sphere here, darker
    there), to a parabola's peak; the half of the rays with the strongest edges is kept (a rim
    lost in a dark background gives none), and `fit_circle` is repeated with the points further
    than 1 px from the last circle dropped (the background's own edges that cross a ray)."""
    g = logimg.astype(float)
    th = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    rr = c.r + np.arange(-search_px, search_px + 0.25, 0.5)
    xs = c.cx + np.cos(th)[:, None] * rr[None]
    ys = c.cy + np.sin(th)[:, None] * rr[None]
    d = np.abs(np.gradient(ndimage.map_coordinates(g, [ys, xs], order=1, mode="nearest"), axis=1))
    i = np.arange(n_angles)
    k = np.clip(np.argmax(d, axis=1), 1, len(rr) - 2)
    y0, y1, y2 = d[i, k - 1], d[i, k], d[i, k + 1]
    den = y0 - 2 * y1 + y2
    off = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    r_edge = rr[k] + 0.5 * np.clip(off, -1, 1)
    keep = (y1 >= np.median(y1)) & (y1 > 0) & (k > 1) & (k < len(rr) - 2)
    if keep.sum() < 24:
        return c
    pts = np.c_[c.cx + np.cos(th[keep]) * r_edge[keep], c.cy + np.sin(th[keep]) * r_edge[keep]]
    f = fit_circle(pts)
    for tol in (2.0, 1.0, 1.0):
        near = np.abs(np.hypot(pts[:, 0] - f.cx, pts[:, 1] - f.cy) - f.r) <= tol
        if near.sum() < 24:
            break
        f = fit_circle(pts[near])
    return f if abs(f.r - c.r) < search_px and np.hypot(f.cx - c.cx, f.cy - c.cy) < search_px else c


def find_sphere_outline(ref, highlight_points=None, min_radius_px=8):
    """A mirror sphere's outline in an image, on a lit card, a dark or a busy background.

    ref : (H, W) or (H, W, 3) image of the sphere (the mean of its photographs: every
        highlight at once, the rim lit from every side).
    highlight_points : (m, 2) (x = column, y = row) points that lie on the sphere (each
        photograph's brightest change, see `mirror_sphere_directions`), or None. A candidate
        outline must hold 90 % of them.

    The card method first (`sphere_mask`: the dark sphere on a lit card, Otsu); where it does not
    apply (a dark background, where the sphere is barely darker than what surrounds it, or a
    textured one), circles voted by the gradient of the log image (Hough), the strongest
    candidate that holds the highlights, refined to sub-pixel on the strongest half of its edge
    (`_refine_on_edges`). Returns a Circle; ValueError when no outline is found (give the sphere
    as a circle or a mask then).
    """
    g = np.asarray(ref, float)
    g = g.mean(axis=2) if g.ndim == 3 else g
    if g.ndim != 2 or not np.all(np.isfinite(g)):
        raise ValueError(f"need a finite (H, W) or (H, W, 3) image, got shape {g.shape}")
    c = _circle_from_card(g, highlight_points)
    if c is not None:
        return c
    u = _log_image(g)
    h, w = g.shape
    for votes in (30, 20, 12):
        found = cv2.HoughCircles(u, cv2.HOUGH_GRADIENT, dp=1, minDist=max(8, min(h, w) // 10),
                                 param1=40, param2=votes, minRadius=int(min_radius_px),
                                 maxRadius=min(h, w) // 2)
        if found is None:
            continue
        for cx, cy, r in found[0][:10]:
            cand = Circle(float(cx), float(cy), float(r))
            if (cx - r < -1 or cy - r < -1 or cx + r > w or cy + r > h
                    or _share_inside(cand, highlight_points) < 0.9):
                continue
            return _refine_on_edges(u, cand)
    raise ValueError("no sphere outline found in the photographs: give it as a circle "
                     "(--sphere cx,cy,r) or a mask, or photograph the sphere whole, off the frame's edge")


def highlight_points(images, box=None):
    """Where each photograph is brightest against the others: (m, 2) (x = column, y = row), the
    peak of (image − median of the photographs), smoothed by 1 px (one hot pixel does not win).
    A fixed reflection (a window, the lamp stand) is in every photograph and drops out. `box`
    (r0, r1, c0, c1) limits the search."""
    img = np.asarray(images, float)
    if img.ndim == 4:
        img = img.mean(axis=3)
    if box is not None:
        r0, r1, c0, c1 = box
        img = img[:, r0:r1, c0:c1]
    else:
        r0 = c0 = 0
    med = np.median(img, axis=0) if len(img) >= 3 else img.min(axis=0)
    pts = []
    for im in img:
        d = ndimage.gaussian_filter(im - med, 1.0)
        k = np.unravel_index(int(np.argmax(d)), d.shape)
        pts.append((k[1] + c0, k[0] + r0))
    return np.array(pts, float)


def highlight_centroid(image, circle, white_level=None, threshold=0.5, margin=0.98, background=None):
    """Sub-pixel centroid of the brightest highlight inside the sphere.

    `background` (H, W), when given, is taken off first (the median of the photographs: what the
    sphere mirrors under every light, a window or the lamp stand, is not a highlight). Pixels above `threshold` × the peak in the region connected to the peak, weighted
    by their value above the threshold. Saturated pixels (≥ `white_level`, when
    given) all weigh the same: the centroid of a clipped, symmetric blob is still
    its centre, and the result says it was saturated.
    """
    g = np.asarray(image, float)
    # a pixel is saturated when any of its channels is
    clipped = None if white_level is None else (g >= white_level if g.ndim == 2
                                                 else np.any(g >= white_level, axis=2))
    g = g.mean(axis=2) if g.ndim == 3 else g
    if background is not None:
        g = g - np.asarray(background, float)
    h, w = g.shape
    rows, cols = np.mgrid[0:h, 0:w]
    inside = np.hypot(cols - circle.cx, rows - circle.cy) < margin * circle.r
    vals = np.where(inside, g, -np.inf)
    k = int(np.argmax(vals))
    peak = float(vals.flat[k])
    base = float(np.median(g[inside]))
    if not np.isfinite(peak) or peak <= base:
        raise ValueError("no highlight on the sphere: is the LED on and the sphere in its view?")
    thr = base + threshold * (peak - base)
    lab, _ = ndimage.label(inside & (g > thr))
    core = lab == lab.flat[k]
    # weigh every pixel near the blob by its value above the sphere's level: a box-filtered
    # (pixel-integrated) blob keeps its first moment, a thresholded one does not
    blob = ndimage.binary_dilation(core, iterations=2) & inside
    wts = g[blob] - base
    sat = False
    if clipped is not None:
        s = clipped[blob]
        sat = bool(s.any())
        if sat:
            wts = np.where(s, white_level - base, wts)
    wts = np.maximum(wts, 0)
    x = float(np.sum(cols[blob] * wts) / np.sum(wts))
    y = float(np.sum(rows[blob] * wts) / np.sum(wts))
    return Highlight(x, y, peak, sat, int(core.sum()))


def mirror_direction(circle, x, y):
    """Light direction from a highlight at (x = column, y = row) on a mirror sphere.

    l = 2(n·v)n − v with v = (0, 0, 1) (orthographic). Returns a unit (3,) vector.
    """
    n = _normal_at(circle, x, y)
    v = np.array([0.0, 0.0, 1.0])
    l = 2 * (n @ v) * n - v
    return l / np.linalg.norm(l)


# A lamp mirrored in a chrome ball is a small spot; a matte ball (or an object taken for the
# sphere) is lit over a third of its disc.
MAX_HIGHLIGHT_SHARE = 0.03


def mirror_sphere_directions(images, white_level=None, outline_image=None, circle=None, mask=None):
    """Light directions from mirror-sphere images, one per LED (one highlight per photograph).

    Parameters
    ----------
    images : (m, H, W) or (m, H, W, 3) linear images of the sphere (on its card, or in the
        corner of an RTI capture on any background).
    white_level : value at which a pixel saturated (single exposures), or None (HDR).
    outline_image : image to find the silhouette in (default the mean of `images`,
        where the card is lit from every side and every highlight shows).
    circle : the sphere's outline as a `Circle` or (cx, cy, r) px, when known.
    mask : (H, W) bool of the sphere, when known (its outline is fitted: `fit_sphere_outline`).

    Returns (directions (m, 3), circle, [Highlight] * m). The outline is found otherwise by
    `find_sphere_outline` (a lit card, a dark or a busy background); with three photographs or
    more, what the sphere mirrors in all of them (their median) is taken off before each
    highlight is located. A sphere whose highlights cannot be on it is refused (ValueError,
    `_check_horizon`, `_check_given_outline`): lights below the horizon, or for a circle or mask given, highlights
    outside its disc or a rim the photographs show elsewhere.
    """
    img = np.asarray(images)
    if img.ndim not in (3, 4):
        raise ValueError(f"images must be (m, H, W) or (m, H, W, 3), got {np.shape(images)}")
    if outline_image is None:
        ref = _mean_image(img)
    else:
        ref = np.asarray(outline_image, float)
        ref = ref.mean(axis=2) if ref.ndim == 3 else ref
    given = circle is not None or mask is not None
    if circle is not None:
        circle = circle if isinstance(circle, Circle) else Circle(*[float(v) for v in circle][:3])
    elif mask is not None:
        circle = fit_sphere_outline(np.asarray(mask, bool))
    else:
        circle = find_sphere_outline(ref, highlight_points(img))
    if given:
        _check_given_outline(img, circle, ref)
    background = None
    if len(img) >= 3:                        # the median over the sphere's box only (cheap)
        h, w = img.shape[1:3]
        r0, r1 = max(int(circle.cy - circle.r) - 2, 0), min(int(circle.cy + circle.r) + 3, h)
        c0, c1 = max(int(circle.cx - circle.r) - 2, 0), min(int(circle.cx + circle.r) + 3, w)
        crop = img[:, r0:r1, c0:c1].astype(float)
        crop = crop.mean(axis=3) if crop.ndim == 4 else crop
        background = np.zeros((h, w))
        background[r0:r1, c0:c1] = np.median(crop, axis=0)
    hl = [highlight_centroid(im, circle, white_level, background=background) for im in img]
    broad = np.median([h.area for h in hl]) / (np.pi * circle.r ** 2)
    if broad > MAX_HIGHLIGHT_SHARE:
        raise ValueError(f"the highlights cover {100 * broad:.0f} % of the sphere at ({circle.cx:.0f}, "
                         f"{circle.cy:.0f}) px, radius {circle.r:.0f} px (a mirror's cover well under "
                         f"{100 * MAX_HIGHLIGHT_SHARE:.0f} %): that is no mirror sphere")
    dirs = np.array([mirror_direction(circle, h.x, h.y) for h in hl])
    _check_horizon(circle, dirs)
    return dirs, circle, hl


# A light below the horizon cannot light the object the camera sees; a few degrees of
# grazing light lost to a highlight's centroid are allowed.
HORIZON_TOLERANCE_DEG = 3.0
# A circle given that the found outline beats on the rim's evidence (`_rim_support`: the share
# of rays whose strongest change lies at the rim) is refused. The renders of
# tests/calib/test_mirror_sphere.py: the outline on a lit card or a dark background 0.88-1.00, a
# circle 4 px off 0.21-0.33, the centre's x and y swapped 0.05; on a checkerboard, whose own edges
# win most rays, 0.09 for the outline, 0.03-0.06 off it: any lead of the found outline decides.
RIM_SUPPORT_LEAD = 0.0


def _rim_support(ref, c, n_angles=360):
    """Share of rays from c's centre whose strongest radial change of the log image within
    ±r/2 lies within 2 px of c's rim."""
    g = _log_image(ref).astype(float)
    th = np.linspace(0, 2 * np.pi, n_angles, endpoint=False)
    rr = c.r + np.arange(-0.5 * c.r, 0.5 * c.r + 0.25, 0.5)
    xs = c.cx + np.cos(th)[:, None] * rr[None]
    ys = c.cy + np.sin(th)[:, None] * rr[None]
    d = np.abs(np.gradient(ndimage.map_coordinates(g, [ys, xs], order=1, mode="nearest"), axis=1))
    return float(np.mean(np.abs(rr[np.argmax(d, axis=1)] - c.r) <= 2.0))


def _mean_image(img):
    ref = np.zeros(img.shape[1:3])
    for im in img:                       # one LED at a time: full-size stacks are large
        ref += im.mean(axis=2) if im.ndim == 3 else im
    return ref / len(img)


def _where(circle):
    return f"the sphere at ({circle.cx:.1f}, {circle.cy:.1f}) px, radius {circle.r:.1f} px"


def _check_horizon(circle, dirs):
    """Refuse directions below the horizon (ValueError): no such light lights what the camera sees."""
    below = np.flatnonzero(dirs[:, 2] < -np.sin(np.radians(HORIZON_TOLERANCE_DEG)))
    if len(below):
        el = np.degrees(np.arcsin(np.clip(dirs[below, 2], -1, 1)))
        raise ValueError(f"{_where(circle)} puts {len(below)} of {len(dirs)} lights below the horizon (photographs "
                         f"{', '.join(str(i + 1) for i in below[:6])}: elevation {', '.join(f'{e:.0f}°' for e in el[:6])}), "
                         "which cannot light what the camera sees: that circle is not the sphere's outline")


def _check_given_outline(img, circle, ref):
    """Refuse a circle or mask given whose disc leaves out the photographs' highlights (each one's
    brightest change), or whose rim the photographs show less than the outline found (ValueError).
    Both are looked for within three radii of the circle: the cost of a crop, not of the photographs."""
    h, w = img.shape[1:3]
    r0, c0 = max(int(circle.cy - 3 * circle.r), 0), max(int(circle.cx - 3 * circle.r), 0)
    r1, c1 = min(int(circle.cy + 3 * circle.r) + 1, h), min(int(circle.cx + 3 * circle.r) + 1, w)
    near = Circle(circle.cx - c0, circle.cy - r0, circle.r)
    crop = ref[r0:r1, c0:c1]
    pts = highlight_points(img, box=(r0, r1, c0, c1)) - [c0, r0]
    outside = np.hypot(pts[:, 0] - near.cx, pts[:, 1] - near.cy) >= near.r
    if outside.mean() > 0.1:
        first = int(np.flatnonzero(outside)[0])
        raise ValueError(f"{_where(circle)} leaves out the highlights of {int(outside.sum())} of {len(pts)} "
                         f"photographs (photograph {first + 1}'s is at ({pts[first][0] + c0:.0f}, "
                         f"{pts[first][1] + r0:.0f}) px): that circle is not the sphere's outline")
    try:
        found = find_sphere_outline(crop, pts)
    except ValueError:
        return                            # nothing to compare with: the circle given stands
    far = np.hypot(found.cx - near.cx, found.cy - near.cy) + abs(found.r - near.r)
    if far > max(3.0, 0.05 * circle.r) and _rim_support(crop, found) > _rim_support(crop, near) + RIM_SUPPORT_LEAD:
        raise ValueError(f"{_where(circle)} is not the outline the photographs show: the sphere's rim is at "
                         f"{found.cx + c0:.1f},{found.cy + r0:.1f},{found.r:.1f} (cx,cy,r px; x the column, y the row)")