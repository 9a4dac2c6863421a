"""The shared (σ, n_i) fit's solver: a bounded Levenberg–Marquardt on two parameters, soft-L1 loss,
with the model's analytic Jacobian (facette.brdf._shading_grad), κ in closed form at every step.

    li_jacobian(e0, w, den, normals, lights, sigma, n_i, volume_model, a=None, b=None) -> (N·m·C, 2)
    robust_lm(residuals, jacobian, x0, lo, hi, f_scale, max_nfev, x_scale) -> LMResult

Why not scipy.optimize.least_squares: with two parameters its trust-region machinery (an SVD and
quadratic models on the whole (n_values, 2) Jacobian, a few per step) cost as much as the model
(DiLiGenT cat, 96 lights, the nine fits of round 1: 1.0 of 2.7 CPU s), and a finite-difference
Jacobian two model evaluations a step. Here a step is one 2 × 2 solve of the robust normal equations
(the gradient Σ ρ' r J and the Gauss–Newton part of the soft-L1 cost's Hessian, the loss's curvature included), and the answer is the same minimum (the nine fits: σ, n_i within 1e-4 of scipy's).
"""
from dataclasses import dataclass

import numpy as np

from facette.brdf import li_shading_terms
from facette.brdf._shading_grad import li_shading_derivatives

__all__ = ["LMResult", "li_jacobian", "robust_lm"]

FTOL = 1e-8        # stop when an accepted step lowers the cost by less than this, relatively
XTOL = 1e-8        # or moves every (scaled) parameter by less than this
RADIUS = 1.0       # the first step's largest length, in x_scale units (doubled after each capped step taken)


@dataclass
class LMResult:
    x: np.ndarray
    cost: float
    success: bool
    message: str
    nfev: int


def li_jacobian(e0, w, den, normals, lights, sigma, n_i, volume_model, a=None, b=None):
    """(N·m·C, 2) ∂r/∂(σ, n_i) of facette.fit._li_model's relative residuals r = (E − A − B κ) / den,
    (N, m, C) raveled, with κ's closed form differentiated too (variable projection: ∂κ = (∂num −
    κ ∂den) / den where κ > 0; 0 where κ is clipped at 0). a, b : the shading terms at (σ, n_i) if
    already computed."""
    if a is None:
        a, b = li_shading_terms(normals, lights, sigma, n_i, volume_model=volume_model)
    d = li_shading_derivatives(normals, lights, sigma, n_i, volume_model)
    wb = w * b
    den_b = np.sum(wb * b, 1)
    ok = den_b > 1e-20
    inv = 1 / np.where(ok, den_b, 1)[:, None]
    resid_a = e0 - a[..., None]
    k_raw = np.einsum("nm,nmc->nc", wb, resid_a) * inv
    free = ok[:, None] & (k_raw > 0)
    k = np.where(free, k_raw, 0)
    cols = []
    for da, db in ((d[0], d[2]), (d[1], d[3])):
        d_num = np.einsum("nm,nmc->nc", w * db, resid_a) - np.sum(wb * da, 1)[:, None]
        dk = np.where(free, (d_num - k * (2 * np.sum(wb * db, 1))[:, None]) * inv, 0)
        cols.append((-(da[..., None] + db[..., None] * k[:, None, :] + b[..., None] * dk[:, None, :]) / den).ravel())
    return np.stack(cols, axis=1)


def _cost(r, f_scale):
    """Σ f² (√(1 + (r/f)²) − 1): scipy's soft-L1 cost (½ Σ ρ(r²))."""
    return float(np.sum(f_scale ** 2 * (np.sqrt(1 + (r / f_scale) ** 2) - 1)))


def robust_lm(residuals, jacobian, x0, lo, hi, f_scale, max_nfev, x_scale):
    """Minimise the soft-L1 cost of `residuals(x)` (n,) within lo ≤ x ≤ hi from x0, `jacobian(x)`
    (n, 2) at accepted points; x_scale : the parameters' typical steps (the damping's metric).
    At most max_nfev evaluations of `residuals`. Returns an LMResult."""
    x = np.clip(np.asarray(x0, float), lo, hi)
    r = residuals(x)
    cost, nfev, lam, radius = _cost(r, f_scale), 1, 1e-4, RADIUS
    message, success = "the evaluation budget ran out", False
    scale2 = np.asarray(x_scale, float) ** 2
    while nfev < max_nfev:
        jac = jacobian(x)
        z1 = 1 + (r / f_scale) ** 2
        grad = jac.T @ (r / np.sqrt(z1))                      # ρ'(z) r J
        # ρ' + 2 z ρ'' = (1 + z)^-1.5: the loss's own curvature along each residual (as scipy's
        # Triggs correction); ρ' alone (plain reweighting) converged in 10 steps where this takes 4
        hess = (jac * np.maximum(z1 ** -1.5, 1e-10)[:, None]).T @ jac
        # a parameter on its bound that the gradient pushes out stays there (its row dropped)
        free = ~(((x <= lo) & (grad > 0)) | ((x >= hi) & (grad < 0)))
        if not free.any() or np.all(np.abs(grad[free]) * np.sqrt(scale2[free]) <= 1e-12 * max(cost, 1e-30)):
            message, success = "the gradient vanishes", True
            break
        accepted = False
        while nfev < max_nfev:
            step = np.zeros(2)
            h = hess[np.ix_(free, free)] + lam * np.diag(np.maximum(np.diag(hess)[free], 1e-12 * scale2[free] ** -1))
            step[free] = np.linalg.solve(h, -grad[free])
            # at most `radius` typical steps at once: a full Gauss–Newton step from above the optimum
            # crossed to n_i = 1, where the lobe and its derivatives vanish (a saddle the fit stopped
            # on: the satin sphere from n_i 1.7 ended at 1.0, cost 7.3 against 0.99 at 1.30)
            move = np.clip(x + step, lo, hi) - x
            size = float(np.sqrt(np.sum(move ** 2 / scale2)))
            capped = size > radius
            if capped:
                move *= radius / size
            if -(grad @ step + 0.5 * step @ hess @ step) <= FTOL * cost:   # the model says no more to gain
                break
            x_new = np.clip(x + move, lo, hi)
            r_new = residuals(x_new)
            nfev += 1
            c_new = _cost(r_new, f_scale)
            if np.isfinite(c_new) and c_new < cost:
                accepted = True
                radius = 2 * radius if capped else radius
                break
            lam, radius = lam * 10, radius / 2 if capped else radius
            if np.all(np.abs(x_new - x) <= XTOL * (np.sqrt(scale2) + np.abs(x))):
                break
        if not accepted:
            message, success = ("the cost settled", True) if nfev < max_nfev else (message, False)
            break
        small = np.all(np.abs(x_new - x) <= XTOL * (np.sqrt(scale2) + np.abs(x)))
        drop = cost - c_new
        x, r, cost, lam = x_new, r_new, c_new, max(lam / 10, 1e-9)
        if drop <= FTOL * cost or small:
            message, success = "the cost settled", True
            break
    return LMResult(x=x, cost=cost, success=success, message=message, nfev=nfev)
