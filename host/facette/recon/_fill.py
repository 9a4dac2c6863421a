"""Normals where photometric stereo measured none, interpolated from the measured ones around them.

A pixel that no light reaches above the noise has no measured normal: a bare metal between its
highlights (under the rig's 12 lights a gold sphere lights 23 % of its pixels, aluminium 62 %),
the bottom of a deep cavity, a pixel saturated in every photograph. The surface goes on there, and
its heights must too, so `process` gives such a pixel the harmonic interpolation of the measured
normals around it: each component solves Laplace's equation over the gap (Δn = 0), the measured
pixels fixed at its edge and no flux across the object's outline, then the vector is made unit.

    fill_normals(normals, measured, region, avoid=None) -> (normals, filled)

Harmonic in the normals, which for gentle slopes is the thin plate on the heights (∫|∇n|² is then
∫|∇∇z|², the bending energy); by the maximum principle each component stays within its values on
the gap's edge, so a fill never overshoots into a slope nobody measured. On Mitsuba's renders
through li_alternating (12 lights, 128 px), harmonic / biharmonic in the normals: gold sphere
19.0° / 12.7°, aluminium sphere 6.0° / 3.3°, gold relief 9.9° / 10.8° (unfilled: 70.3°, 35.1°,
20.7°, the gap's zero normals counting 90°); harmonic was kept for the guarantee and the relief,
whose gaps lie along sharp edges. A gap that touches no measured pixel (a piece of the region lit
by nothing) stays unfilled. Solved by algebraic multigrid (pyamg): 4.1 million gap pixels at 12 MP
in 13-15 s, where a direct factorisation's fill-in would not fit in memory.

A bare metal's dark pixels say more than "no measurement": their normal lies outside every light's
lobe, or the lobe would have lit them. With `avoid` (the lights' half vectors and the lobe's reach,
pipeline._filled) the fill keeps out of those cones: a plain fill between a gold sphere's highlights
leaves 74 % of its normals within 15° of some half vector, where 4.6 % of the true ones lie.
"""
import numpy as np
import pyamg
import scipy.sparse as sp
from scipy import ndimage

__all__ = ["fill_normals", "FILL_TOLERANCE", "AVOID_ROUNDS"]

FILL_TOLERANCE = 1e-5      # relative residual of the multigrid solve (1e-4 moves a 12 MP fill by 3e-5°)
AVOID_ROUNDS = 4           # active-set rounds of a constrained fill (Mitsuba's metals: done after one)


def fill_normals(normals, measured, region, avoid=None):
    """Normals interpolated where `region` has no measured normal.

    normals : (H, W, 3) unit normals where `measured`, anything elsewhere (not read);
    measured : (H, W) bool, the pixels with a measured normal; region : (H, W) bool, the object;
    avoid : optional (dirs (k, 3) unit, cos_max, where (H, W) bool): directions the normals filled at
    `where` must stay more than arccos(cos_max) from (a metal's dark pixels: its lobes' half vectors).
    Returns (normals, filled): a float32 copy with the gap pixels written (or `normals` itself
    when there is no gap), and the (H, W) bool map of the pixels written.

    With `avoid`, the fill is the harmonic one under those constraints, by active sets: a filled
    normal inside a cone is moved onto its edge (away from the cone's axis) and held there, the rest
    of the gap filled again, until no filled normal enters a cone (AVOID_ROUNDS at most, then the
    last ones are moved out without filling again)."""
    out, filled = _harmonic(normals, measured, region)
    if avoid is None or not filled.any():
        return out, filled
    dirs, cos_max, where = np.asarray(avoid[0], np.float64), float(avoid[1]), np.asarray(avoid[2], bool)
    held = np.asarray(measured, bool) & ~filled
    for last in [False] * AVOID_ROUNDS + [True]:
        inside = filled & where & ~held
        inside[inside] = (out[inside] @ dirs.T > cos_max + 1e-6).any(1)
        if not inside.any():
            break
        out[inside] = _out_of_cones(out[inside].astype(np.float64), dirs, cos_max)
        if last:                   # rounds spent: the last ones moved out without filling again
            break
        held |= inside
        out, more = _harmonic(out, held, region)
        filled |= more
    return out, filled


def _out_of_cones(n, dirs, cos_max):
    """(N, 3) unit normals, each moved onto the edge of every cone (axis in `dirs`, half-angle
    arccos(cos_max)) it lies in, in the plane of the normal and the axis."""
    sin_max = np.sqrt(max(1.0 - cos_max * cos_max, 0.0))
    for h in dirs:
        d = n @ h
        bad = d > cos_max
        away = n[bad] - d[bad, None] * h
        norm = np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-9)
        n[bad] = cos_max * h + sin_max * away / norm
    return n.astype(np.float32)


def _harmonic(normals, measured, region):
    """`fill_normals` without constraints."""
    # a measured normal that is not finite would spread NaN over its whole gap: it joins the gap
    measured = np.asarray(measured, bool) & np.asarray(region, bool) & np.isfinite(normals).all(-1)
    gap = np.asarray(region, bool) & ~measured
    if not gap.any():
        return normals, gap
    # a piece of the gap with no measured pixel beside it has nothing to interpolate from
    labels, n = ndimage.label(gap)
    touching = np.unique(labels[ndimage.binary_dilation(measured) & gap])
    keep = np.zeros(n + 1, bool)
    keep[touching[touching > 0]] = True
    gap = keep[labels]
    if not gap.any():
        return normals, gap
    h, w = gap.shape
    flat = np.asarray(normals, np.float32).reshape(-1, 3)
    pos = np.full(h * w, -1, np.int64)
    g = np.flatnonzero(gap)
    pos[g] = np.arange(g.size)
    diag = np.zeros(g.size)
    rhs = np.zeros((g.size, 3))
    rows, cols = [], []
    for step, a, b in ((1, np.s_[:, :-1], np.s_[:, 1:]), (w, np.s_[:-1, :], np.s_[1:, :])):
        ia = np.flatnonzero(_pairs(gap, measured, a, b))      # pairs (p, p + step) in the region
        for p, q in ((ia, ia + step), (ia + step, ia)):
            here = p[gap.ravel()[p]]                          # the pair's gap end ...
            other = q[gap.ravel()[p]]
            diag += np.bincount(pos[here], minlength=g.size)  # ... one neighbour more
            inner = gap.ravel()[other]
            rows.append(pos[here[inner]])                     # a gap neighbour: unknown
            cols.append(pos[other[inner]])
            for k in range(3):                                # a measured one: fixed
                rhs[:, k] += np.bincount(pos[here[~inner]], flat[other[~inner], k], minlength=g.size)
    r, c = np.concatenate(rows), np.concatenate(cols)
    lap = (sp.diags(diag) - sp.csr_matrix((np.ones(r.size), (r, c)), shape=(g.size, g.size))).tocsr()
    solver = pyamg.ruge_stuben_solver(lap)     # classical AMG: at 12 MP 13 s, smoothed aggregation's 22
    x = np.stack([solver.solve(rhs[:, k], tol=FILL_TOLERANCE, accel="cg") for k in range(3)], 1)
    norm = np.linalg.norm(x, axis=1)
    ok = norm > 1e-6                                          # opposite normals cancelling: left out
    out = np.array(normals, np.float32, copy=True)
    out.reshape(-1, 3)[g[ok]] = (x[ok] / norm[ok, None]).astype(np.float32)
    filled = np.zeros(h * w, bool)
    filled[g[ok]] = True
    return out, filled.reshape(h, w)


def _pairs(gap, measured, a, b):
    """(H, W) bool: pixel p whose neighbour at slice b of p's slice a forms a pair with one end in
    the gap and both in the gap or measured (the flat index of p, the neighbour's is p + step)."""
    inside = gap | measured
    m = np.zeros(gap.shape, bool)
    m[a] = inside[a] & inside[b] & (gap[a] | gap[b])
    return m
