"""The re-solve measures tried for the uncertainty band (bench._uncertainty_bootstrap): the wild bootstrap through
the per-pixel solve spreads the normal as the noise does (Lambert's Cramér–Rao bound), and the cost's other valleys
weigh nothing on clean data and more as the noise grows."""
import numpy as np

from facette.bench._uncertainty_bootstrap import BOOTSTRAP_CANDIDATES, bootstrap_measures
from facette.recon.synthetic import thesis_light_directions


def _pixels(noise, count=300, seed=1):
    rng = np.random.default_rng(seed)
    lights = thesis_light_directions()
    n = rng.normal(size=(count, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e = np.maximum(n @ lights.T, 0.0)
    e = e + noise * rng.normal(size=e.shape)
    rc = np.stack(np.unravel_index(np.arange(count), (20, 15)), axis=1)
    return e, n, lights, rc


def _lambert_bound(n, lights, noise):
    """RMS angle (rad) of the Lambertian least-squares normal under noise: sqrt of the tangent part of
    noise² (LᵀL)⁻¹, unit albedo."""
    cov = noise ** 2 * np.linalg.inv(lights.T @ lights)
    tangent = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    return np.sqrt(np.einsum("nij,jk,nki->n", tangent, cov, tangent))


def test_the_wild_bootstrap_spreads_the_normal_as_the_noise_does():
    e, n, lights, rc = _pixels(0.02)
    m = bootstrap_measures(e / e.max(1, keepdims=True), np.ones(e.shape, bool), n, lights, np.full(len(e), -1),
                           None, None, rc)
    assert tuple(m) == BOOTSTRAP_CANDIDATES
    bound = _lambert_bound(n, lights, 0.02) / e.max(1)
    ratio = np.median(m["bootstrap wild"]) / np.median(bound)
    assert 0.6 < ratio < 1.6, ratio
    assert np.all(np.isfinite(np.stack(list(m.values()))))


def test_other_valleys_weigh_nothing_on_clean_data_and_more_with_noise():
    spread = {}
    for noise in (0.0, 0.05):
        e, n, lights, rc = _pixels(noise)
        m = bootstrap_measures(e / e.max(1, keepdims=True), np.ones(e.shape, bool), n, lights, np.full(len(e), -1),
                               None, None, rc)
        spread[noise] = np.degrees(np.median(m["valley spread"]))
    assert spread[0.0] < 0.1 and spread[0.05] > 10 * max(spread[0.0], 0.01)
