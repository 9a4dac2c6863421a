"""facette.calib.matte_sphere: directions from a Lambertian sphere (cross-check)."""
import numpy as np
import pytest

from facette.calib import nominal_light_directions
from facette.calib.matte_sphere import matte_sphere_directions
from facette.calib.mirror_sphere import Circle
from facette.calib.targets import render_matte_sphere

SHAPE, PITCH = (150, 180), 0.2
CENTER, R = (88.3, 71.6), 50.4


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def test_matte_sphere_cross_check():
    d = nominal_light_directions()
    I = np.random.default_rng(3).uniform(0.85, 1.15, 12)
    imgs = np.stack([render_matte_sphere(SHAPE, CENTER, R, PITCH, direction=l, intensity=i)
                     for l, i in zip(d, I)])
    dirs, inten, resid, circle = matte_sphere_directions(imgs)
    assert _angle_deg(dirs, d).max() < 0.3
    np.testing.assert_allclose(inten[:, 1], I / I.mean(), rtol=5e-3)
    assert resid.max() < 0.01
    assert abs(circle.r - R) < 0.3


def test_matte_sphere_edges_no_light_and_bad_shapes():
    with pytest.raises(ValueError, match=r"\(m, H, W\)"):
        matte_sphere_directions(np.zeros((4, 4)))
    imgs = np.stack([render_matte_sphere(SHAPE, CENTER, R, PITCH, direction=l)
                     for l in nominal_light_directions()[:3]])
    dark = imgs.copy()
    dark[1] = 0.0
    with pytest.raises(ValueError, match="too few lit pixels"):
        matte_sphere_directions(dark, circle=Circle(*CENTER, R))
