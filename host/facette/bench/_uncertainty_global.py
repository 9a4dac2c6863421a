"""Non-local measures of a normal's reliability (issue 50 item 3), tried for the uncertainty band beside the local
ones of bench._uncertainty_candidates (`facette bench uncertainty --candidates`). Each is computed from the solve's
own normals (and, for the visibility, the lights), over the whole object:

- `integrability 1px`, `integrability 2px`: the angle between each normal and the normal of the least-squares
  surface of the whole field (recon.integrate_least_squares on the mask), at full resolution and on the field
  averaged over 2 x 2 blocks. Any surface's normals agree with their own heights; where the solve's normals
  disagree with every integrable surface they are likely wrong. Unlike the curl (the non-integrability of one
  plaquette), the least-squares residual gathers the curl of the whole field (its divergence-free part, whose
  reach falls off as 1/distance);
- `sky view`: from those heights (pixels as the unit: an orthographic camera), the share of the hemisphere above
  each pixel's horizon (horizon-based ambient occlusion over HORIZON_AZIMUTHS directions, recon._shadows' march),
  reported as 1 − share (high: a pit that sees much surface, the light it gathers from itself);
- `hidden lights`: the share of the lights in front of the facet (n·l > FRONT_COS) that the heights' horizon hides
  (a cast shadow the heights imply: recon._shadows.hidden_lights, margin 0);
- `concavity`: minus the heights' Laplacian at 2 px (Gaussian), high in pits and grooves (inter-reflections).
"""
import numpy as np
from scipy.ndimage import gaussian_laplace

from facette.recon import integrate_least_squares
from facette.recon._shadows import hidden_lights, horizon_excess

__all__ = ["global_measures", "integrability_angle", "GLOBAL_CANDIDATES"]

GLOBAL_CANDIDATES = ("integrability 1px", "integrability 2px", "sky view", "hidden lights", "concavity")
HORIZON_AZIMUTHS = 16
FRONT_COS = 0.05


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def _height_normals(z, mask):
    """(H, W, 3) normals of heights z (pixel units, y up, row 0 the top): central differences where both
    neighbours lie in the mask, one-sided where one does."""
    def slope(axis):
        zf, zb = np.roll(z, -1, axis), np.roll(z, 1, axis)
        mf, mb = np.roll(mask, -1, axis), np.roll(mask, 1, axis)
        if axis == 0:
            mf[-1], mb[0] = False, False
        else:
            mf[:, -1], mb[:, 0] = False, False
        d = np.where(mf & mb, (zf - zb) / 2, np.where(mf, zf - z, np.where(mb, z - zb, 0.0)))
        return d
    dzdx = slope(1)
    dzdy = -slope(0)          # rows grow downwards, y upwards
    return _unit(np.stack([-dzdx, -dzdy, np.ones_like(z)], axis=-1))


def _angle(a, b):
    return np.arccos(np.clip(np.sum(_unit(a) * _unit(b), axis=-1), -1.0, 1.0))


def integrability_angle(normals, mask, block=1):
    """(H, W) rad: the angle between each normal and its least-squares surface's, the field first averaged over
    block x block cells (each pixel takes its cell's angle); 0 off the mask. Also returns the heights (pixels)."""
    n = np.asarray(normals, np.float64)
    mask = np.asarray(mask, bool)
    h, w = mask.shape
    if block > 1:
        hb, wb = -(-h // block) * block, -(-w // block) * block
        pad_n = np.zeros((hb, wb, 3))
        pad_n[:h, :w] = np.where(mask[..., None], n, 0)
        pad_m = np.zeros((hb, wb), bool)
        pad_m[:h, :w] = mask
        cells_n = pad_n.reshape(hb // block, block, wb // block, block, 3).sum((1, 3))
        cells_m = pad_m.reshape(hb // block, block, wb // block, block).sum((1, 3)) > block * block // 2
        ang, z = integrability_angle(_unit(cells_n) * cells_m[..., None], cells_m)
        up = np.repeat(np.repeat(ang, block, 0), block, 1)[:h, :w]
        return np.where(mask, up, 0.0), np.repeat(np.repeat(z, block, 0), block, 1)[:h, :w] * block
    z = np.asarray(integrate_least_squares(n, pixel_pitch_mm=1.0, mask=mask), np.float64)
    return np.where(mask, _angle(n, _height_normals(z, mask)), 0.0), z


def _visibility(z, mask, normals, lights):
    """(sky view: the share of the hemisphere below each pixel's horizon, hidden lights' share of the lights in
    front), each (H, W); the horizons by recon._shadows' march (the one the pipeline's cast shadows use)."""
    phi = 2 * np.pi * np.arange(HORIZON_AZIMUTHS) / HORIZON_AZIMUTHS
    level = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)     # elevation 0: the horizon itself
    elevation = np.radians(np.maximum(horizon_excess(z, mask, level), 0.0))
    occluded = np.mean(np.sin(elevation), axis=0)    # uniform solid angle: the band below elevation h holds sin h
    lights = np.asarray(lights, np.float64)
    if lights.ndim != 2:
        return occluded, np.full(mask.shape, np.nan)
    hidden, _ = hidden_lights(normals, mask, lights, 0.0)
    front = np.einsum("hwi,mi->mhw", normals, lights) > FRONT_COS
    return occluded, (hidden & front).sum(0) / np.maximum(front.sum(0), 1)


def global_measures(normals, sel, lights):
    """{name: (N,) over the pixels of sel (row-major), high = unreliable} of GLOBAL_CANDIDATES.

    normals (H, W, 3) the solve's, sel (H, W) bool (pixels with a normal), lights (m, 3) distant (per-pixel
    lights: `hidden lights` is NaN)."""
    mask = np.asarray(sel, bool) & (np.linalg.norm(normals, axis=-1) > 0.5)
    n = _unit(np.asarray(normals, np.float64))
    ang1, z = integrability_angle(n, mask)
    ang2, _ = integrability_angle(n, mask, block=2)
    sky, hidden = _visibility(z, mask, n, lights)
    concave = -gaussian_laplace(np.where(mask, z, 0.0), 2.0)
    sel = np.asarray(sel, bool)
    return {"integrability 1px": ang1[sel], "integrability 2px": ang2[sel], "sky view": sky[sel],
            "hidden lights": hidden[sel], "concavity": concave[sel]}
