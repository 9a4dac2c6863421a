"""facette.sim.render: radiance per LED, near-light fall-off, cast shadows."""
import numpy as np

from facette.calib import nominal_light_directions
from facette.sim.lights import LedArray
from facette.sim.render import _read, cast_shadow_visibility, radiance_per_led, to_local
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


def _dome(n=96, radius=40.0):
    yy, xx = np.mgrid[0:n, 0:n].astype(float) - (n - 1) / 2
    h = np.sqrt(np.clip(radius ** 2 - xx ** 2 - yy ** 2, 0, None))
    gy, gx = np.gradient(h)                  # rows down: dz/dy = -dz/drow
    nrm = np.stack([-gx, gy, np.ones_like(h)], -1)
    return h, nrm / np.linalg.norm(nrm, axis=-1, keepdims=True), h > 0


def test_a_dome_does_not_shadow_itself_where_it_faces_the_light():
    # a convex surface lit from above its tangent plane (n.s > 0) cannot be occluded by itself;
    # reading the nearest pixel along the ray, half a pixel off it on the rim's steep slope,
    # shadowed 1.7 % of the facing pixels here (all near the rim) under the first light
    h, nrm, dome = _dome()
    for phi in range(0, 360, 30):
        for elev in (60.0, 75.0):
            t, p = np.radians(90 - elev), np.radians(phi)
            s = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
            vis = cast_shadow_visibility(h, 1.0, s)
            facing = dome & (nrm @ s > 0.05)
            assert np.mean(vis[facing] == 0) < 0.002, (phi, elev, np.mean(vis[facing] == 0))
            assert np.any(vis[~dome] == 0)          # it still shadows the table


def test_shadows_by_doubling_match_a_march_of_every_step():
    # the far steps' highest point found by doubling, against a march that reads every step
    # between pixels: the two differ by a few pixels at the shadows' edges at most
    h, _, _ = _dome(128, 30.0)
    h[20:30, 90:110] = 25.0                          # a block, and a ridge
    h += 4.0 * np.exp(-((np.arange(128) - 64) / 6.0) ** 2)[None, :]
    for phi in (20.0, 135.0, 250.0):
        t, p = np.radians(30.0), np.radians(phi)
        s = np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
        fast = cast_shadow_visibility(h, 1.0, s)
        dr, dc = -s[1] / np.hypot(s[0], s[1]), s[0] / np.hypot(s[0], s[1])
        rise = s[2] / np.hypot(s[0], s[1])
        rows, cols = np.mgrid[0:128, 0:128].astype(float)
        top = h + 1e-3 * (h.max() - h.min())
        blocked = np.zeros(h.shape, bool)
        for k in range(1, 2 * 128):
            blocked |= _read(h, rows + k * dr, cols + k * dc) - k * rise > top
        assert blocked.sum() > 500
        assert np.sum((fast == 0) != blocked) <= 0.01 * blocked.sum(), (phi, np.sum((fast == 0) != blocked))


def test_to_local_puts_the_normal_on_z():
    n = np.array([[0.3, -0.4, np.sqrt(1 - 0.25)]])
    np.testing.assert_allclose(to_local(n, n), [[0, 0, 1]], atol=1e-12)
