"""recon.fill_normals: the normals of the pixels with none measured, harmonic from those around them."""
import numpy as np

from facette.recon import fill_normals
from facette.recon.synthetic import angular_error_deg


def _sphere(size=96):
    yy, xx = (np.mgrid[:size, :size] - (size - 1) / 2) / (0.45 * size)
    inside = xx ** 2 + yy ** 2 < 1
    n = np.dstack([xx, -yy, np.sqrt(np.clip(1 - xx ** 2 - yy ** 2, 0, 1))]).astype(np.float32)
    n[~inside] = 0
    return n, inside


def test_a_sphere_measured_in_spots_is_filled_close_to_its_shape():
    n, inside = _sphere()
    yy, xx = np.mgrid[:96, :96]
    spots = inside & ((xx // 12 + yy // 12) % 3 == 0)         # a third measured, in blocks
    seen = np.where(spots[..., None], n, 0)
    out, filled = fill_normals(seen, spots, inside)
    assert np.array_equal(filled, inside & ~spots)
    assert np.array_equal(out[spots], n[spots])                # the measured ones untouched
    assert np.allclose(np.linalg.norm(out[filled], axis=1), 1, atol=1e-5)
    err = angular_error_deg(out, n)[filled]
    assert err.mean() < 4.0 and err.max() < 35.0, (err.mean(), err.max())   # 2.7 and 27 (at the outline)
    # harmonic: each component within the values measured (no overshoot), z never turns away
    for k in range(3):
        assert n[spots][:, k].min() - 1e-5 <= out[filled][:, k].min()
    assert out[filled][:, 2].min() > 0


def test_a_single_gap_pixel_is_the_mean_of_its_four_neighbours():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(5, 5, 3)).astype(np.float32) + [0, 0, 3]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    region = np.ones((5, 5), bool)
    seen = region.copy()
    seen[2, 2] = False
    out, filled = fill_normals(n, seen, region)
    want = n[[1, 3, 2, 2], [2, 2, 1, 3]].sum(0)
    assert filled.sum() == 1 and np.allclose(out[2, 2], want / np.linalg.norm(want), atol=1e-5)


def test_only_the_region_is_read_and_a_gap_with_nothing_measured_stays_empty():
    n, inside = _sphere(40)
    seen = inside.copy()
    seen[15:25, 15:25] = False                                  # a hole in the middle: filled
    other = np.zeros_like(inside)
    other[:3, :3] = True                                        # a piece lit by nothing: left as it is
    wrong = n.copy()
    wrong[~inside] = [1, 0, 0]                                  # outside the region: never read
    out, filled = fill_normals(wrong, seen, inside | other)
    assert np.array_equal(filled, inside & ~seen)
    assert np.array_equal(out[other], wrong[other])
    assert angular_error_deg(out, n)[filled].mean() < 1.0


def test_a_measured_normal_that_is_not_finite_is_filled_not_spread():
    n, inside = _sphere(40)
    seen = inside.copy()
    seen[15:25, 15:25] = False
    bad = n.copy()
    bad[20, 14] = np.nan                                        # on the hole's edge
    out, filled = fill_normals(bad, seen, inside)
    assert filled[20, 14] and np.isfinite(out[inside]).all()
    assert angular_error_deg(out, n)[filled].mean() < 1.0


def test_a_constrained_fill_keeps_out_of_the_cones_and_only_where_asked():
    n, inside = _sphere()
    yy, xx = np.mgrid[:96, :96]
    spots = inside & ((xx // 12 + yy // 12) % 3 == 0)
    seen = np.where(spots[..., None], n, 0)
    axes = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    c = np.cos(np.radians(20))
    where = inside & (xx < 48)                                 # the left half only
    plain, _ = fill_normals(seen, spots, inside)
    out, filled = fill_normals(seen, spots, inside, avoid=(axes, c, where))
    assert np.array_equal(filled, inside & ~spots) and np.array_equal(out[spots], n[spots])
    assert np.allclose(np.linalg.norm(out[filled], axis=1), 1, atol=1e-5)
    assert (out[filled & where] @ axes.T <= c + 1e-4).all()
    assert ((plain[filled & where] @ axes.T) > c + 1e-3).any(1).sum() > 50      # the plain fill enters them
    assert ((out[filled & ~where] @ axes.T) > c + 1e-3).any()                   # elsewhere left free


def test_no_gap_returns_the_normals_as_they_are():
    n, inside = _sphere(20)
    out, filled = fill_normals(n, inside, inside)
    assert out is n and not filled.any()
