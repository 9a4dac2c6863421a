"""The (σ, n_i) fit's solver (facette.fit._li_fit_lm): the analytic Jacobian against a finite
difference of the residuals, and the same minimum as scipy's trust region with finite differences."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from facette.brdf import kappa_from_kd, li_shading_terms
from facette.fit._li_fit_lm import li_jacobian, robust_lm
from facette.fit._li_model import _kd_and_residuals, _relative_fit_values, fit_li_per_pixel_kd
from facette.recon.synthetic import sphere_on_plane, thesis_light_directions


def _values(volume_model, sigma, n_i, noise=0.01):
    sc = sphere_on_plane(32, 32)
    normals = sc.normals[sc.sphere & (sc.normals[..., 2] > 0.3)].astype(np.float32)
    lights = thesis_light_directions().astype(np.float32)
    a, b = li_shading_terms(normals, lights, sigma, n_i, volume_model=volume_model)
    kappa = kappa_from_kd(np.array([0.6, 0.45, 0.3]), n_i, volume_model, sigma)
    e = a[..., None] + b[..., None] * kappa
    e *= 1 + noise * np.random.default_rng(0).normal(size=e.shape)
    return e.astype(np.float32), lights, normals, np.ones(e.shape[:2], bool)


@pytest.mark.parametrize("volume_model", ["tables", "coupled", "lambert"])
def test_the_jacobian_is_the_residuals_derivative(volume_model):
    e, lights, normals, ok = _values(volume_model, 0.15, 1.4)
    e0, w, _, den = _relative_fit_values(e, ok)
    p = (0.13, 1.37)             # inside one node cell in log σ and in n_i
    jac = li_jacobian(e0, w, den, normals, lights, *p, volume_model)
    for k, h in enumerate((2e-4, 2e-4)):
        dp = np.eye(2)[k] * h
        rp = _kd_and_residuals(e0, w, den, normals, lights, *(np.add(p, dp)), volume_model)[1].ravel()
        rm = _kd_and_residuals(e0, w, den, normals, lights, *(np.subtract(p, dp)), volume_model)[1].ravel()
        fd = (rp.astype(float) - rm) / (2 * h)
        assert np.abs(jac[:, k] - fd).max() < 0.02 * np.abs(fd).max(), (k, np.abs(jac[:, k] - fd).max())


@pytest.mark.parametrize("volume_model", ["tables", "coupled"])
def test_the_fit_finds_scipys_minimum_and_the_truth(volume_model):
    e, lights, normals, ok = _values(volume_model, 0.12, 1.45)
    got = fit_li_per_pixel_kd(e, lights, normals, ok, x0=(0.2, 1.3), volume_model=volume_model)
    e0, w, sel, den = _relative_fit_values(e, ok)

    def fun(p):
        return _kd_and_residuals(e0, w, den, normals, lights, p[0], p[1], volume_model)[1][sel].astype(float)
    ref = least_squares(fun, (0.2, 1.3), bounds=((1e-3, 1.0), (1.0, 2.5)), loss="soft_l1", f_scale=0.05,
                        diff_step=1e-3, x_scale=np.array([0.05, 0.1 * 0.3]))
    assert got["success"]
    assert abs(got["sigma"] - ref.x[0]) < 1e-3 and abs(got["n_i"] - ref.x[1]) < 2e-3, (got, ref.x)
    assert got["cost"] <= ref.cost * (1 + 1e-6)
    assert abs(got["sigma"] - 0.12) < 0.01 and abs(got["n_i"] - 1.45) < 0.03


def test_a_bound_holds_the_parameter_the_gradient_pushes_out():
    # the minimum of (x0 − 2)² + (x1 − 0.5)² within [0, 1]²: x0 stops on its upper bound
    def res(x):
        return np.array([x[0] - 2.0, x[1] - 0.5])

    def jac(x):
        return np.eye(2)
    r = robust_lm(res, jac, (0.2, 0.9), np.zeros(2), np.ones(2), f_scale=10.0, max_nfev=40, x_scale=np.ones(2))
    assert r.success and r.x[0] == 1.0 and abs(r.x[1] - 0.5) < 1e-6, r


@pytest.mark.parametrize("volume_model", ["lambert", "tables"])
def test_a_start_above_the_optimum_does_not_cross_to_the_saddle_at_n_i_one(volume_model):
    # from n_i 1.7 a full Gauss–Newton step crossed to n_i = 1 (no lobe: the lobe's derivatives
    # vanish there too) and the fit stopped on it at 7x the cost; capped steps reach the minimum
    e, lights, normals, ok = _values(volume_model, 0.15, 1.3)
    got = fit_li_per_pixel_kd(e, lights, normals, ok, x0=(0.15, 1.7), volume_model=volume_model)
    near = fit_li_per_pixel_kd(e, lights, normals, ok, x0=(0.14, 1.32), volume_model=volume_model)
    assert got["n_i"] > 1.2 and got["cost"] <= near["cost"] * (1 + 1e-4), (got["sigma"], got["n_i"], got["cost"], near["cost"])
    assert abs(got["sigma"] - 0.15) < 0.01 and abs(got["n_i"] - 1.3) < 0.02
