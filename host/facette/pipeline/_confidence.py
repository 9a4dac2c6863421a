"""`process`'s confidence in each normal: the uncertainty map (facette.recon.normal_uncertainty),
its summary in process.json ("quality" → "normal_uncertainty"), its channel in normal.exr
("uncertainty_deg", beside X, Y, Z) and its map in report.html."""
import time

import numpy as np

from facette.recon import normal_uncertainty, uncertainty_summary

__all__ = ["uncertainty_stage", "normal_channels", "confidence_maps", "UNCERTAINTY_CHANNEL"]

UNCERTAINTY_CHANNEL = "uncertainty_deg"
NOT_WHOLE_NOTE = ("normal uncertainty: not computed with --memory over bands (the images are never held whole); "
                  "normal.exr has no uncertainty_deg channel")


def uncertainty_stage(res, images, light_dirs, saturation=None):
    """res.uncertainty (H, W) deg (the radius of each normal's 90 % band) from the images the
    method saw, and its summary in res.quality; None with a note when the images are not whole."""
    t0 = time.perf_counter()
    if images is None:
        res.notes.append(NOT_WHOLE_NOTE)
        return
    res.uncertainty = normal_uncertainty(images, light_dirs, res.normals, res.mask, saturation=saturation)
    summary = uncertainty_summary(res.uncertainty, res.mask)
    if summary is not None:
        res.quality["normal_uncertainty"] = summary
    res.timings["uncertainty"] = time.perf_counter() - t0


def normal_channels(res):
    """(image, channel names) of normal.exr: X, Y, Z and, when computed, uncertainty_deg."""
    if getattr(res, "uncertainty", None) is None:
        return res.normals, ("X", "Y", "Z")
    return np.concatenate([res.normals, res.uncertainty[..., None]], axis=2), ("X", "Y", "Z", UNCERTAINTY_CHANNEL)


def confidence_maps(res, st, mask, resid):
    """The report's confidence maps, as `_map` arguments [(args, kwargs)]: the least-squares
    residual (`resid`, decimated by st) and the uncertainty of each normal when computed."""
    top = max(float(np.nanpercentile(resid, 99)) if mask.any() else 1, 1e-6)
    maps = [(("Least-squares relative residual (low is Lambertian)", resid), {"cmap": "magma", "vmin": 0, "vmax": top})]
    unc = getattr(res, "uncertainty", None)
    if unc is not None:
        u = np.where(mask, unc[::st, ::st], np.nan)
        hi = max(float(np.nanpercentile(u, 95)) if mask.any() else 1, 1e-3)
        maps.append((("Uncertainty of the normal (deg): 90 % of the normals are within it of the truth", u),
                     {"cmap": "viridis", "vmin": 0, "vmax": hi, "label": "deg"}))
    return maps
