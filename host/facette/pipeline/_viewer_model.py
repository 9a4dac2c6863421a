"""The relighting model (recon._relight_model) packed for the report's WebGL viewer.

Shipped at the viewer's size (every st-th pixel): the diffuse, lobe and gathered-light maps as
RGBA8, each channel v = sqrt(x / scale) (a square-root code: dark values keep their levels), the
heights as float16 (pixels of the viewer's grid; the shader marches them for the cast shadows),
the residual's first 16 planes as RGBA8 layers (plane j = bias_j + scale_j · byte / 255), and
the kernel of the planes' light functions (centres, weights, ε and the HSH order-2 trend), which
viewer.js evaluates per frame. `packed_model` returns the model rebuilt from exactly what was shipped: the Python
reference of the page (`RelightModel.display`).
"""
import base64

import numpy as np

from facette.recon import RelightModel

__all__ = ["model_data", "packed_model"]

NO_HEIGHT = -60000.0        # float16 stand-in for "no surface" (never casts a shadow)
VIEWER_PLANES = 16          # residual planes the shader draws (its uniform arrays)


def _b64(a):
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _sqrt8(x, mask):
    scale = float(np.max(x[mask])) if mask.any() else 0.0
    scale = scale if scale > 0 else 1.0
    v = np.round(np.sqrt(np.clip(x / scale, 0, 1)) * 255).astype(np.uint8)
    rgba = np.zeros(x.shape[:2] + (4,), np.uint8)
    rgba[..., :3] = np.where(mask[..., None], v, 0)
    rgba[..., 3] = np.where(mask, 255, 0)
    return rgba, scale


def _planes8(planes, mask):
    k = planes.shape[-1]
    out = np.zeros((k,) + planes.shape[:2] + (4,), np.uint8)
    lo, hi = np.zeros(k), np.ones(k)
    for j in range(k):
        p = planes[..., j].astype(np.float32)
        if mask.any():
            lo[j], hi[j] = float(p[mask].min()), float(p[mask].max())
        span = hi[j] - lo[j] if hi[j] > lo[j] else 1.0
        hi[j] = lo[j] + span
        out[j, ..., :3] = np.where(mask[..., None], np.round((p - lo[j]) / span * 255), 0)
        out[j, ..., 3] = 255
    return out, lo, hi - lo


def model_data(model, st, mask):
    """(JSON-ready dict, the model as shipped) of `model` at every st-th pixel; mask: the
    viewer's pixels (at that size)."""
    # process fits the model at the viewer's size when relight_model.npz is not asked for
    small = (model if model.mask.shape == np.shape(mask) else model.decimated(st)).first_planes(VIEWER_PLANES)
    mask = np.asarray(mask, bool) & small.mask
    maps, scales = [], []
    for x in (small.rho, small.spec, small.amb):
        rgba, sc = _sqrt8(x, mask)
        maps.append(rgba)
        scales.append(sc)
    data = {"shininess": small.shininess, "softness": small.softness, "map_scales": scales,
            "rho": _b64(maps[0]), "spec": _b64(maps[1]), "amb": _b64(maps[2]), "heights": None,
            "planes": None, "n_planes": 0}
    decoded = [s * (m[..., :3].astype(np.float32) / 255) ** 2 for m, s in zip(maps, scales)]
    heights = None
    if small.heights is not None:
        h = np.where(mask & np.isfinite(small.heights), small.heights, NO_HEIGHT).astype(np.float16)
        data["heights"] = _b64(h)
        heights = np.where(h == np.float16(NO_HEIGHT), np.nan, h.astype(np.float32))
    planes = None
    if small.weights is not None:
        p8, bias, scale = _planes8(small.planes, mask)
        data.update(planes=_b64(p8), n_planes=int(p8.shape[0]), plane_bias=bias.tolist(),
                    plane_scale=scale.tolist(), centres=small.centres.ravel().tolist(),
                    weights=small.weights.ravel().tolist(), epsilon=small.epsilon, n_lights=len(small.centres),
                    spacing=small.spacing, reach=small.reach,
                    trend=None if small.trend is None else small.trend.ravel().tolist())
        planes = (bias + scale * p8[..., :3].astype(np.float32).transpose(1, 2, 3, 0) / 255).astype(np.float32)
    shipped = RelightModel(small.normals, mask, decoded[0], decoded[1], decoded[2], small.shininess, heights,
                           planes, small.centres, small.weights, small.epsilon, small.white, small.softness,
                           small.spacing, small.reach, trend=small.trend)
    return data, shipped


def packed_model(model, st, mask):
    """The model rebuilt from what `model_data` ships (the page's Python reference: its first
    VIEWER_PLANES residual planes)."""
    return model_data(model, st, mask)[1]
