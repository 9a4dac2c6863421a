"""The re-solve measures tried for the uncertainty band (bench._uncertainty_bootstrap): the wild bootstrap through
the per-pixel solve spreads the normal as the noise does (Lambert's Cramér–Rao bound), and the cost's other valleys
weigh nothing on clean data and more as the noise grows; the lights' calibration error is found from all the pixels
(bench._uncertainty_selfcal); a tinted bounce parts the colour channels' normals."""
import numpy as np

from facette.bench._uncertainty_bootstrap import BOOTSTRAP_CANDIDATES, bootstrap_measures, channel_spread
from facette.bench._uncertainty_selfcal import light_corrections, selfcal_shift
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


def test_the_lights_calibration_error_is_found_from_all_the_pixels():
    rng = np.random.default_rng(3)
    lights = thesis_light_directions()
    n = rng.normal(size=(3000, 3)) * [0.4, 0.4, 0.0] + [0.0, 0.0, 1.0]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    true = lights.copy()
    tilt = np.radians(2.0)                                     # light 0 is 2 deg off what the calibration says
    t1 = np.cross(true[0], [0.0, 0.0, 1.0])
    t1 /= np.linalg.norm(t1)
    true[0] = np.cos(tilt) * true[0] + np.sin(tilt) * t1
    gain = np.ones(len(lights))
    gain[1] = 1.1                                              # light 1 is 10 % brighter than calibrated
    e = np.maximum(n @ true.T, 0.0) * gain + 0.002 * rng.normal(size=(len(n), len(lights)))
    w = (n @ lights.T > 0).astype(np.float64)
    labels = np.full(len(n), -1)
    scale, moved = light_corrections(e * w, w, n, lights, labels, None)
    # a gain common to all the lights is every pixel's albedo's (no data tell them apart): light 1 against the rest
    rest = np.median(np.delete(scale, 1))
    assert 0.07 < scale[1] - rest < 0.12 and np.all(np.abs(np.delete(scale, 1) - rest) < 0.02)
    off = np.degrees(np.arccos(np.clip(np.sum(moved * true, 1), -1, 1)))
    # light 0's 2 deg found; with each pixel's albedo free, the 12 lights near the axis are pinned to ~0.5 deg
    assert off[0] < 0.6 and np.all(off < 0.6), off
    shift = selfcal_shift(e * w, w, n, lights, labels, None, np.arange(500))
    assert np.all(np.isnan(shift[500:])) and np.degrees(np.median(shift[:500])) > 0.1


def test_a_tinted_bounce_parts_the_channels_normals():
    rng = np.random.default_rng(4)
    lights = thesis_light_directions()
    n = rng.normal(size=(400, 3)) * [0.3, 0.3, 0.0] + [0.0, 0.0, 1.0]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    shade = np.maximum(n @ lights.T, 0.0)
    vals = shade[..., None] * np.array([0.8, 0.5, 0.3])                # a coloured Lambertian surface
    bounce = np.maximum(lights @ [0.6, 0.0, 0.8], 0.0)                  # light a wall on the left sends back
    vals[200:] += 0.3 * bounce[None, :, None] * np.array([0.8, 0.5, 0.3]) ** 2    # tinted: albedo squared
    m = channel_spread(vals, np.ones(shade.shape, bool), n, lights, np.full(len(n), -1), None, None)
    assert np.degrees(np.median(m[:200])) < 0.01 and np.degrees(np.median(m[200:])) > 1.0   # 0.0004 and 3.0 deg
