"""Virtual objects, LEDs and the renderer of the simulated rig."""
import numpy as np
import pytest

from facette.calib import nominal_light_directions
from facette.sim.lights import LedArray, thesis_leds
from facette.sim.render import cast_shadow_visibility, radiance_per_led, to_local
from facette.sim.scene import SCENES, Scene, make_scene, normals_from_height


@pytest.mark.parametrize("name", SCENES)
def test_scenes_have_unit_normals_and_consistent_shapes(name):
    sc = make_scene(name, shape=(24, 32))
    assert sc.height_mm.shape == (24, 32) and sc.normals.shape == (24, 32, 3)
    assert sc.mask.dtype == bool and sc.mask.any()
    np.testing.assert_allclose(np.linalg.norm(sc.normals, axis=-1), 1.0, atol=1e-12)
    assert np.all(sc.normals[..., 2] >= 0)
    assert np.all((sc.albedo >= 0) & (sc.albedo <= 1))


def test_default_scene_is_plaque_left_sphere_right():
    sc = make_scene(shape=(48, 64))
    x, _ = sc.coordinates_mm()
    top = np.unravel_index(np.argmax(sc.height_mm), sc.shape)
    assert x[top] > 0                       # the sphere (highest point) is on the right
    assert sc.mask[:, : 64 // 3].any()      # the plaque covers the left part
    centre = sc.normals[top]
    np.testing.assert_allclose(centre, [0, 0, 1], atol=0.1)


def test_normals_from_height_follow_the_camera_frame():
    # z = 0.5 x + 0.25 y (mm): n ∝ (−0.5, −0.25, 1); row 0 is the top (y up)
    pitch = 2.0
    h, w = 10, 12
    x = (np.arange(w) - (w - 1) / 2) * pitch
    y = ((h - 1) / 2 - np.arange(h)) * pitch
    xx, yy = np.meshgrid(x, y)
    n = normals_from_height(0.5 * xx + 0.25 * yy, pitch)
    expect = np.array([-0.5, -0.25, 1.0]) / np.linalg.norm([-0.5, -0.25, 1.0])
    np.testing.assert_allclose(n, np.broadcast_to(expect, n.shape), atol=1e-12)


def test_brdf_presets_are_the_thesis_validation_materials():
    assert make_scene(shape=(16, 16)).brdf == {"model": "cook_torrance", "params": {"sigma": 0.05, "n_i": 1.2}}
    assert make_scene(shape=(16, 16), brdf="bust").brdf["params"] == {"sigma": 0.1, "n_i": 1.3}
    with pytest.raises(ValueError, match="unknown BRDF preset"):
        make_scene(shape=(16, 16), brdf="velvet")


def test_bad_scene_arguments_are_refused():
    with pytest.raises(ValueError, match="unknown scene"):
        make_scene("teapot")
    with pytest.raises(ValueError, match="at least 8"):
        make_scene(shape=(4, 4))


def test_thesis_leds_are_near_nominal_and_errors_scale():
    nominal = nominal_light_directions()
    exact = thesis_leds(direction_error_deg=0, intensity_error=0)
    np.testing.assert_allclose(exact.directions, nominal, atol=1e-12)
    np.testing.assert_allclose(exact.intensities, 1.0)
    noisy = thesis_leds(direction_error_deg=1.0, intensity_error=0.05, seed=3)
    ang = np.degrees(np.arccos(np.clip(np.sum(noisy.directions * nominal, 1), -1, 1)))
    assert 0 < ang.max() < 5
    assert np.std(noisy.intensities) > 0
    near = thesis_leds(near=True, distance_mm=1500)
    np.testing.assert_allclose(np.linalg.norm(near.positions_mm, axis=1), 1500)


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
