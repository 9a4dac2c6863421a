"""facette.sim.scene: the simulated objects and their materials."""
import numpy as np
import pytest

from facette.sim.scene import SCENES, make_scene, normals_from_height


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


def _height_rms_pitches(scene, normals):
    """RMS (in pixel pitches) of the heights integrated from `normals` against the scene's
    own, on the object, up to a constant."""
    from facette.recon import integrate
    d = (integrate(normals, scene.pixel_pitch_mm) - scene.height_mm)[scene.mask]
    return np.sqrt(np.mean((d - d.mean()) ** 2)) / scene.pixel_pitch_mm


@pytest.mark.parametrize("shape", [(48, 64), (96, 128)])
def test_the_truths_normals_integrate_to_the_truths_heights(shape):
    # One surface: the normals are the mean slopes of the footprint whose mean heights are the
    # truth, so integrating them leaves only the aliasing of sub-pixel detail: 0.053 and 0.048
    # pitches measured. The sphere's analytic normals (vertical at its rim, where the sampled
    # heights step down by several pitches) gave 0.49 and 0.60 pitches.
    sc = make_scene(shape=shape)
    assert _height_rms_pitches(sc, sc.normals) < 0.08


def test_a_pixel_is_the_mean_of_its_footprint():
    # a tilted plane is the same at any sub-sampling; the plaque's sub-pixel detail averages
    # out: heights at k = 8 are the means of the heights at k = 1 on an 8× finer grid
    fine = make_scene("plaque", shape=(96, 128), supersample=1)
    coarse = make_scene("plaque", shape=(12, 16), supersample=8)
    assert coarse.pixel_pitch_mm == pytest.approx(8 * fine.pixel_pitch_mm)
    block = fine.height_mm.reshape(12, 8, 16, 8).mean(axis=(1, 3))
    # (point samples at the coarse pixel centres differ from these means by up to 0.50 mm)
    np.testing.assert_allclose(coarse.height_mm, block, atol=1e-9)
    frac = fine.mask.reshape(12, 8, 16, 8).mean(axis=(1, 3))
    assert np.all(coarse.mask[frac > 0.6]) and not np.any(coarse.mask[frac < 0.4])
    with pytest.raises(ValueError, match="supersample"):
        make_scene(shape=(16, 16), supersample=0)
