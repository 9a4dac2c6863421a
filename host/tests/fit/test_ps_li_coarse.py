"""Coarse-to-fine steps of ps_li_alternating (facette.fit._ps_li_coarse): the binning factor,
the binned inputs and the upsampled normals."""
import numpy as np
import pytest

from facette.fit._ps_li_coarse import bin_inputs, coarse_factor, upsample_normals


@pytest.mark.parametrize("n_valid, coarse_pixels, materials, factor", [
    (1000, 1000, 1, None),          # not above the threshold: full size
    (1001, 1000, 1, 2),             # just above: the smallest factor that brings it below
    (786_432, 250_000, 1, 2),       # 1024 x 768 at the default
    (786_432, 250_000, None, 2),
    (3_052_736, 250_000, 1, 4),     # 2144 x 1424: sqrt(12.2) -> 4
    (786_432, 250_000, "auto", None),   # several materials: never coarse-to-fine
    (786_432, None, 1, None), (786_432, 0, 1, None),
])
def test_the_coarse_factor_is_the_smallest_that_brings_the_pixels_below(n_valid, coarse_pixels, materials, factor):
    f = coarse_factor(n_valid, coarse_pixels, materials)
    assert f == factor
    if f:
        assert n_valid / f ** 2 <= coarse_pixels < n_valid / (f - 1) ** 2


def test_binning_averages_the_valid_values_of_each_block_and_pads_the_edge():
    rng = np.random.default_rng(0)
    im = rng.random((2, 5, 4, 3)).astype(np.float32)
    mask = np.ones((5, 4), bool)
    mask[0, 0] = False                               # block (0, 0): 3 of 4 pixels count
    im[1, 2, 2, 0] = np.nan                          # block (1, 1): 3 of 4 values in light 1, channel 0
    out, dirs, cmask = bin_inputs(im, np.eye(3)[[0, 2]], mask, 2, None)
    assert out.shape == (2, 3, 2, 3) and cmask.shape == (3, 2)
    np.testing.assert_allclose(out[:, 0, 0], im[:, [0, 1, 1], [1, 0, 1]].mean(1), rtol=1e-6)
    np.testing.assert_allclose(out[1, 1, 1, 0], np.nanmean(im[1, 2:4, 2:4, 0]), rtol=1e-6)
    np.testing.assert_allclose(out[:, 2, 1], im[:, 4, 2:4].mean(1), rtol=1e-6)   # the padded last row
    assert cmask.all()
    np.testing.assert_array_equal(dirs, np.eye(3)[[0, 2]])     # distant lights pass through


def test_a_block_with_fewer_than_half_its_pixels_is_nan_and_out_of_the_mask():
    im = np.ones((1, 4, 4, 1), np.float32)
    mask = np.ones((4, 4), bool)
    mask[:2, :2] = [[False, False], [False, True]]   # 1 of 4
    out, _, cmask = bin_inputs(im, np.float32([[0, 0, 1]]), mask, 2, None)
    assert np.isnan(out[0, 0, 0, 0]) and not cmask[0, 0] and cmask.sum() == 3
    sat = bin_inputs(im * 2, np.float32([[0, 0, 1]]), np.ones((4, 4), bool), 2, 1.5)[0]
    assert np.isnan(sat).all()                       # every value saturated


def test_per_pixel_directions_are_the_renormalised_block_mean():
    dirs = np.zeros((2, 2, 1, 3), np.float32)
    dirs[..., 2] = 1
    dirs[0, 0, 0] = [0.6, 0, 0.8]
    _, out, _ = bin_inputs(np.ones((1, 2, 2, 1), np.float32), dirs, np.ones((2, 2), bool), 2, None)
    expect = np.float32([0.15, 0, 0.95]) / np.linalg.norm([0.15, 0, 0.95])
    np.testing.assert_allclose(out[0, 0, 0], expect, rtol=1e-6)


def test_upsampling_keeps_a_constant_field_and_fills_cells_without_a_normal():
    n = np.float32([0.6, 0, 0.8])
    coarse = np.tile(n, (3, 4, 1))
    coarse[1, 2] = 0                                 # no normal there: its neighbours' is used
    up = upsample_normals(coarse, (6, 8), 2)
    assert up.shape == (6, 8, 3) and up.dtype == np.float32
    np.testing.assert_allclose(up, np.broadcast_to(n, up.shape), atol=1e-6)
    np.testing.assert_array_equal(upsample_normals(np.zeros((2, 2, 3), np.float32), (4, 4), 2), 0)


def test_upsampling_interpolates_between_cell_centres():
    coarse = np.zeros((1, 2, 3), np.float32)
    coarse[0, 0] = [0, 0, 1]
    coarse[0, 1] = [1, 0, 0]
    up = upsample_normals(coarse, (2, 4), 2)
    np.testing.assert_allclose(np.linalg.norm(up, axis=-1), 1, atol=1e-6)
    np.testing.assert_allclose(up[0, 0], [0, 0, 1], atol=1e-6)        # left of the first centre: its normal
    np.testing.assert_allclose(up[0, 3], [1, 0, 0], atol=1e-6)
    x = up[0, :, 0]
    assert x[0] < x[1] < x[2] < x[3]                                  # monotone in between
