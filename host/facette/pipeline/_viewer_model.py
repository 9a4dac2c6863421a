"""The relighting model (recon._relight_model) packed for the report's WebGL viewer.

Shipped at the viewer's size (every st-th pixel): the diffuse, lobe and gathered-light maps as
RGBA8, each channel v = sqrt(x / scale) (a square-root code: dark values keep their levels), the
heights as float16 (pixels of the viewer's grid; the shader marches them for the cast shadows),
the residual's first 16 planes as RGBA8 layers (plane j = bias_j + scale_j · byte / 255), and
the kernel of the planes' light functions (centres, weights, ε and the HSH order-2 trend), which
viewer.js evaluates per frame. A model fitted coarser than the viewer's grid (process fits the
report's at pipeline._relight_model_stage.MODEL_SIDE) has its maps repeated onto that grid
(`onto_grid`: each of its pixels covers f x f of the viewer's), the viewer's own normals beside
them. `packed_model` returns the model rebuilt from exactly what was shipped: the Python
reference of the page (`RelightModel.display`).
"""
import base64

import numpy as np

from facette.recon import RelightModel

__all__ = ["model_data", "packed_model", "onto_grid"]

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


def _coarser_by(model_shape, shape):
    """f such that a grid of `shape` taken every f-th pixel is `model_shape`, or None."""
    for f in range(2, max(shape) + 1):
        if (-(-shape[0] // f), -(-shape[1] // f)) == tuple(model_shape):
            return f
    return None


def _repeated(a, f, shape):
    """a (h, w, ...) with each pixel repeated f x f, cut to shape (H, W)."""
    return np.repeat(np.repeat(a, f, axis=0), f, axis=1)[:shape[0], :shape[1]]


def _textured(x, albedo, f, most=4.0):
    """x (H, W, 3) repeated from every f-th pixel, times each pixel's albedo over the albedo of the
    pixel it was repeated from (per channel, at most `most`; 1 where that albedo is not above 0)."""
    a = np.asarray(albedo, np.float32)
    a = np.repeat(a, 3, axis=-1) if a.ndim == 2 or a.shape[-1] == 1 else a[..., :3]
    at = _repeated(a[::f, ::f], f, a.shape[:2])
    ok = np.isfinite(a) & np.isfinite(at) & (at > 0)
    ratio = np.where(ok, np.clip(np.nan_to_num(a) / np.where(ok, at, 1), 0, most), 1).astype(np.float32)
    return x * ratio


def onto_grid(model, st, shape, normals=None, albedo=None):
    """`model` on the viewer's grid (H, W) = shape, the image's every st-th pixel: decimated when it
    was fitted finer (st itself when it has every pixel), its maps repeated when coarser (normals:
    the viewer's own (H, W, 3), else the model's repeated too; albedo: photometric stereo's (H, W, C)
    on that grid, whose ratio to its value at the fitted pixel carries the texture into the diffuse,
    lobe and gathered-light maps, `_textured`)."""
    if model.mask.shape == tuple(shape):
        return model
    f = _coarser_by(model.mask.shape, shape)
    if f is None:
        return model.decimated(st)
    if normals is None:
        normals = _repeated(model.normals, f, shape)
    up = [None if x is None else _repeated(x, f, shape)
          for x in (model.mask, model.rho, model.spec, model.amb, model.heights, model.planes)]
    mask = up[0] & np.all(np.isfinite(normals), axis=-1)
    if albedo is not None:       # a 256 x 192 scan, the model at 128 px: 26.1 dB -> 32.1 (36.0 fitted at 256)
        up[1:4] = [_textured(x, albedo, f) for x in up[1:4]]
    return RelightModel(np.asarray(normals, np.float32), mask, up[1], up[2], up[3], model.shininess,
                        None if up[4] is None else up[4] * np.float32(f), up[5], model.centres, model.weights,
                        model.epsilon, model.white, model.softness * f, model.spacing, model.reach,
                        list(model.notes), model.trend)


def model_data(model, st, mask, normals=None, albedo=None):
    """(JSON-ready dict, the model as shipped) of `model` at every st-th pixel; mask: the
    viewer's pixels (at that size); normals, albedo: the viewer's (at that size: `onto_grid`)."""
    small = onto_grid(model, st, np.shape(mask), normals, albedo).first_planes(VIEWER_PLANES)
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
