"""Physically grounded measures of a normal's reliability, tried for the uncertainty band and not taken (issue
50 item 3; `facette bench uncertainty --candidates`, beside bench._uncertainty_candidates' measures). Each is
high where the normal is expected to be poor:
- `view tilt`: the normal's angle from the view axis (foreshortened, dark, near the silhouette);
- `front crb`: the Lambertian Cramér-Rao bound of the normal's two tangent angles from the lights in front of
  the facet (n·l > FRONT_COS), whatever their values: sqrt(tr I⁻¹), I = Σ P l lᵀ P, P = 1 − n nᵀ. Few lights in
  front, or all on one side of it, leave a tangent direction unconstrained;
- `front incidence`: 1 / Σ (n·l)₊, the lights in front weighted by their incidence (the light a facet gathers);
- `highlight count`: minus the number of lights whose mirror direction (half vector) lies within
  HIGHLIGHT_DEG of the normal: a glossy facet with no highlight leaves its lobe, and so its normal, less pinned;
- `cast-shadow share`: the share of the lights well in front (n·l > LIT_COS) under which the pixel is dark
  (below recon._uncertainty.T_DARK x its brightest): light the surface hides from it;
- `backlit share`: the share of its light that comes from lights behind the facet (n·l < −0.05): light the
  surface sends to itself (inter-reflections), or a wrong normal;
- `edge distance`: 1 / the distance (px) to the nearest pixel without a normal (silhouettes, depth edges);
- `shadow distance`: 1 / (1 + the distance (px) to the nearest pixel whose cast-shadow share exceeds SHADOW_SHARE);
- `normal variation 1px`, `normal variation 3px`: the angle between the normal and the field's Gaussian mean
  over 1 and 3 px (creases, folds, noise), at two scales;
- `calibration intensity`, `calibration direction`: how far the Lambertian least-squares normal b = A⁻¹ Σ l e on
  the carrying lights (recon._uncertainty._carrying) moves for independent errors of each light's intensity
  (relative, δb = A⁻¹ Σ l e s) or direction (δl ⊥ l, δb ≈ −A⁻¹ Σ l (b·δl)): the root trace of the tangential
  covariance per unit error (rad). An error common to the object (the lights' calibration) moves each normal
  by its own sensitivity.
"""
import numpy as np
from scipy.ndimage import distance_transform_edt, gaussian_filter

from facette.recon import _uncertainty as unc

__all__ = ["physics_measures", "PHYSICS_CANDIDATES", "normal_variation", "front_crb", "calibration_sensitivity"]

PHYSICS_CANDIDATES = ("view tilt", "front crb", "front incidence", "highlight count", "cast-shadow share",
                      "backlit share", "edge distance", "shadow distance", "normal variation 1px",
                      "normal variation 3px", "calibration intensity", "calibration direction")
FRONT_COS = 0.05      # a light this far above the facet's horizon is in front of it
LIT_COS = 0.2         # ... and this far, well in front (a dark value there is a cast shadow, not grazing light)
HIGHLIGHT_DEG = 10.0  # a half vector this close to the normal puts a highlight on the facet
SHADOW_SHARE = 0.25   # a pixel dark under this share of its lights in front is in cast shadow
UNCONSTRAINED = 1e6   # the bound where the lights in front leave a tangent direction free (ranks last, stays finite)


def _dots(n, d):
    """(N, m) n·d for unit normals n (N, 3) and directions d (m, 3) or per pixel (N, m, 3)."""
    return n @ d.T if d.ndim == 2 else np.einsum("ni,nmi->nm", n, d)


def front_crb(n, lights):
    """(N,) the Lambertian bound sqrt(tr I⁻¹) (rad per unit relative noise) from the lights in front of each facet;
    UNCONSTRAINED where they leave a tangent direction free (fewer than two, or all in one plane with n)."""
    lights = np.broadcast_to(lights, (len(n),) + lights.shape) if lights.ndim == 2 else lights
    front = (np.einsum("ni,nmi->nm", n, lights) > FRONT_COS).astype(np.float64)
    pl = lights - np.einsum("ni,nmi->nm", n, lights)[..., None] * n[:, None, :]       # P l, in the tangent plane
    info = np.einsum("nm,nmi,nmj->nij", front, pl, pl) + n[:, :, None] * n[:, None, :]  # + n nᵀ: invertible
    with np.errstate(divide="ignore", invalid="ignore"):
        det = np.linalg.det(info)
        inv = np.linalg.inv(np.where((det > 1e-9)[:, None, None], info, np.eye(3)))
    bound = np.sqrt(np.maximum(np.trace(inv, axis1=1, axis2=2) - 1.0, 0.0))
    return np.where(det > 1e-9, np.minimum(bound, UNCONSTRAINED), UNCONSTRAINED)


def calibration_sensitivity(e, ok, n, lights):
    """(intensity, direction) (N,) each: the tangential root trace of the Lambertian normal's covariance per unit
    relative error of each carrying light's intensity, and per unit (rad) error of its direction."""
    w = unc._carrying(e, ok)
    e = e / np.maximum((e * w).max(1, keepdims=True), 1e-30)
    lights = np.broadcast_to(lights, e.shape + (3,)) if lights.ndim == 2 else lights
    lw = lights * w[..., None]
    a_inv = np.linalg.inv(np.einsum("nmi,nmj->nij", lw, lw) + 1e-9 * np.eye(3))
    b = np.einsum("nij,nj->ni", a_inv, np.einsum("nmi,nm->ni", lw, e * w))
    rho = np.maximum(np.linalg.norm(b, axis=1), 1e-12)
    proj = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    nl = np.einsum("ni,nmi->nm", n, lights)
    out = []
    for weight in ((e * w) ** 2, w * (1 - nl ** 2) * rho[:, None] ** 2):   # δb's spread: intensity, direction
        middle = np.einsum("nm,nmi,nmj->nij", weight, lw, lw)
        cov = proj @ a_inv @ middle @ a_inv @ proj
        out.append(np.sqrt(np.maximum(np.trace(cov, axis1=1, axis2=2), 0.0)) / rho)
    return tuple(out)


def normal_variation(normals, has, sigma):
    """(H, W) rad: the angle between each normal and the Gaussian mean (sigma px) of the field over `has`."""
    w = has.astype(np.float64)
    mean = np.stack([gaussian_filter(normals[..., k] * w, sigma) for k in range(3)], axis=-1)
    mean /= np.maximum(np.linalg.norm(mean, axis=-1, keepdims=True), 1e-12)
    unit = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    return np.where(has, np.arccos(np.clip(np.sum(mean * unit, axis=-1), -1.0, 1.0)), 0.0)


def physics_measures(e, ok, n, lights, sel, normals):
    """{name: (N,) measure, high = unreliable} of PHYSICS_CANDIDATES over the N pixels of `sel` (row-major).

    e (N, m) values (any scale per pixel), ok (N, m) usable, n (N, 3) unit normals of those pixels,
    lights (m, 3) or (N, m, 3), sel (H, W) bool, normals (H, W, 3) the whole field (zero: no normal)."""
    lights = np.asarray(lights, np.float64)
    nl = _dots(n, lights)
    peak = np.max(np.where(ok, e, 0.0), axis=1)
    dark = ok & (e < unc.T_DARK * peak[:, None])
    lit = nl > LIT_COS
    shadow_share = (dark & lit).sum(1) / np.maximum(lit.sum(1), 1)
    total = np.maximum(np.where(ok, e, 0.0).sum(1), 1e-30)
    near = _dots(n, unc._halves(lights)) > np.cos(np.radians(HIGHLIGHT_DEG))
    sel = np.asarray(sel, bool)
    idx = np.flatnonzero(sel.ravel())
    normals = np.asarray(normals, np.float64)
    has = np.linalg.norm(normals, axis=-1) > 0.5
    shaded = np.zeros(sel.size, bool)
    shaded[idx] = shadow_share > SHADOW_SHARE
    to_shadow = distance_transform_edt(~shaded.reshape(sel.shape)) if shaded.any() else np.full(sel.shape, np.inf)
    out = {"view tilt": np.arccos(np.clip(n[:, 2], -1.0, 1.0)),
           "front crb": front_crb(n, lights),
           "front incidence": 1.0 / np.maximum(np.maximum(nl, 0.0).sum(1), 1e-3),
           "highlight count": -near.sum(1).astype(np.float64),
           "cast-shadow share": shadow_share,
           "backlit share": np.where(ok & (nl < -0.05), e, 0.0).sum(1) / total,
           "edge distance": 1.0 / np.maximum(distance_transform_edt(has).ravel()[idx], 1.0),
           "shadow distance": 1.0 / (1.0 + to_shadow.ravel()[idx])}
    for sigma in (1, 3):
        out[f"normal variation {sigma}px"] = normal_variation(normals, has, sigma).ravel()[idx]
    out["calibration intensity"], out["calibration direction"] = calibration_sensitivity(e, ok, n, lights)
    return out
