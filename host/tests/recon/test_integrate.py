"""Integration of normal maps into heights (mm) and the mesh."""
import numpy as np
import pytest

from facette.recon import (INTEGRATION_DEFAULT, integrate, integrate_frankot_chellappa1988,
                           integrate_least_squares, integrate_poisson_flat_margin, integrate_simchony1990,
                           mesh_from_height, normals_to_gradients)
from facette.recon._integrate import MAX_SLOPE, MIN_BACKGROUND_PIXELS, flat_margin


def surface_normals(z_fn, h=64, w=80, pitch=1.0):
    """Normals (H, W, 3) of z(x, y) in mm on a grid (x right, y up, row 0 at the top)."""
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    x, y = (xx - w / 2) * pitch, -(yy - h / 2) * pitch
    z, zx, zy = z_fn(x, y)
    n = np.stack([-zx, -zy, np.ones_like(z)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True), z


def bump(x, y, a=3.0, s=8.0):
    g = a * np.exp(-(x ** 2 + y ** 2) / (2 * s ** 2))
    return g, -x / s ** 2 * g, -y / s ** 2 * g


def centred(z, mask=None):
    sel = np.ones(z.shape, bool) if mask is None else mask
    return np.where(sel, z - z[sel].mean(), 0)


@pytest.mark.parametrize("fn", [integrate_frankot_chellappa1988, integrate_simchony1990,
                                integrate_poisson_flat_margin, integrate_least_squares])
def test_gaussian_bump_heights(fn):
    n, z = surface_normals(bump)
    got = fn(n, pixel_pitch_mm=1.0)
    assert got.shape == z.shape and got.dtype == np.float32
    assert np.max(np.abs(got - centred(z))) < 0.05 * z.max()


@pytest.mark.parametrize("method", ["frankot_chellappa1988", "simchony1990", "poisson_flat_margin",
                                    "least_squares"])
def test_heights_scale_with_the_pixel_pitch(method):
    # the same normal map read at twice the pitch is twice as high
    n, _ = surface_normals(bump)
    a = integrate(n, 0.05, method=method)
    b = integrate(n, 0.1, method=method)
    np.testing.assert_allclose(b, 2 * a, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("method", ["simchony1990", "least_squares"])
def test_sign_conventions_x_right_y_up(method):
    # z = 0.1 x + 0.2 y: height grows to the right and towards the top row
    n, z = surface_normals(lambda x, y: (0.1 * x + 0.2 * y, 0.1 + 0 * x, 0.2 + 0 * x), 20, 30)
    got = integrate(n, 1.0, method=method)
    np.testing.assert_allclose(got, centred(z), atol=1e-4)
    assert got[10, 29] > got[10, 0] and got[0, 15] > got[19, 15]


def two_domes_on_a_table(h=96, w=160):
    """Normals and heights of two hemispheres (radii 30 and 20 px) standing on a flat table,
    the surface given by its heights at the pixel corners: a pixel's normal is that of its mean
    slope (the difference of its edges' mean heights), its height the mean of its corners (the
    simulator's pixel at 1024x768 RAW and above)."""
    from facette.sim.scene import _edge_means, _trapezoid_mean    # the simulator's own pixel

    x, y = np.meshgrid(np.arange(w + 1) - w / 2, h / 2 - np.arange(h + 1))
    z = np.sqrt(np.clip(30.0 ** 2 - (x + 40) ** 2 - y ** 2, 0, None)) + \
        np.sqrt(np.clip(20.0 ** 2 - (x - 45) ** 2 - y ** 2, 0, None))
    height = _trapezoid_mean(z, 1)
    vertical, horizontal = _edge_means(z, 1)
    sx, sy = vertical[:, 1:] - vertical[:, :-1], horizontal[:-1] - horizontal[1:]
    n = np.stack([-sx, -sy, np.ones_like(sx)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True), height


def rms_error(got, truth, sel):
    d = (got - truth)[sel]
    return float(np.sqrt(np.mean((d - d.mean()) ** 2)))


def test_poisson_flat_margin_does_not_ring_at_the_rims_nor_tilt_with_a_biased_table():
    n, height = two_domes_on_a_table()
    on = height > 0
    methods = ("frankot_chellappa1988", "simchony1990", "poisson_flat_margin")
    rms = {m: rms_error(integrate(n, 1.0, method=m), height, on) for m in methods}
    # Fourier derivatives ring at the rims' one-pixel walls (0.11 px RMS); the local stencil is
    # exact on heights given at the pixel corners
    assert rms["poisson_flat_margin"] < 1e-3 < 0.05 < rms["frankot_chellappa1988"], rms
    # a table whose normals lean by 0.3 deg (a dark cloth's biased normals) between the domes:
    # Simchony's Neumann solve integrates the lean into a ramp that tilts one dome against the
    # other; the mean slope removed, the map keeps its shape (measured 0.15 / 0.11 / 0.028 px)
    lean = np.deg2rad(0.3)
    biased = n.copy()
    biased[~on] = [-np.sin(lean), 0.0, np.cos(lean)]
    tilted = {m: rms_error(integrate(biased, 1.0, method=m), height, on) for m in methods}
    assert tilted["poisson_flat_margin"] < 0.5 * min(tilted["simchony1990"],
                                                     tilted["frankot_chellappa1988"]), tilted
    assert INTEGRATION_DEFAULT == "poisson_flat_margin"
    # told which pixels are the table, it takes the lean from them alone and leaves the domes'
    # slopes as they are: exact again (the whole image's mean slope also tilts the domes)
    told = rms_error(integrate(biased, 1.0, method="poisson_flat_margin", background=~on), height, on)
    assert told < 1e-3 < tilted["poisson_flat_margin"], (told, tilted)


def test_flat_margin_background_too_small_or_of_another_size():
    n, height = two_domes_on_a_table()
    stray = np.zeros(height.shape, bool)
    stray[:MIN_BACKGROUND_PIXELS // 100, :99] = True          # fewer pixels than a margin needs
    assert flat_margin(stray, stray.shape) is None
    np.testing.assert_array_equal(integrate_poisson_flat_margin(n, background=stray),
                                  integrate_poisson_flat_margin(n))
    # the methods that assume no margin have no use for one
    np.testing.assert_array_equal(integrate(n, method="simchony1990", background=height == 0),
                                  integrate(n, method="simchony1990"))
    with pytest.raises(ValueError, match="background has shape"):
        integrate_poisson_flat_margin(n, background=np.ones((4, 4), bool))


def test_least_squares_on_a_mask_with_holes_strands_and_isolated_pixels():
    n, z = surface_normals(bump, 48, 48)
    mask = np.zeros((48, 48), bool)
    mask[5:40, 5:40] = True
    mask[15:25, 15:25] = False            # a hole
    mask[44, 2:46] = True                 # a one-pixel strand, separate from the block
    mask[2, 2] = True                     # an isolated pixel
    got = integrate_least_squares(n, 1.0, mask)
    assert np.all(np.isfinite(got))
    assert np.all(got[~mask] == 0)
    block = np.zeros_like(mask)
    block[5:40, 5:40] = True
    block &= mask
    assert np.max(np.abs(got[block] - centred(z, block)[block])) < 0.02 * z.max()
    strand = np.zeros_like(mask)
    strand[44, 2:46] = True
    # along a strand only the x gradient is seen: the profile of z along that row
    np.testing.assert_allclose(got[strand], centred(z, strand)[strand], atol=0.01 * z.max())
    assert got[2, 2] == 0.0


def test_least_squares_by_multigrid_gives_the_direct_solve_s_heights():
    # rtol: pyamg to that residual (the horizon test's heights), same mask rules: holes, a strand,
    # an isolated pixel at 0, each piece centred
    n, z = surface_normals(bump, 48, 48)
    mask = np.zeros((48, 48), bool)
    mask[5:40, 5:40] = True
    mask[15:25, 15:25] = False
    mask[44, 2:46] = True
    mask[2, 2] = True
    exact = integrate_least_squares(n, 1.0, mask)
    close = integrate_least_squares(n, 1.0, mask, rtol=1e-8)
    assert np.all(close[~mask] == 0) and close[2, 2] == 0.0
    np.testing.assert_allclose(close, exact, atol=1e-4 * z.max())
    rough = integrate_least_squares(n, 1.0, mask, rtol=1e-3)
    assert 0 < np.max(np.abs(rough - exact)) < 0.05 * z.max()


def test_normals_to_gradients_edges():
    n = np.zeros((2, 3, 3))
    n[..., 2] = 1
    n[0, 0] = [np.nan, 0, 1]
    n[0, 1] = [1, 0, 0]                  # grazing: n_z = 0
    n[0, 2] = [0.6, 0, -0.8]             # facing away
    n[1, 0] = [-0.6, 0, 0.8]             # slope dz/dx = 0.75
    p, q = normals_to_gradients(n)
    assert p[0, 0] == p[0, 1] == p[0, 2] == 0 and q[0, 0] == 0
    assert p[1, 0] == pytest.approx(0.75)
    p, _ = normals_to_gradients(np.array([[[-0.9999, 0, 0.0001]]]))
    assert p[0, 0] == MAX_SLOPE           # clipped slope


@pytest.mark.parametrize("method", ["frankot_chellappa1988", "simchony1990", "poisson_flat_margin",
                                    "least_squares"])
def test_a_wall_steeper_than_87_degrees_keeps_its_height(method):
    # a plateau whose sides rise 30 pitches within one pixel (slope 30, 88.1 deg), as a pixel
    # over a sphere's rim does at a fine pitch: its height is 30, not the 20 of a clip at 20
    n = np.zeros((16, 40, 3))
    n[..., 2] = 1.0
    for col, slope in ((10, 30.0), (30, -30.0)):
        n[:, col] = np.array([-slope, 0.0, 1.0]) / np.hypot(slope, 1.0)
    z = integrate(n, 1.0, method=method)
    step = z[:, 12:29].mean() - np.r_[z[:, :9].ravel(), z[:, 32:].ravel()].mean()
    assert step == pytest.approx(30.0, rel=0.05)


def test_bad_arguments():
    n, _ = surface_normals(bump, 8, 8)
    with pytest.raises(ValueError, match="pixel_pitch_mm"):
        integrate_simchony1990(n, 0.0)
    with pytest.raises(ValueError, match="unknown integration method"):
        integrate(n, method="magic")
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        integrate_frankot_chellappa1988(n[..., :2])


def test_mesh_from_height_counts_coordinates_and_orientation():
    hgt = np.arange(12, dtype=float).reshape(3, 4)
    mask = np.ones((3, 4), bool)
    mask[0, 0] = False
    v, f = mesh_from_height(hgt, mask, pixel_pitch_mm=0.5)
    assert len(v) == 11
    # 6 blocks of 2x2: 5 full (2 triangles) and 1 with three corners (1 triangle)
    assert len(f) == 11
    assert v[:, 0].max() == 1.5 and v[:, 1].min() == -1.0
    flat_v, flat_f = mesh_from_height(np.zeros((3, 3)), np.ones((3, 3), bool))
    tri = flat_v[flat_f]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(normals[:, 2] > 0)      # counter-clockwise seen from the camera
    v2, _ = mesh_from_height(np.zeros((9, 9)), np.ones((9, 9), bool), step=2)
    assert len(v2) == 25


def test_mesh_leaves_out_the_curtain_down_a_silhouette():
    """A 10 mm plateau on a base at 0.1 mm pitch: with max_slope the triangles that join the
    two levels (a wall no photograph from above measured) are left out, the rest kept."""
    from facette.recon import mesh_from_height
    h = np.zeros((20, 30))
    h[5:15, 8:22] = 10.0
    v_all, f_all = mesh_from_height(h, np.ones(h.shape, bool), 0.1)
    v, f = mesh_from_height(h, np.ones(h.shape, bool), 0.1, max_slope=10.0)
    z = v[f][..., 2]
    assert len(v) == len(v_all) == h.size
    assert np.all((z.max(axis=1) - z.min(axis=1)) == 0)          # no face joins the levels
    za = v_all[f_all][..., 2]
    spanning = int(((za.max(axis=1) - za.min(axis=1)) > 0).sum())
    assert spanning > 0 and f.shape[0] == f_all.shape[0] - spanning    # the wall's faces only


@pytest.mark.parametrize("rows", [1, 7, 1000])
def test_dct_solve_in_bands_and_float32_is_the_least_squares_heights(monkeypatch, rows):
    """The DCT Poisson solve builds its divergence a band of rows at a time in float32 (for
    100 MP maps): any band height gives the heights of the same equations solved exactly in
    float64 by the sparse least squares on the full grid, to 1e-5 of their range."""
    import facette.recon._integrate as integ
    monkeypatch.setattr(integ, "SLOPE_BAND_ROWS", rows)
    rng = np.random.default_rng(3)
    n, _ = surface_normals(lambda x, y: bump(x, y, a=5.0, s=6.0), h=37, w=53)
    n = n + rng.normal(0, 0.05, n.shape)           # not integrable: the least-squares answer matters
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    want = integrate_least_squares(n, 0.2)
    got = integrate_simchony1990(n, 0.2)
    assert got.dtype == np.float32
    assert np.abs(got - want).max() < 1e-5 * np.ptp(want)


@pytest.mark.parametrize("rows", [3, 1000])
def test_flat_margin_lean_taken_in_bands_as_over_the_whole_image(monkeypatch, rows):
    """The margin's mean slope is summed band by band: the same heights as the slopes with
    that mean removed at once, integrated whole (the least squares on the full grid)."""
    import facette.recon._integrate as integ
    monkeypatch.setattr(integ, "SLOPE_BAND_ROWS", rows)
    h, w = 40, 50
    n, _ = surface_normals(lambda x, y: bump(x, y, a=2.0, s=5.0), h=h, w=w)
    tilt = np.array([0.05, -0.03, 1.0])
    bg = np.zeros((h, w), bool)
    bg[:, :8] = bg[:, -8:] = True
    n[bg] = tilt / np.linalg.norm(tilt)              # a leaning table around the bump
    bg_big = np.zeros((h * 10, w * 10), bool)        # MIN_BACKGROUND_PIXELS: upsample the scene
    big = np.repeat(np.repeat(n, 10, 0), 10, 1)
    bg_big[:] = np.repeat(np.repeat(bg, 10, 0), 10, 1)
    got = integrate_poisson_flat_margin(big, 1.0, background=bg_big)
    gx, gy = normals_to_gradients(big)
    gy = -gy
    gx[bg_big] -= gx[bg_big].mean()
    gy[bg_big] -= gy[bg_big].mean()
    # the same slopes as a normal map (n ∝ (-p, -q, 1)) integrated whole
    fixed = np.dstack([-gx, gy, np.ones_like(gx)])
    want = integrate_least_squares(fixed / np.linalg.norm(fixed, axis=-1, keepdims=True), 1.0)
    assert np.abs(got - want).max() < 1e-4 * np.ptp(want)


@pytest.mark.parametrize("columns", [1, 7, 1000])
def test_the_dct_in_bands_and_blocks_is_scipy_s_whole_transform(monkeypatch, columns):
    """The Poisson solve's DCT runs one axis at a time in place (rows in bands, columns in blocks, for
    100 MP maps): the 2-D transform and its inverse of scipy.fft.dctn / idctn, to float32's rounding."""
    import scipy.fft
    import facette.recon._integrate as integ
    monkeypatch.setattr(integ, "DCT_BLOCK_COLUMNS", columns)
    monkeypatch.setattr(integ, "SLOPE_BAND_ROWS", 3)
    x = np.random.default_rng(5).standard_normal((23, 31)).astype(np.float32)
    for inverse, fn in ((False, scipy.fft.dctn), (True, scipy.fft.idctn)):
        got = integ._dct_in_place(x.copy(), inverse)
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, fn(x, type=2, norm="ortho"), atol=2e-6 * np.abs(x).max() * 31)


def test_heights_of_normals_on_disk_are_those_of_normals_in_memory():
    """`process --memory` integrates the normal map kept in a temporary file: the same heights."""
    from facette._memory import disk_array
    n, _ = surface_normals(lambda x, y: bump(x, y, a=4.0, s=7.0), h=41, w=57)
    on_disk = disk_array(n.shape, np.float32)
    on_disk[:] = n
    mask = np.zeros(n.shape[:2], bool)
    mask[3:-3, 5:-5] = True
    for method in ("poisson_flat_margin", "simchony1990"):
        want = integrate(n.astype(np.float32), 0.1, None, method)
        assert np.array_equal(integrate(on_disk, 0.1, None, method), want)
    want = integrate_simchony1990(n.astype(np.float32), 0.1, mask)
    assert np.array_equal(integrate_simchony1990(on_disk, 0.1, mask), want) and not want[~mask].any()
