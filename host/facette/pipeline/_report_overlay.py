"""The report's picture of mask.png over the photograph (pipeline._report's maps)."""
import numpy as np

from facette.recon import srgb_encode

__all__ = ["mask_overlay"]


def mask_overlay(res, st):
    """(title, RGB): mask.png over the photograph (the median over the lights, sRGB): the
    object as photographed, the rest dimmed and tinted blue, the object's outline red."""
    obj = getattr(res, "object_mask", None)
    if obj is None or res.inputs is None or res.inputs.images is None:
        return None
    from facette.capture._pixels_jit import median_over_lights   # numba: loaded on first use
    obj, ims = obj[::st, ::st], res.inputs.images[:, ::st, ::st]
    photo = np.empty(ims.shape[1:], ims.dtype)  # np.nanmedian: 9 s of 40 on the 16-bit DiLiGenT ball
    median_over_lights(ims.reshape(ims.shape[:2] + (-1,)), photo.reshape(photo.shape[0], -1), slice(None), workers=2)
    photo = np.nan_to_num(photo, nan=1.0)                                # NaN: saturated everywhere
    top = float(np.percentile(photo[obj], 99)) if obj.any() else float(np.max(photo) or 1.0)
    rgb = srgb_encode(photo / max(top, 1e-12))
    out = np.where(obj[..., None], rgb, 0.35 * rgb + np.array([0.0, 0.05, 0.25]))
    edge = obj & ~(np.roll(obj, 1, 0) & np.roll(obj, -1, 0) & np.roll(obj, 1, 1) & np.roll(obj, -1, 1))
    out[edge] = [1.0, 0.1, 0.1]
    full = res.object_mask
    return (f"mask.png over the photograph (median over the lights): the object, {int(full.sum()):,} of "
            f"{full.size:,} px, outlined red; the rest dimmed", out)
