"""`process`'s relighting model (output "relight", relight_model.npz): `relight_model_stage`.

The model of `facette.recon._relight_model` fitted to the photographs process loaded (linear,
divided by the lights' intensities), with process's normals and its heights (for the cast
shadows). Its white (display 1) is the 99.9th percentile of the object's brightest channel over
the lights: the photographs' own scale, highlights above it clip as in a photograph.

Its cost grows with pixels x lights (about 5 us per pixel and light on one core), so the full
model is fitted only when relight_model.npz is asked for; for the report alone it is fitted at
the viewer's size (every st-th pixel, pipeline._viewer.MAX_SIDE), which is all the page shows.
"""
import time

import numpy as np

from facette.pipeline._viewer import MAX_SIDE
from facette.pipeline._viewer_model import VIEWER_PLANES
from facette.recon import fit_relight_model, save_relight_model

__all__ = ["relight_model_stage", "save_relight_model", "WHITE_PERCENTILE"]

WHITE_PERCENTILE = 99.9


def _white(images, mask, sample=200_000):
    rows, cols = np.nonzero(mask)
    pick = np.linspace(0, len(rows) - 1, min(sample, len(rows))).astype(int)
    vals = np.max(images[:, rows[pick], cols[pick]], axis=-1)
    vals = vals[np.isfinite(vals) & (vals > 0)]
    return float(np.percentile(vals, WHITE_PERCENTILE)) if vals.size else 1.0


def relight_model_stage(res, images, light_dirs, pixel_pitch_mm=1.0, write=None, every_pixel=True):
    """res.relight_model fitted (and res.timings["relight_model"]), then write("relight") (process's
    writer of relight_model.npz; run after the heights: the cast shadows need them); returns the notes. images
    (m, H, W, C) linear or None (read by bands with --memory: no model, a note says so);
    light_dirs (m, 3) or None (near lights: per-pixel directions, which the model does not take);
    every_pixel False: the model at the report viewer's size (every st-th pixel, heights in its pixels)."""
    if images is None:
        return ["relighting model: not fitted with --memory (it reads every photograph whole)"]
    if light_dirs is None or np.ndim(light_dirs) != 2:
        return ["relighting model: not fitted for near lights (it takes one direction per light)"]
    t0 = time.perf_counter()
    mask = np.asarray(res.object_mask if res.object_mask is not None else res.mask, bool)
    mask = mask & np.all(np.isfinite(res.normals), axis=-1) & (np.linalg.norm(res.normals, axis=-1) > 0.5)
    if images.shape[-1] == 1:
        images = np.broadcast_to(images, images.shape[:-1] + (3,))
    heights = None if res.height is None else np.where(mask, res.height / float(pixel_pitch_mm), np.nan)
    white = _white(images, mask)
    st = 1 if every_pixel else max(1, int(np.ceil(max(mask.shape) / MAX_SIDE)))
    cut = (slice(None, None, st), slice(None, None, st))
    res.relight_model = fit_relight_model(images[:, cut[0], cut[1]], light_dirs, mask[cut], res.normals[cut],
                                          heights=None if heights is None else heights[cut] / np.float32(st),
                                          white=white, n_planes=None if every_pixel else VIEWER_PLANES)
    res.timings["relight_model"] = time.perf_counter() - t0
    if write is not None:
        write("relight")
    return [f"relighting model: {n}" for n in res.relight_model.notes]
