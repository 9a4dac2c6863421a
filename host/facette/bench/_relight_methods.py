"""The relighting methods `facette bench relight` compares, each fitted on some photographs.

A method is `fit(cap, train) -> Fitted` (train: the indices of the fitted photographs) whose
`raw(l)` is its display values (H, W, 3) under light l before any clipping (a viewer then clips
to [0, 1]), `size` its bytes per pixel as 8-bit planes, `why` a note. The polynomials are fitted
to the display values (sRGB-encoded), as RTIBuilder fits a dome's JPEGs.
"""
import shutil
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RBFInterpolator

from facette.errors import InsufficientData
from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.pipeline._relight import kd_map_from_albedo, relight, viewer_model
from facette.recon import (fit_hsh, fit_ptm_lrgb, hsh_basis, ptm_basis, ps_rank_trimmed, ps_woodham1980,
                           srgb_encode, integrate)
from facette.recon import fit_relight_model

__all__ = ["Fitted", "METHODS", "model_normals"]

RBF_PLANES = 18        # Relight's RBF: principal components of the pixels' 3m light responses


@dataclass
class Fitted:
    raw: object            # light (3,) -> (H, W, 3) display values, not clipped
    size: float            # bytes per pixel (8-bit planes)
    why: str = ""


def _ptm(cap, train):
    if len(train) < 6:
        return None
    fit = fit_ptm_lrgb(cap.lin[train], cap.dirs[train], mask=cap.mask, white=1.0, encoding="srgb")
    return Fitted(lambda d: (fit.coeffs @ ptm_basis(d))[..., None] * fit.rgb, 9)


def _hsh(order):
    def fit_fn(cap, train):
        if len(train) < order * order:
            return None
        fit = fit_hsh(cap.lin[train], cap.dirs[train], order, mask=cap.mask, white=1.0, encoding="srgb")
        return Fitted(lambda d: fit.coeffs @ hsh_basis(d, order), 3 * order * order)
    return fit_fn


def _rbf_relight(cap, train, widths=(1, 2, 4, 8), smoothings=(1e-3, 1e-2)):
    """Relight's RBF basis: the principal components (RBF_PLANES) of the pixels' light responses
    (3m values each) over the display values, each component's light function interpolated by a
    Gaussian RBF over the lights' (x, y) (width 1–8 × the lights' median spacing and smoothing
    chosen on the fitted photographs: every 8th, or each when fewer than 16, predicted from the rest)."""
    sel = np.nonzero(cap.mask)
    vals = cap.shown[train][:, sel[0], sel[1]]                          # (m, N, 3)
    m = len(train)
    rows = vals.transpose(1, 0, 2).reshape(len(sel[0]), m * 3).astype(np.float64)
    mean = rows.mean(axis=0)
    _, vecs = np.linalg.eigh((rows - mean).T @ (rows - mean))
    k = min(RBF_PLANES, m * 3)
    basis = vecs[:, ::-1][:, :k]                                       # (3m, k)
    coef = (rows - mean) @ basis                                       # (N, k)
    funcs = np.concatenate([mean[:, None], basis], axis=1).reshape(m, 3 * (k + 1))
    xy = cap.dirs[train, :2]
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    spacing = float(np.median(dist.min(axis=1)))
    folds = [np.arange(j, m, 8) for j in range(8)] if m >= 16 else [[j] for j in range(m)]
    best = None
    for mult in widths:
        for sm in smoothings:
            err = 0.0
            for f in folds:
                keep = np.setdiff1d(np.arange(m), f)
                rbf = RBFInterpolator(xy[keep], funcs[keep], kernel="gaussian", epsilon=1 / (mult * spacing),
                                      smoothing=sm)
                err += float(np.sum((rbf(xy[f]) - funcs[f]) ** 2))
            if best is None or err < best[0]:
                best = (err, mult, sm)
    rbf = RBFInterpolator(xy, funcs, kernel="gaussian", epsilon=1 / (best[1] * spacing), smoothing=best[2])

    def raw(d):
        f = rbf(np.asarray(d, float)[None, :2]).reshape(3, k + 1)          # per channel: mean, planes
        out = np.zeros(cap.mask.shape + (3,))
        out[sel] = f[:, 0][None] + coef @ f[:, 1:].T
        return out

    return Fitted(raw, k)


def model_normals(lin, dirs, mask):
    """Normals (H, W, 3) for the model: trimmed least squares (ranks) with 8 lights or more,
    plain least squares with fewer; heights (H, W, px) integrated from them."""
    fn = ps_rank_trimmed if len(dirs) >= 8 else ps_woodham1980
    ps = fn(lin, dirs, mask=mask)
    n = np.where(ps.valid[..., None] & mask[..., None], np.nan_to_num(ps.normal), np.nan)
    return n


def _model(shadows):
    def fit_fn(cap, train):
        n = model_normals(cap.lin[train], cap.dirs[train], cap.mask)
        ok = cap.mask & np.all(np.isfinite(n), axis=-1)
        heights = None
        if shadows:
            filled = np.where(ok[..., None], n, np.array([0, 0, 1.0]))
            heights = np.where(ok, integrate(filled, mask=ok), np.nan)
        model = fit_relight_model(cap.lin[train], cap.dirs[train], ok, n, heights=heights,
                                  shown=cap.shown[train])
        k = 0 if model.weights is None else model.planes.shape[-1]
        # how often the residual's floor darkens a pixel the physics lights, at raking light
        floored = np.mean([np.mean((np.any(model.display_unfloored(d) < 0, axis=-1)
                                    & np.any(model.physical(d) > 1e-3, axis=-1))[ok]) for d in _raking()])
        notes = model.notes + [f"k {model.shininess:g}, {k} planes; lit pixels the residual floors to black at "
                               f"75°: {100 * floored:.1f} %"]
        return Fitted(model.display_raw, 2 + 9 + 3 * k + (2 if shadows else 0), "; ".join(notes))
    return fit_fn


def _raking(theta_deg=75.0, n=8):
    az = np.radians(np.arange(n) * 360.0 / n)
    t = np.radians(theta_deg)
    return np.c_[np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.full(n, np.cos(t))]


def _pb_before(cap, train, work):
    """The report's viewer before this change: process() on the fitted photographs (normals,
    albedo, one LI BRDF), relit by `pipeline._relight.relight` with the K_d map from the albedo."""
    lin = cap.lin[train]
    top = max(float(np.max(lin)), 1e-6)
    u16 = np.round(np.clip(lin / top, 0, 1) * 65534).astype(np.uint16)
    # the BRDF fit wants radiance factors: one intensity that brings the typical bright pixel's
    # albedo to about 0.8, the predictions scaled back by it
    med = np.median((lin / top)[:, cap.mask][..., 1], axis=0)
    c = max(float(np.percentile(med, 99)), 1e-6) / (0.8 * 0.8 / np.pi)
    write_diligent(work, u16, cap.dirs[train], light_intensities=np.full((len(train), 3), c), mask=cap.mask)
    try:
        res = process(work, outputs=["normals", "albedo", "brdf"],
                      method="rank_trimmed" if len(train) >= 8 else "woodham1980", fit_options={"model": "li"})
    except InsufficientData as exc:
        return Fitted(None, 5, f"process: {exc}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    try:
        vm = viewer_model(res.brdf if res.brdf is not None else {"success": False, "message": "no BRDF"})
    except ValueError as exc:
        return Fitted(None, 5, str(exc))
    kd = kd_map_from_albedo(np.nan_to_num(res.albedo), res.mask, vm.kd, res.inputs.material_mask)
    scale = top * c
    return Fitted(lambda d: srgb_encode(np.clip(scale * relight(res.normals, kd, res.mask, vm, d), 0, 1)), 5)


METHODS = {"PTM": _ptm, "HSH 2": _hsh(2), "HSH 3": _hsh(3), "RBF (Relight)": _rbf_relight,
           "facette PB (before)": _pb_before, "facette (no shadows)": _model(False), "facette model": _model(True)}
