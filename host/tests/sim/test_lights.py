"""facette.sim.lights: the simulated LEDs and their errors."""
import numpy as np

from facette.calib import nominal_light_directions
from facette.sim.lights import thesis_leds


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
