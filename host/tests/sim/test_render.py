"""facette.sim.render: radiance per LED, near-light fall-off, cast shadows."""
import numpy as np

from facette.calib import nominal_light_directions
from facette.sim.lights import LedArray
from facette.sim.render import cast_shadow_visibility, radiance_per_led, to_local
from facette.sim.scene import make_scene


def _plane(albedo=0.5):
    sc = make_scene("plane", shape=(16, 20))
    sc.albedo[:] = albedo
    sc.brdf = {"model": "lambert", "params": {}}
    return sc


def test_lambert_plane_radiance_is_k_i_albedo_cos_over_pi():
    sc = _plane(0.5)
    leds = LedArray(nominal_light_directions(), np.ones((12, 3)) * [[1.0, 0.9, 0.8]])
    r = radiance_per_led(sc, leds, electrons_per_mA_s=20.0)
    k = 20.0 * np.pi * 1e-6
    cos = nominal_light_directions()[:, 2]
    expect = k * (0.5 / np.pi) * cos[:, None] * np.array([1.0, 0.9, 0.8])[None, :]
    np.testing.assert_allclose(r[:, 5, 7, :], expect, rtol=1e-9)


def test_near_leds_fall_off_with_distance():
    sc = _plane(0.5)
    d = np.array([[0.0, 0.0, 1.0]])
    far = radiance_per_led(sc, LedArray(d, np.ones((1, 3))))
    near = radiance_per_led(sc, LedArray(d, np.ones((1, 3)), positions_mm=d * 100.0, distance_mm=100.0))
    # centre pixel is ~100 mm from the LED: same as the distant model; corners get less light
    assert near[0, 0, 0, 1] < near[0, 8, 10, 1] <= far[0, 8, 10, 1] * 1.0001


def test_cast_shadows_fall_away_from_the_light():
    h = np.zeros((20, 40))
    h[8:12, 28:32] = 10.0                     # a 10 mm tall block, 1 mm pixels
    s = np.array([np.sin(np.radians(45)), 0, np.cos(np.radians(45))])   # light from +x (right)
    vis = cast_shadow_visibility(h, 1.0, s)
    # at 45° the shadow is as long as the block is tall: columns 18..27, left of the block
    assert np.all(vis[10, 19:28] == 0.0)
    assert vis[10, 16] == 1.0 and np.all(vis[10, 32:] == 1.0)
    assert np.all(vis[2] == 1.0)


def test_to_local_puts_the_normal_on_z():
    n = np.array([[0.3, -0.4, np.sqrt(1 - 0.25)]])
    np.testing.assert_allclose(to_local(n, n), [[0, 0, 1]], atol=1e-12)
