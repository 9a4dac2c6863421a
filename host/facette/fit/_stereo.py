"""Grids over the visible hemisphere of normals in stereographic coordinates, for tables looked up
per pixel by bilinear interpolation (the compiled solve's volume part: `_normals_li_jit._model`
does the lookup).

    (u, v) = (n_x, n_y) / (1 + n_z);   n = (2u, 2v, 1 − u² − v²) / (1 + u² + v²)

The hemisphere n_z ≥ 0 is the unit disk and n is smooth up to its rim, so a cell there spans about
half a degree of tilt at 257 points per axis; on a grid of (n_x, n_y) instead, n_z = √(1 − n_x² − n_y²)
is not smooth at the rim and the last cells span tilts from 83° to 90° (a table's values there
were 2-36 % off at 80-89.5°). A point (u, v) outside the disk is a normal facing away (n_z < 0);
its mirror image (n_x, n_y, −n_z) is the point (u, v) / (u² + v²) inside.
"""
import numpy as np

__all__ = ["stereo_grid"]


def stereo_grid(grid):
    """(normals (grid, grid, 3) float64, r² (grid, grid)) on u, v = linspace(−1, 1, grid) (row
    index: v, column: u); the points with r² ≥ 1 have n_z ≤ 0."""
    u = np.linspace(-1, 1, grid)
    gu, gv = np.meshgrid(u, u)
    r2 = gu * gu + gv * gv
    return np.stack([2 * gu, 2 * gv, 1 - r2], -1) / (1 + r2)[..., None], r2

