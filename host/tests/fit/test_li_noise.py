"""The quantisation step read from the values (facette.fit._li_noise) and the fit's floor from it."""
import numpy as np

from facette.fit._li_noise import FLOOR_MAX_LIGHTS, NOISE_SIGMAS, quantum_step, relative_floor


def _lattice(step, n=400, m=12, c=3, seed=0):
    rng = np.random.default_rng(seed)
    levels = rng.integers(0, 12, size=(n, m, c))
    return (levels * step + rng.uniform(0, 1, size=(1, m, c))).astype(np.float32)      # each column offset


def test_the_step_of_8_bit_values_is_their_level_and_floats_have_none():
    step = 1 / 255 / 0.7
    e = _lattice(step)
    assert np.isclose(quantum_step(e, np.ones(e.shape[:2], bool)), step, rtol=1e-3)
    floats = np.random.default_rng(1).uniform(0, 0.05, size=(400, 12, 3)).astype(np.float32)
    assert quantum_step(floats, np.ones(floats.shape[:2], bool)) < step / 100


def test_unusable_and_non_finite_values_do_not_count_and_too_few_pixels_give_no_step():
    step = 1 / 255
    e = _lattice(step)
    usable = np.ones(e.shape[:2], bool)
    e[::7, 3, :] = np.nan
    e[1::7, 4, :] = e[1::7, 4, :] + step / 3          # off the lattice, but marked unusable
    usable[1::7, 4] = False
    assert np.isclose(quantum_step(e, usable), step, rtol=1e-3)
    assert quantum_step(e[:1], usable[:1]) == 0.0


def test_the_floor_is_the_noise_sigmas_over_the_robust_scale_and_none_under_many_lights_or_by_default():
    step = 1 / 255
    e = _lattice(step)
    ok = np.ones(e.shape[:2], bool)
    assert np.isclose(relative_floor(e, ok, f_scale=0.05, sigmas=4.0), 4.0 * step / np.sqrt(12) / 0.05, rtol=1e-3)
    many = _lattice(step, m=FLOOR_MAX_LIGHTS + 1)
    assert relative_floor(many, np.ones(many.shape[:2], bool), sigmas=4.0) == 0.0
    assert NOISE_SIGMAS == 0.0 and relative_floor(e, ok) == 0.0          # off unless asked for
