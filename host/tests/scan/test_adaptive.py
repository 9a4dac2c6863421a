"""The adaptive bracket's object mask: a dark background is left out of the plan."""
import numpy as np

from facette.scan.adaptive import object_mask


def test_object_mask_leaves_a_dark_background_out():
    rng = np.random.default_rng(0)
    frames = []
    for li in range(3):
        img = np.full((40, 50, 3), 20.0) + rng.normal(0, 1, (40, 50, 3))   # table, 4 % albedo
        img[10:30, 10:40] = 500.0 * (1 + 0.3 * li)                          # object, lit by each light
        img[10:30, 10:15] *= 0.3                                            # a darker part of it
        frames.append(img)
    mask = object_mask(frames)
    assert mask[10:30, 10:40].all() and not mask[:8].any() and not mask[:, 42:].any()


def test_object_mask_is_everything_when_nothing_stands_out():
    flat = [np.full((20, 20, 3), 100.0)]
    assert object_mask(flat).all()
    assert object_mask([np.zeros((20, 20, 3))]).all()       # black metering: plan_adaptive says why


def test_a_large_metering_frame_is_sampled_with_its_highlights_kept():
    from facette.scan.adaptive import sampled_for_plan

    rng = np.random.default_rng(0)
    img = rng.uniform(10, 20, (60, 90, 3)).astype(np.float32)
    img[31, 44] = (900.0, 1000.0, 800.0)             # a one-pixel highlight off the sample grid
    same, k = sampled_for_plan(img, pixels=60 * 90)
    assert k == 1 and same is img                    # small enough: the frame itself
    out, k = sampled_for_plan(img, pixels=600)
    assert k == 3 and out.shape == (20, 30, 3) and out.dtype == np.float32
    assert out.max() == 1000.0 and np.array_equal(out[10, 14], [900.0, 1000.0, 800.0])
    dim = np.ones((20, 30), bool)
    dim[10, 14] = False
    assert np.array_equal(out[dim], img[::3, ::3][dim])   # elsewhere: the frame's own pixels
