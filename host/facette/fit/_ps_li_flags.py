"""Cast-shadow flags no neighbour shares, under few lights (`Pixels.neighbour_round`'s second step).

The per-pixel solve leaves a light out as a cast shadow where, at its start normal, the value is
below CAST_SHADOW_RATIO of the model's prediction (facette.fit._normals_li). A cast shadow is cast by
the surface on a region: its edge is a curve, and a pixel inside it has shadowed neighbours. A light
left out of one pixel whose 3 × 3 neighbours all keep it is not a shadow but the mark of a start in
the wrong place: under the rig's 12 lights each light is a twelfth of the pixel's evidence, and the
solve, free of it, ends in a minimum the rest allow. Such a pixel is solved again from its
neighbours' mean (the minima search's kernel, facette.fit._ps_li_minima_jit: the start's own flags,
then both minima's robust costs over every usable light on the pixel's scale) and moves where that
minimum is cheaper. Under more than SEARCH_MAX_LIGHTS lights nothing is done (each light is a small
part of the evidence, and DiLiGenT's 96 and a dome's keep their normals).

Measured on the concave renders under the 12 rig lights (bench concave, paint and dark paint, 16- and
8-bit, every full-size li_alternating call of `process`): 3-147 pixels tried a call, 0-6 moved (the
dark paint craters: 751 tried, 30 moved); the moved pixels' errors summed 394 -> 275° over the 16-bit
paint_0.10 scenes' calls (craters 79 -> 29°, one grooves pixel 11.5 -> 13.8°). A small step: the
scenes' means moved by ≤ 0.02° (16-bit, with and without it, the search from 4°).

    isolated_flags(shadow, usable, idx, shape) -> (N,) bool
"""
import numpy as np

__all__ = ["isolated_flags", "MIN_NEIGHBOURS"]

# a pixel's flag is isolated when at least this many of its 8 neighbours are valid and each of them keeps
# the light (an image's edge or the mask's: too few neighbours to say)
MIN_NEIGHBOURS = 5


def isolated_flags(shadow, usable, idx, shape, min_neighbours=MIN_NEIGHBOURS):
    """(N,) bool: the valid pixels (flat indices `idx` into an image of `shape`) with a light left out
    as a cast shadow (`shadow` (N, m)) that every valid 3 × 3 neighbour keeps (usable, not left out),
    with at least `min_neighbours` valid neighbours."""
    from scipy.ndimage import correlate
    h, w = shape
    ring = np.ones((3, 3), np.int32)
    ring[1, 1] = 0
    valid = np.zeros(h * w, np.int32)
    valid[idx] = 1
    n_valid = correlate(valid.reshape(h, w), ring, mode="constant").ravel()[idx]
    out = np.zeros(idx.size, bool)
    keeps = np.asarray(usable, bool) & ~np.asarray(shadow, bool)
    for light in np.flatnonzero(shadow.any(0)):
        grid = np.zeros(h * w, np.int32)
        grid[idx] = keeps[:, light]
        n_keep = correlate(grid.reshape(h, w), ring, mode="constant").ravel()[idx]
        out |= shadow[:, light] & (n_keep == n_valid)
    return out & (n_valid >= min_neighbours)
