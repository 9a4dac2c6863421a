"""The volume part's table of the compiled per-pixel solve (facette.fit._normals_li_jit): B(n, s_i)
of eq 3.15 per light over the normals' stereographic coordinates, built once per (σ, n_i) and lights
and read bilinearly by the solve's `_model` (its module doc)."""
import threading

import numpy as np

from facette._threads import run_blocks
from facette.brdf import li_shading_terms

from ._stereo import stereo_grid

__all__ = ["volume_table", "TABLE_GRID", "TABLE_BLOCK"]

TABLE_GRID = 257           # grid points per axis of the B table (stereographic u, v ∈ [−1, 1])
TABLE_BLOCK = 1024         # normals per block of the table's evaluation (~100 k values with 96 lights)
RIM_CELLS = 2.5            # grid points this many cells outside the disk hold B's continuation (`_volume_table`)
RIM_NZ = 1e-4              # n_z of the rim normals of that continuation (B at n_z = 0 exactly: no view)

# Remembered tables, (σ, n_i, grid, volume model, lights' bytes) -> table, in the order made: the
# last KEEP_LARGE of the solve's grid (the alternation asks for the same model in its full-size step
# as in its last round), and the model choice's coarse ones (grid <= SMALL_GRID) up to SMALL_BYTES:
# its search asks for the same grid points in every li run with the same lights (DiLiGenT pot2's
# `process`, 96 lights: 28 of its 105 tables were ones made before, 0.46 of 27 CPU s)
KEEP_LARGE = 8
SMALL_GRID = 65
SMALL_BYTES = 64 << 20
_TABLES = {}
_SMALL = {}
_TABLES_LOCK = threading.Lock()     # the model choice's diffuse parts search on two threads


def volume_table(lights, sigma, n_i, grid=TABLE_GRID, volume_model="approx"):
    """`_volume_table`, remembered (see KEEP_LARGE, SMALL_BYTES); the same table either way."""
    s = np.ascontiguousarray(lights, np.float64)
    key = (float(sigma), float(n_i), int(grid), volume_model, s.tobytes())
    store = _SMALL if grid <= SMALL_GRID else _TABLES
    tab = store.get(key)
    if tab is None:
        tab = _volume_table(s, sigma, n_i, grid, volume_model)
        with _TABLES_LOCK:
            if store is _SMALL:
                while store and sum(t.nbytes for t in store.values()) + tab.nbytes > SMALL_BYTES:
                    store.pop(next(iter(store)))
            elif len(store) >= KEEP_LARGE:
                store.pop(next(iter(store)))
            store[key] = tab
    return tab


def _volume_table(lights, sigma, n_i, grid, volume_model):
    """(grid, grid, m) float32 B(n, s_i) on the normals of `stereo_grid(grid)` (facette.fit._stereo:
    smooth up to the rim, where a grid of (n_x, n_y) put 2 % errors (median) on B at 80-87° of tilt
    and 21 % at 87-89.5°; solved to convergence, the simulated 12 MP scan's silhouette ran to the
    horizon). Lights last: the four corners of a pixel's cell hold every light's value side by side
    (cache lines). The points just outside the disk (within RIM_CELLS cells of it, which a lookup
    near the rim reads) hold B's linear continuation across the rim, 2 B(rim) − B(mirror image
    inside), at least 0; the others 0."""
    nrm, r2 = stereo_grid(grid)
    inside = r2 < 1
    near = ~inside & (np.sqrt(r2) < 1 + RIM_CELLS * 2 / (grid - 1))
    rim = nrm[near] * [1, 1, 0]
    rim = rim / np.linalg.norm(rim, axis=1, keepdims=True)
    rim[:, 2] = RIM_NZ
    gn = np.concatenate([nrm[inside], np.abs(nrm[near]), rim]).astype(np.float32)   # disk, mirrors, rim
    # in blocks of TABLE_BLOCK normals on two threads: the float32 temporaries of a large disk
    # (~20 MB each at 257² × 96 lights) missed the caches (DiLiGenT reading, in `process`: 0.73 of
    # the time). A small one (the model choice's 65² grid) at once: threads and blocks cost it more
    b_all = np.empty((len(gn), len(lights)), np.float32)
    block_size = TABLE_BLOCK if len(gn) > 4 * TABLE_BLOCK else len(gn)

    def block(a):
        b_all[a:a + block_size] = li_shading_terms(gn[a:a + block_size], lights, sigma, n_i, specular=False,
                                                   volume_model=volume_model)[1]

    run_blocks(block, range(0, len(gn), max(block_size, 1)))
    n_in, n_near = int(inside.sum()), int(near.sum())
    b = np.zeros((grid, grid, len(lights)), np.float32)
    b[inside] = b_all[:n_in]
    b[near] = np.maximum(2 * b_all[n_in + n_near:] - b_all[n_in:n_in + n_near], 0)
    return b
