"""The dark level of each photograph (facette.recon._dark): what pixels read with the light behind them."""
import numpy as np

from facette.recon import dark_level_notes, dark_offsets
from facette.recon._dark import DARK_MAX_RELATIVE, DARK_MIN_PIXELS


def _sphere(n_px=96):
    """Normals of a full sphere filling the image (every direction of the front hemisphere)."""
    u = np.linspace(-1, 1, n_px)
    x, y = np.meshgrid(u, -u)
    r2 = x * x + y * y
    valid = r2 < 0.98
    n = np.stack([x, y, np.sqrt(np.maximum(1 - r2, 0))], -1) * valid[..., None]
    return n.astype(np.float32), valid


def _lights(tilts_deg):
    t = np.radians(np.asarray(tilts_deg, float))
    p = np.linspace(0, 2 * np.pi, len(t), endpoint=False)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)


def test_each_photograph_gets_its_own_level_and_an_axial_light_none():
    n, valid = _sphere()
    lights = _lights([60, 45, 70, 3])                  # the last: no normal is behind it
    lam = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)[..., None] * np.float32([0.5, 0.4, 0.3])
    pedestal = np.float32([[0.01, 0.008, 0.006], [0.015, 0.012, 0.03], [0.005, 0.01, 0.0], [0.01, 0.01, 0.01]])
    images = (lam + pedestal[:, None, None, :]).astype(np.float32)
    images[2, 10, 40] = np.nan                         # a missing value is not read
    off, info = dark_offsets(images, lights, n, valid)
    expect = pedestal.copy()
    expect[1, 2] = 0                                   # 0.03 is 14 % of that channel's lit median: not a pedestal
    expect[3] = 0                                      # too few dark pixels: left as it is
    np.testing.assert_allclose(off, expect, atol=1e-6)
    assert info["too_high"] == 1 and info["spread"] == 0
    assert info["estimated"] == 3 and info["pixels"] >= 3 * DARK_MIN_PIXELS
    assert 0 < info["relative"] < DARK_MAX_RELATIVE


def test_saturated_values_are_not_read_and_no_level_is_negative():
    n, valid = _sphere()
    lights = _lights([60, 60])
    images = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)[..., None].repeat(3, -1).astype(np.float32)
    images[0] -= 0.01                                  # a level below zero (over-subtracted black level)
    images[1][images[1] < 0.01] = 9.0                  # every dark pixel saturated in the second
    off, info = dark_offsets(images, lights, n, valid, saturation=5.0)
    assert np.all(off == 0) and info["estimated"] == 0


def test_no_valid_pixel_or_per_pixel_lights():
    n, valid = _sphere(48)
    lights = _lights([60, 50, 40])
    images = np.zeros((3, 48, 48, 1), np.float32)
    off, info = dark_offsets(images, lights, n, np.zeros_like(valid))
    assert off.shape == (3, 1) and np.all(off == 0) and info["estimated"] == 0
    per_pixel = np.broadcast_to(lights, (48, 48, 3, 3))          # near lights: (H, W, m, 3)
    images += np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)[..., None] + 0.02
    off2, _ = dark_offsets(images, per_pixel, n, valid)
    np.testing.assert_allclose(off2, 0.02, atol=1e-7)


def test_light_that_reaches_only_some_dark_pixels_is_no_level():
    # a concavity's own walls light part of the pixels the light is behind: their readings spread
    # from 0 up, no common level (the first photograph: 60 % of them lit); a uniform pedestal is
    # found under fewer such pixels (the second: 20 %), and not where they spread (the third)
    n, valid = _sphere()
    lights = _lights([60, 60, 60])
    lam = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)[..., None].astype(np.float32)
    dark = np.einsum("hwk,mk->mhw", n, lights) < -0.2
    rng = np.random.default_rng(1)
    lit_by_walls = rng.random(dark.shape) < np.float32([0.6, 0.2, 0.6])[:, None, None]
    walls = np.where(dark & lit_by_walls, rng.uniform(0.01, 0.2, dark.shape), 0)
    images = lam + walls[..., None].astype(np.float32)
    images[1:] += 0.02                                  # a pedestal under the second and the third
    off, info = dark_offsets(images, lights, n, valid)
    assert off[0, 0] == 0 and off[2, 0] == 0
    np.testing.assert_allclose(off[1, 0], 0.02, rtol=1e-5)
    assert info["estimated"] == 1


def test_what_the_report_says_of_it():
    assert dark_level_notes(None) == [] and dark_level_notes({"applied": False, "too_high": 0}) == []
    taken = dark_level_notes({"applied": True, "estimated": 72, "relative": 0.0142, "too_high": 0})
    assert len(taken) == 1 and "72 photograph(s)" in taken[0] and "1.4 %" in taken[0]
    left = dark_level_notes({"applied": False, "too_high": 113})
    assert len(left) == 1 and "left in" in left[0] and "113" in left[0]
