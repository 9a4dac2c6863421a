"""Measures of a normal's reliability from the default's own model (li_alternating's fitted (σ, n_i) per
material), tried for the uncertainty band and not taken (issue 50 item 3; `facette bench uncertainty
--candidates`, beside bench._uncertainty_candidates' measures).

Per pixel, on the lights the solve kept (usable, not flagged a cast shadow by the solve, n·l > 0), the
residual of the fitted model at the solution, r_i(n) = e_i − A_i(n) − B_i(n) κ(n) (facette.brdf.li_shading_terms,
κ in closed form for each n: variable projection, as the solve), and its Jacobian J (m, 2) over the normal's two
tangent angles (finite differences):
- `li laplace`: the Gauss–Newton (Laplace) covariance of the normal, s² (JᵀJ)⁻¹, s² = Σ r² / (k − 3) the
  residual variance over the k kept lights; its root trace (rad). "The curvature of the default's cost";
- `li crb`: (JᵀJ)⁻¹ alone (the noise taken equal everywhere): what the lights' geometry and the model's
  sensitivity allow, whatever the residual;
- `li split`: the default's per-pixel solve (facette.fit.refine_normals_li, the same model) on two halves of
  the lights drawn at random, each from the solution: the angle between the two halves' normals (rad). The
  disagreement between two honest solves;
- `li highlight residual`: the RMS residual of the fitted model under the kept lights whose mirror direction (half
  vector) lies within HIGHLIGHT_DEG of the normal (the highlight, where a misfit lobe shows);
- `lambertian both-kept`: the angle between the solution and the Lambertian least-squares normal on the lights both
  keep (the solve's kept lights that also carry the pixel for recon._uncertainty: lit, not the brightest share).
A material whose BRDF step did not run (Lambertian-like) is Lambert's model (A = 0, B = n·l).
Distant lights (m, 3) only; per-pixel lights give NaN.
"""
import numpy as np

from facette.brdf import li_shading_terms
from facette.fit import refine_normals_li
from facette.recon import _uncertainty as unc

__all__ = ["li_measures", "LI_CANDIDATES"]

LI_CANDIDATES = ("li laplace", "li crb", "li split", "li highlight residual", "lambertian both-kept")
_FD = 1e-3            # rad, the tangent angles' finite-difference step
_SPLIT_SEED = 0
HIGHLIGHT_DEG = 15.0   # a kept light whose half vector is this close to the normal lights its highlight


def _lambertian(mat):
    return mat is None or not mat.get("brdf_step") or mat.get("sigma") is None or (mat.get("n_i") or 1.0) <= 1.0


def _terms(n, lights, mat):
    """(A, B) (N, m) of the material's model at unit normals n (N, 3)."""
    if _lambertian(mat):
        b = np.maximum(n @ lights.T, 0.0)
        return np.zeros_like(b), b
    a, b = li_shading_terms(n.astype(np.float32), lights.astype(np.float32), mat["sigma"], mat["n_i"],
                            volume_model=mat.get("volume_model", "tables"))
    return a.astype(np.float64), b.astype(np.float64)


def _residual(n, e, w, lights, mat):
    """(N, m) weighted residual of the model at n, κ ≥ 0 in closed form."""
    a, b = _terms(n, lights, mat)
    kappa = np.maximum(np.sum(w * b * (e - a), 1) / np.maximum(np.sum(w * b * b, 1), 1e-30), 0.0)
    return (e - a - b * kappa[:, None]) * w


def laplace(e, w, n, lights, mat):
    """(root trace of s² (JᵀJ)⁻¹, root trace of (JᵀJ)⁻¹), each (N,) rad; e, w (N, m), n (N, 3) unit."""
    r = _residual(n, e, w, lights, mat)
    jac = np.empty(r.shape + (2,))
    for k, t in enumerate(unc._tangents(n)):
        nk = n + _FD * t
        nk /= np.linalg.norm(nk, axis=1, keepdims=True)
        jac[..., k] = (_residual(nk, e, w, lights, mat) - r) / _FD
    jtj = np.einsum("nmi,nmj->nij", jac, jac)
    jtj += (1e-9 * np.maximum(np.trace(jtj, axis1=1, axis2=2), 1e-30))[:, None, None] * np.eye(2)
    tr = np.trace(np.linalg.inv(jtj), axis1=1, axis2=2)
    k = (w > 0).sum(1)
    s2 = (r * r).sum(1) / np.maximum(k - 3, 1)
    return np.sqrt(s2 * tr), np.sqrt(tr)


def split_angle(e, w, n, lights, mat, seed=_SPLIT_SEED):
    """(N,) rad: the angle between the model's per-pixel solves on two random halves of the lights."""
    perm = np.random.default_rng(seed).permutation(len(lights))
    halves = (np.sort(perm[: len(lights) // 2]), np.sort(perm[len(lights) // 2:]))
    sigma, n_i, vm = (1e-3, 1.0, "lambert") if _lambertian(mat) else \
        (mat["sigma"], mat["n_i"], mat.get("volume_model", "tables"))
    sol = [refine_normals_li(e[:, h, None].astype(np.float32), lights[h].astype(np.float32), n.astype(np.float32),
                             sigma, n_i, usable=w[:, h] > 0, volume_model=vm).normals for h in halves]
    return np.arccos(np.clip(np.sum(sol[0] * sol[1], axis=1), -1.0, 1.0))


def both_kept_angle(e, w, n, lights):
    """(N,) rad: the angle between n (N, 3) and the Lambertian least-squares normal on the lights of weight w (N, m)."""
    lw = lights[None] * w[..., None]
    a = np.einsum("nmi,nmj->nij", lw, lw) + 1e-9 * np.eye(3)
    b = np.linalg.solve(a, np.einsum("nmi,nm->ni", lw, e * w)[..., None])[..., 0]
    b /= np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-30)
    return np.arccos(np.clip(np.sum(b * n, axis=1), -1.0, 1.0))


def li_measures(e, ok, n, lights, labels, materials, shadow=None):
    """{name: (N,) rad} of LI_CANDIDATES over N pixels.

    e (N, m) values as the solve saw them (the channels' mean), ok (N, m) usable, n (N, 3) unit normals,
    lights (m, 3), labels (N,) each pixel's index into `materials` (info["materials"] of the solve; −1 or
    out of range: Lambert's model), shadow (N, m) the solve's cast-shadow flags or None."""
    out = {name: np.full(len(e), np.nan) for name in LI_CANDIDATES}
    if np.ndim(lights) != 2:
        return out
    lights = np.asarray(lights, np.float64)
    keep = ok & (n @ lights.T > 0) & (True if shadow is None else ~shadow)
    w = keep.astype(np.float64)
    e = np.where(keep, e, 0.0)
    near = keep & (n @ unc._halves(lights).T > np.cos(np.radians(HIGHLIGHT_DEG)))
    materials = materials or []
    for label in np.unique(labels):
        p = np.flatnonzero(labels == label)
        mat = materials[label] if 0 <= label < len(materials) else None
        out["li laplace"][p], out["li crb"][p] = laplace(e[p], w[p], n[p], lights, mat)
        out["li split"][p] = split_angle(e[p], w[p], n[p], lights, mat)
        r = _residual(n[p], e[p], w[p], lights, mat)
        out["li highlight residual"][p] = np.sqrt((r * r * near[p]).sum(1) / np.maximum(near[p].sum(1), 1))
    both = (keep & (unc._carrying(e, ok) > 0)).astype(np.float64)
    out["lambertian both-kept"] = both_kept_angle(e, both, n, lights)
    return out
