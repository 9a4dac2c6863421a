"""The default's own measures of a normal's reliability (bench._uncertainty_li): the Laplace covariance of
the fitted LI model predicts the spread of the model's own solve under noise, the bound without the residual
does not depend on the noise, and two half-light solves agree on clean data and part under noise."""
import numpy as np

from facette.bench._uncertainty_li import LI_CANDIDATES, li_measures
from facette.brdf import li_shading_terms
from facette.fit import refine_normals_li
from facette.recon.synthetic import thesis_light_directions

MAT = {"brdf_step": True, "sigma": 0.2, "n_i": 1.5, "volume_model": "approx"}


def _pixels(noise, count=200, seed=0):
    """count pixels of one normal under the rig's 12 lights and 40 more, the LI model plus noise."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(400, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    lights = np.concatenate([thesis_light_directions(), v[v[:, 2] > 0.4][:40]])
    n = np.array([[0.3, -0.2, 0.933]])
    n /= np.linalg.norm(n)
    a, b = li_shading_terms(n.astype(np.float32), lights.astype(np.float32), MAT["sigma"], MAT["n_i"],
                            volume_model=MAT["volume_model"])
    clean = (a + 0.4 * b).astype(np.float64)
    e = clean + noise * clean.max() * rng.normal(size=(count, len(lights)))
    return e, lights, np.repeat(n, count, axis=0)


def _measures(e, lights, n):
    ok = np.ones(e.shape, bool)
    return li_measures(e, ok, n, lights, np.zeros(len(e), np.intp), [MAT])


def test_laplace_predicts_the_spread_of_the_models_own_solve():
    e, lights, truth = _pixels(0.01)
    solved = refine_normals_li(e[..., None].astype(np.float32), lights.astype(np.float32), truth.astype(np.float32),
                               MAT["sigma"], MAT["n_i"], volume_model=MAT["volume_model"]).normals
    spread = np.sqrt(np.mean(np.arccos(np.clip(np.sum(solved * truth, 1), -1, 1)) ** 2))
    at = _measures(e, lights, solved.astype(np.float64))
    assert tuple(at) == LI_CANDIDATES
    predicted = np.sqrt(np.mean(at["li laplace"] ** 2))
    assert 0.6 < predicted / spread < 1.6


def test_laplace_grows_with_the_noise_and_the_bound_does_not():
    e1, lights, n = _pixels(0.005, count=50)
    e4, _, _ = _pixels(0.02, count=50)
    m1, m4 = _measures(e1, lights, n), _measures(e4, lights, n)
    assert 3 < np.median(m4["li laplace"]) / np.median(m1["li laplace"]) < 5
    assert 0.8 < np.median(m4["li crb"]) / np.median(m1["li crb"]) < 1.25


def test_halves_agree_on_clean_data_and_part_under_noise():
    clean = _measures(*_pixels(0.0, count=20))["li split"]
    noisy = _measures(*_pixels(0.02, count=20))["li split"]
    assert np.degrees(np.max(clean)) < 0.05
    assert np.degrees(np.median(noisy)) > 10 * np.degrees(np.max(clean)) and np.degrees(np.median(noisy)) > 0.2
