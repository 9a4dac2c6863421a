"""Integration of the gradient field of a normal map into heights (mm), and a mesh.

Gradients: p = dz/dx = -n_x / n_z, q = dz/dy = -n_y / n_z in the camera frame (x right,
y up). Image row 0 is the top, so dz/d(row) = -q * pitch and dz/d(col) = p * pitch.
Heights are defined up to a constant: each method returns heights whose mean over
the mask (or the whole image) is 0.
"""
import numpy as np
import scipy.fft
import scipy.sparse
import scipy.sparse.csgraph
import scipy.sparse.linalg

from facette._memory import release
from facette._registry import Registry

__all__ = ["MESH_MAX_SLOPE", "normals_to_gradients", "integrate_frankot_chellappa1988", "integrate_simchony1990",
           "integrate_poisson_flat_margin", "integrate_least_squares", "INTEGRATION_DEFAULT", "integrate",
           "flat_margin", "MIN_BACKGROUND_PIXELS",
           "INTEGRATION_METHODS", "mesh_from_height"]

# |p|, |q| are clipped here (88.9 deg): n_z -> 0 (silhouettes) would give infinite slopes. Not
# lower: a pixel over a vertical tangent (a sphere's rim on the table) has a mean slope that grows
# as sqrt(2 R / pitch), 26 on the simulated sphere at the thesis camera's 4288x2848; clipped at 20
# its scan lost 0.025 mm of height RMS (0.043 -> 0.018 mm at 50, the same at 100; no change at
# 1072x712 and below).
MAX_SLOPE = 50.0


def normals_to_gradients(normals, mask=None, max_slope=MAX_SLOPE):
    """(p, q) = (-n_x/n_z, -n_y/n_z), each (H, W) float64, clipped to +-max_slope.

    normals : (H, W, 3) camera frame. Pixels outside `mask`, not finite, zero, or facing away
    (n_z <= 0) get p = q = 0.
    """
    normals = np.asarray(normals, dtype=np.float64)
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise ValueError(f"normals must have shape (H, W, 3), got {normals.shape}")
    nz = normals[..., 2]
    ok = np.all(np.isfinite(normals), axis=-1) & (nz > 1e-9)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    safe = np.where(ok, nz, 1.0)
    p = np.where(ok, np.clip(-normals[..., 0] / safe, -max_slope, max_slope), 0.0)
    q = np.where(ok, np.clip(-normals[..., 1] / safe, -max_slope, max_slope), 0.0)
    return p, q


def _image_gradients(normals, mask, pixel_pitch_mm):
    if pixel_pitch_mm <= 0 or not np.isfinite(pixel_pitch_mm):
        raise ValueError(f"pixel_pitch_mm must be a positive length in mm, got {pixel_pitch_mm}")
    p, q = normals_to_gradients(normals, mask)
    # per-pixel steps in mm along columns (x) and rows (-y)
    return p * pixel_pitch_mm, -q * pixel_pitch_mm


def _centre(z, mask, rows=1024):
    """z (float32, in place when it is float32) less its mean over the mask, 0 outside it; a band of
    rows at a time (no copy of the masked values: 4 bytes per pixel, 0.4 GB at 100 MP)."""
    z = z.astype(np.float32, copy=False)
    some = mask is not None and mask.any()
    total, count = 0.0, 0
    for r0 in range(0, z.shape[0], rows):
        part = z[r0:r0 + rows]
        if some:
            sel = mask[r0:r0 + rows]
            total += float(part.sum(dtype=np.float64, where=sel))
            count += int(np.count_nonzero(sel))
        else:
            total += float(part.sum(dtype=np.float64))
            count += part.size
    mean = np.float32(total / max(count, 1))
    for r0 in range(0, z.shape[0], rows):
        z[r0:r0 + rows] -= mean
        if mask is not None:
            z[r0:r0 + rows][~mask[r0:r0 + rows]] = 0.0
    return z


def integrate_frankot_chellappa1988(normals, pixel_pitch_mm=1.0, mask=None):
    """Heights (H, W) float32 in mm from a normal map, by projection on integrable
    Fourier bases (Frankot & Chellappa 1988; the thesis's choice, §4.2.1).

    normals : (H, W, 3) unit vectors, camera frame; pixel_pitch_mm : object-side pixel size.
    mask : optional (H, W) bool; outside it the gradients are 0 and the height is 0.
    The field is treated as periodic: keep a flat margin around the object.
    """
    mask = None if mask is None else np.asarray(mask, bool)
    gx, gy = _image_gradients(normals, mask, pixel_pitch_mm)
    h, w = gx.shape
    wx = 2 * np.pi * scipy.fft.fftfreq(w)[None, :]
    wy = 2 * np.pi * scipy.fft.fftfreq(h)[:, None]
    denom = wx ** 2 + wy ** 2
    denom[0, 0] = 1.0
    zf = (-1j * wx * scipy.fft.fft2(gx) - 1j * wy * scipy.fft.fft2(gy)) / denom
    zf[0, 0] = 0.0
    return _centre(np.real(scipy.fft.ifft2(zf)), mask)


def integrate_simchony1990(normals, pixel_pitch_mm=1.0, mask=None):
    """Heights (H, W) float32 in mm: discrete Poisson equation with Neumann boundaries,
    solved exactly by the DCT (Simchony, Chellappa & Shao 1990).

    Minimises sum over neighbour pairs of (z_j+1 - z_j - (g_j + g_j+1)/2)^2 on the full grid.
    normals, pixel_pitch_mm, mask as `integrate_frankot_chellappa1988`.
    """
    return _poisson_heights(normals, pixel_pitch_mm, mask, lean=None)


def integrate_poisson_flat_margin(normals, pixel_pitch_mm=1.0, mask=None, background=None):
    """Heights (H, W) float32 in mm: Simchony's DCT Poisson solve of the slopes with the flat
    margin's mean slope removed. The default of `facette process`.

    With a flat margin around the object (which Frankot–Chellappa's periodic field needs too),
    opposite borders are at one height, so the true mean slope of the margin is zero; a dark
    margin's measured one is not (a black cloth's normals: 2° of noise where the object's have
    0.5°, and a lean of 0.1° from the little gloss it has). Removing that lean keeps it from
    tilting one object against another, as Frankot–Chellappa's periodicity does, while the
    local stencil does not ring at one-pixel walls as Fourier derivatives do (the simulated
    sphere's rim from exact normals: 0.005 mm RMS against 0.043 there; once the surface has
    detail finer than a pixel both alias alike). Not for a surface that fills the frame with a
    slope: that needs "simchony1990" (or "least_squares" on the mask).

    background : optional (H, W) bool, the margin's own pixels (the table or cloth around the
        object: `process` gives the lit pixels darker than the object). Its mean slope is taken
        over them and removed from them only, so the object's slopes are integrated as measured
        (on the simulated scans: heights per object 0.013-0.015 -> 0.008 mm at every size). Without
        it (or with fewer than MIN_BACKGROUND_PIXELS), the mean slope of the whole image is
        removed from every pixel, the object's included.
    normals, pixel_pitch_mm, mask as `integrate_frankot_chellappa1988`.
    """
    margin = flat_margin(background, np.shape(normals)[:2])
    return _poisson_heights(normals, pixel_pitch_mm, mask, lean="all" if margin is None else margin)


# Below this many pixels a background is too small to give its mean slope (a few stray dark
# pixels on a slab that fills the frame): the whole image's mean slope is removed instead.
MIN_BACKGROUND_PIXELS = 1000


def flat_margin(background, shape):
    """The pixels `integrate_poisson_flat_margin` takes the margin's mean slope from: the
    background as an (H, W) bool array, or None when it is None or has too few pixels."""
    if background is None:
        return None
    bg = np.asarray(background, bool)
    if bg.shape != shape:
        raise ValueError(f"background has shape {bg.shape}, the normals are {shape[1]}x{shape[0]}")
    return bg if int(bg.sum()) >= MIN_BACKGROUND_PIXELS else None


# rows of normals turned into slopes at a time by the DCT solve: bounds its float64 scratch
# (~100 bytes per pixel of a band) whatever the image's size
SLOPE_BAND_ROWS = 256


def _bands(h, rows=None):
    rows = rows or SLOPE_BAND_ROWS
    return [(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]


def _band_slopes(normals, mask, pitch, r0, r1):
    """(gx, gy) float64 of rows r0:r1 (clipped to the image): per-pixel steps in mm along
    columns and rows, as `_image_gradients` gives them."""
    r0, r1 = max(r0, 0), min(r1, normals.shape[0])
    p, q = normals_to_gradients(normals[r0:r1], None if mask is None else mask[r0:r1])
    release(normals)                    # a map kept on disk: its pages read so far handed back
    return p * pitch, -q * pitch


def _poisson_heights(normals, pixel_pitch_mm, mask, lean):
    """The DCT Poisson solve (Simchony et al. 1990) of a normal map's slopes, in memory that
    does not grow with the normals' copies: the slopes are made a band of rows at a time (the
    normals may be a memory-mapped file, read once or twice in order), the divergence and its
    transform are one float32 array solved in place (4 bytes per pixel), its DCT one axis at a time
    (`_dct_in_place`: a band's scratch, where scipy.fft.dctn's added ~6 bytes per pixel, 0.6 GB at
    100 MP). The heights agree with the float64 whole-image form to 2.5e-7 of their range at 12 MP
    (the tests: with the sparse least squares of the same equations, whatever the bands); the
    axis-at-a-time DCT moves them by 3.4e-7 of their range (12 MP relief slab: at most 1.2e-4 px).

    lean : None (the slopes as measured), "all" (the whole image's mean slope removed from
    every pixel) or an (H, W) bool margin (its mean slope removed from its own pixels)."""
    if pixel_pitch_mm <= 0 or not np.isfinite(pixel_pitch_mm):
        raise ValueError(f"pixel_pitch_mm must be a positive length in mm, got {pixel_pitch_mm}")
    if np.ndim(normals) != 3 or np.shape(normals)[2] != 3:
        raise ValueError(f"normals must have shape (H, W, 3), got {np.shape(normals)}")
    mask = None if mask is None else np.asarray(mask, bool)
    h, w = normals.shape[:2]
    pitch = float(pixel_pitch_mm)
    mean_x = mean_y = 0.0
    if lean is not None:         # a first pass for the mean slope to take out
        sx = sy = 0.0
        count = 0
        for r0, r1 in _bands(h):
            gx, gy = _band_slopes(normals, mask, pitch, r0, r1)
            sel = None if isinstance(lean, str) else lean[r0:r1]
            sx += float(gx.sum() if sel is None else gx[sel].sum())
            sy += float(gy.sum() if sel is None else gy[sel].sum())
            count += gx.size if sel is None else int(sel.sum())
        mean_x, mean_y = sx / max(count, 1), sy / max(count, 1)
    div = np.empty((h, w), np.float32)
    for r0, r1 in _bands(h):
        # one row of halo each side: the vertical flux through a band's top and bottom edges
        a = max(r0 - 1, 0)
        gx, gy = _band_slopes(normals, mask, pitch, a, r1 + 1)
        if isinstance(lean, str):
            gx -= mean_x
            gy -= mean_y
        elif lean is not None:
            sel = lean[a:a + gx.shape[0]]
            gx[sel] -= mean_x
            gy[sel] -= mean_y
        gx = gx[r0 - a:r1 - a]
        # slopes on the edges between neighbours (averaged), zero flux through the border:
        # edge i lies above row i (edges 0 and h are the border)
        ex = np.zeros((r1 - r0, w + 1))
        ex[:, 1:w] = 0.5 * (gx[:, :-1] + gx[:, 1:])
        edge = np.arange(r0, r1 + 1)
        inner = (edge > 0) & (edge < h)
        ey = np.zeros((r1 - r0 + 1, w))
        ey[inner] = 0.5 * (gy[edge[inner] - 1 - a] + gy[edge[inner] - a])
        div[r0:r1] = (ex[:, 1:] - ex[:, :-1]) + (ey[1:] - ey[:-1])
    return _centre(_solve_poisson_dct(div), mask)


# columns transformed at a time by the DCT's second axis: bounds its copy (H x 256 x 4 bytes)
DCT_BLOCK_COLUMNS = 256


def _dct_in_place(x, inverse=False):
    """The 2-D orthonormal DCT-II (or its inverse) of float32 `x`, in place: along the rows a band
    of rows at a time, then along the columns a block of columns at a time, so that its scratch is
    a band's, not the image's (scipy.fft.dctn held ~6 bytes per pixel besides: 0.6 GB at 100 MP).
    The same transform as dctn, one axis after the other."""
    fn = scipy.fft.idct if inverse else scipy.fft.dct
    h, w = x.shape
    for r0, r1 in _bands(h, max(1, (SLOPE_BAND_ROWS * 1024) // max(w, 1))):
        x[r0:r1] = fn(x[r0:r1], type=2, norm="ortho", axis=1)
    for c0 in range(0, w, DCT_BLOCK_COLUMNS):
        c1 = min(w, c0 + DCT_BLOCK_COLUMNS)
        x[:, c0:c1] = fn(np.ascontiguousarray(x[:, c0:c1]), type=2, norm="ortho", axis=0, overwrite_x=True)
    return x


def _solve_poisson_dct(div):
    """Heights whose discrete Laplacian (Neumann) is `div`, in place in `div` (float32), by the
    DCT-II (Simchony et al. 1990): each cosine mode divided by its eigenvalue."""
    h, w = div.shape
    f = _dct_in_place(div)
    col = (2 * np.cos(np.pi * np.arange(w) / w) - 2).astype(np.float32)
    row = (2 * np.cos(np.pi * np.arange(h) / h) - 2).astype(np.float32)
    for r0, r1 in _bands(h, 1024):
        lam = row[r0:r1, None] + col[None, :]
        if r0 == 0:
            lam[0, 0] = 1.0
        f[r0:r1] /= lam
    f[0, 0] = 0.0
    return _dct_in_place(f, inverse=True)


def integrate_least_squares(normals, pixel_pitch_mm=1.0, mask=None, rtol=None):
    """Heights (H, W) float32 in mm by sparse least squares restricted to the mask.

    One equation per pair of 4-neighbours both in the mask: z_b - z_a = mean of their
    gradients. Works on any mask (holes, one-pixel strands, several pieces): each connected
    piece is integrated on its own and has mean 0; isolated pixels get 0.
    Solved by the normal equations (sparse Cholesky-like direct solve up to ~1e6 pixels,
    conjugate gradients above). rtol: solved instead by classical algebraic multigrid (pyamg) to
    that relative residual, for heights that need not be exact (recon._shadows' horizon test:
    0.28 M pixels 1.3 CPU s against the direct solve's 3.2, heights within 2e-7 at rtol 1e-8).
    """
    normals = np.asarray(normals)
    h, w = normals.shape[:2]
    mask = np.ones((h, w), bool) if mask is None else np.asarray(mask, bool)
    if mask.shape != (h, w):
        raise ValueError(f"mask has shape {mask.shape}, normals are {h}x{w}")
    gx, gy = _image_gradients(normals, mask, pixel_pitch_mm)
    index = -np.ones((h, w), np.int64)
    n = int(mask.sum())
    index[mask] = np.arange(n)
    z = np.zeros((h, w))
    if n == 0:
        return z.astype(np.float32)
    rows_a, rows_b, rhs = [], [], []
    hx = mask[:, :-1] & mask[:, 1:]
    rows_a.append(index[:, :-1][hx]); rows_b.append(index[:, 1:][hx])
    rhs.append(0.5 * (gx[:, :-1] + gx[:, 1:])[hx])
    vy = mask[:-1] & mask[1:]
    rows_a.append(index[:-1][vy]); rows_b.append(index[1:][vy])
    rhs.append(0.5 * (gy[:-1] + gy[1:])[vy])
    a_idx, b_idx, b = np.concatenate(rows_a), np.concatenate(rows_b), np.concatenate(rhs)
    ne = a_idx.size
    eq = np.arange(ne)
    d = scipy.sparse.csr_matrix((np.r_[-np.ones(ne), np.ones(ne)], (np.r_[eq, eq], np.r_[a_idx, b_idx])),
                                shape=(ne, n))
    # each connected piece has one free constant: pin its first pixel, then centre the piece
    ncomp, labels = scipy.sparse.csgraph.connected_components(
        scipy.sparse.csr_matrix((np.ones(ne), (a_idx, b_idx)), shape=(n, n)), directed=False)
    first = np.unique(labels, return_index=True)[1]
    pin = np.zeros(n)
    pin[first] = 1.0
    lhs = (d.T @ d + scipy.sparse.diags(pin)).tocsc()
    rhs_v = d.T @ b
    if rtol is not None:
        import pyamg
        sol = pyamg.ruge_stuben_solver(lhs.tocsr()).solve(rhs_v, tol=rtol, accel="cg")
    elif n <= 1_000_000:
        sol = scipy.sparse.linalg.spsolve(lhs, rhs_v)
    else:
        diag = lhs.diagonal()
        pre = scipy.sparse.diags(1.0 / np.where(diag > 0, diag, 1.0))
        sol, _ = scipy.sparse.linalg.cg(lhs, rhs_v, M=pre, rtol=1e-8, maxiter=5000)
    sizes = np.bincount(labels, minlength=ncomp)
    sol = sol - (np.bincount(labels, weights=sol, minlength=ncomp) / sizes)[labels]
    z[mask] = sol
    return z.astype(np.float32)


INTEGRATION_METHODS = Registry("integration method")
INTEGRATION_METHODS.add("frankot_chellappa1988", integrate_frankot_chellappa1988)
INTEGRATION_METHODS.add("simchony1990", integrate_simchony1990)
INTEGRATION_METHODS.add("poisson_flat_margin", integrate_poisson_flat_margin)
INTEGRATION_METHODS.add("least_squares", integrate_least_squares)


# Measured against Frankot–Chellappa (the thesis's, §4.2.1) on the rank_trimmed normals of simulated
# scans at 1024x768 / 1072x712 / 4288x2848 RAW (committed profile): height RMS 0.015 / 0.017 /
# 0.014 mm against 0.018 / 0.020 / 0.014 (per object 0.013 / 0.013 / 0.014 against 0.017 / 0.017 /
# 0.014); on nine Mitsuba scenes 1-42 % lower on seven, 0.3 % higher on the two vases. Plain
# Simchony is best per object but tilts two objects apart through a noisy background (with the
# previous profile 0.038 / 0.043 / 0.030 mm, against 0.026 / 0.024 / 0.015 here). With the table's
# lean taken from the table alone (`background`, as `process` passes it), on scans from the
# simulator whose dome rims no longer shadow themselves: 0.017 / 0.013 / 0.015 -> 0.016 / 0.010 /
# 0.008 mm, per object 0.014 / 0.013 / 0.015 -> 0.008 / 0.009 / 0.008; Mitsuba's two domes on a
# dark table 0.490 -> 0.475 px (`facette bench mitsuba`).
INTEGRATION_DEFAULT = "poisson_flat_margin"


def integrate(normals, pixel_pitch_mm=1.0, mask=None, method=INTEGRATION_DEFAULT, background=None):
    """Dispatch by name: "poisson_flat_margin" (default), "frankot_chellappa1988", "simchony1990"
    or "least_squares". background : the flat margin's pixels (see
    `integrate_poisson_flat_margin`); the methods that assume no margin have no use for it."""
    fn = INTEGRATION_METHODS[method]
    if fn is integrate_poisson_flat_margin:
        return fn(normals, pixel_pitch_mm=pixel_pitch_mm, mask=mask, background=background)
    return fn(normals, pixel_pitch_mm=pixel_pitch_mm, mask=mask)


# meshes leave out triangles steeper than this (rise over run, ~84°): the curtains a height map
# hangs from a silhouette down to what is behind it, which no photograph from above measured
MESH_MAX_SLOPE = 10.0


def mesh_from_height(height_mm, mask, pixel_pitch_mm=1.0, step=1, max_slope=None):
    """Triangle mesh of a height map: one vertex per masked pixel (every `step` px).

    Returns (vertices (V, 3) float32 in mm, camera frame: x right, y up, z = height;
    faces (F, 3) int32, counter-clockwise seen from +z). Two triangles per 2x2 block whose
    four corners are in the mask, one where exactly three are. max_slope : leave out the
    triangles with an edge steeper than this rise over run (|Δz| / horizontal length): the
    walls a height map hangs from a silhouette down to what is behind it (None: keep all).
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    hgt = np.asarray(height_mm)[::step, ::step]
    msk = np.asarray(mask, bool)[::step, ::step] & np.isfinite(hgt)
    h, w = hgt.shape
    index = -np.ones((h, w), np.int64)
    index[msk] = np.arange(int(msk.sum()))
    rows, cols = np.nonzero(msk)
    verts = np.stack([cols * step * pixel_pitch_mm, -rows * step * pixel_pitch_mm, hgt[msk]],
                     axis=1).astype(np.float32)
    a, b = index[:-1, :-1], index[:-1, 1:]      # top-left, top-right
    c, d = index[1:, :-1], index[1:, 1:]        # bottom-left, bottom-right
    faces = []
    # image rows go down (y decreases): (a, c, b) is counter-clockwise seen from +z
    for t in ((a, c, b), (b, c, d), (a, c, d), (a, d, b)):
        faces.append(np.stack([x for x in t], axis=-1))
    full = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    f = [faces[0][full], faces[1][full]]
    f.append(faces[2][(a >= 0) & (c >= 0) & (d >= 0) & (b < 0)])
    f.append(faces[3][(a >= 0) & (d >= 0) & (b >= 0) & (c < 0)])
    f.append(np.stack([a, c, b], -1)[(a >= 0) & (b >= 0) & (c >= 0) & (d < 0)])
    f.append(np.stack([b, c, d], -1)[(b >= 0) & (c >= 0) & (d >= 0) & (a < 0)])
    faces = np.concatenate(f).astype(np.int32)
    if max_slope is not None and len(faces):
        p = verts[faces].astype(np.float64)                    # (F, 3 corners, xyz)
        q = np.roll(p, -1, axis=1)
        run = np.hypot(p[..., 0] - q[..., 0], p[..., 1] - q[..., 1])
        steep = (np.abs(p[..., 2] - q[..., 2]) > max_slope * run).any(axis=1)
        faces = faces[~steep]
    return verts, faces
