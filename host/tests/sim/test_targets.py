"""Targets shown through the simulator's own renderer (no device needed)."""
import types

import numpy as np
import pytest

from facette.calib.mirror_sphere import mirror_sphere_directions
from facette.calib.spectralon import spectralon_intensities
from facette.calib.checks import angle_deg
from facette.calib.targets import channel_reflectance
from facette.sim.lights import thesis_leds
from facette.sim.render import radiance_per_led
from facette.sim.scene import make_scene
from facette.sim.targets import SIM_TARGETS, render_target, restore_scene, show_target, target_scene


def _sim(shape=(48, 64), scale=20.0, **led_kw):
    """The parts of a SimulatedRig the targets use: scene, leds, camera.radiance."""
    scene = make_scene("plaque_sphere", shape)
    leds = thesis_leds(**{"direction_error_deg": 2.0, "intensity_error": 0.15, "seed": 1, **led_kw})
    camera = types.SimpleNamespace(radiance=radiance_per_led(scene, leds, scale))
    return types.SimpleNamespace(scene=scene, leds=leds, camera=camera)


def test_spectralon_rendered_by_the_simulator_matches_eq_4_3():
    sim = _sim(scale=37.0)
    rad, scene = render_target(sim, "spectralon")
    assert sim._calib_scale == pytest.approx(37.0)          # recovered from the rig's own render
    rho = channel_reflectance()
    cos = sim.leds.directions[:, 2]
    k = 37.0 * np.pi * 1e-6
    expected = k * sim.leds.intensities * rho / np.pi * cos[:, None]
    np.testing.assert_allclose(rad[:, 10, 20, :], expected, rtol=1e-9)
    res = spectralon_intensities(rad, sim.leds.directions, rho)
    np.testing.assert_allclose(res.intensities, sim.leds.intensities / sim.leds.intensities.mean(0),
                               rtol=1e-9)


def test_mirror_sphere_scene_gives_the_true_directions():
    sim = _sim()
    rad, scene = render_target(sim, "mirror_sphere", radius_mm=38.1)
    assert scene.mask.any() and np.all(scene.albedo[scene.mask] == 0)
    dirs, circle, _ = mirror_sphere_directions(rad)
    assert circle.r == pytest.approx(38.1 / sim.scene.pixel_pitch_mm, abs=0.05)
    assert angle_deg(dirs, sim.leds.directions).max() < 0.25


def test_show_and_restore_swap_what_the_camera_sees():
    sim = _sim()
    original = sim.camera.radiance
    show_target(sim, "lens_cap")
    assert sim.camera.radiance.shape == original.shape and not sim.camera.radiance.any()
    show_target(sim, "none")
    assert 0 < sim.camera.radiance.max() < 0.1 * original.max()
    restore_scene(sim)
    assert sim.camera.radiance is original
    with pytest.raises(ValueError, match="unknown target"):
        target_scene("grey_card", (8, 8), 1.0)
    assert "spectralon" in SIM_TARGETS


def test_target_faults_show_the_empty_table_or_an_overexposed_target():
    sim = _sim()
    empty = show_target(sim, "none")
    empty_radiance = sim.camera.radiance
    assert show_target(sim, "spectralon", fault="missing").name == empty.name
    np.testing.assert_array_equal(sim.camera.radiance, empty_radiance)
    bright, _ = render_target(sim, "spectralon")
    show_target(sim, "spectralon", fault="overexposed")
    np.testing.assert_allclose(sim.camera.radiance, 300.0 * bright)
    with pytest.raises(ValueError, match="unknown target fault"):
        show_target(sim, "spectralon", fault="smudged")
