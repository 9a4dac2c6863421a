"""`process`'s relighting model (output "relight", relight_model.npz): `relight_model_stage`.

The model of `facette.recon._relight_model` fitted to the photographs process loaded (linear,
divided by the lights' intensities), with process's normals and its heights (for the cast
shadows), by `recon.fit_relight_bands`: read a band of rows at a time, from the whole images
or, with --memory (or a default budget the whole capture does not fit), from `ImagesSpill`: the
photographs as the band reader gave them, written to a temporary file during the PTM/HSH pass
(the heights the cast shadows need come after the reader is closed). Its white (display 1) is
the 99.9th percentile of the object's brightest channel over the lights (`recon._relight_fit.WHITE_PERCENTILE`):
the photographs' own scale, highlights above it clip as in a photograph.

Its cost grows with pixels x lights, so the full model is fitted only when relight_model.npz is
asked for; for the report (and model.glb's maps) alone it is fitted at MODEL_SIDE pixels along the
longest side (`report_step`): the viewer draws at most 900 px wide from its MAX_SIDE grid, and
the model's maps are repeated onto that grid (pipeline._viewer_model), its normals the viewer's
own. At the thesis camera's size (2144 x 1424 HDR) that is the last chain after the last frame.
"""
import time

import numpy as np

from facette._memory import disk_array, release
from facette.pipeline._viewer import MAX_SIDE
from facette.pipeline._viewer_model import VIEWER_PLANES
from facette.recon import fit_relight_bands, save_relight_model

__all__ = ["relight_model_stage", "save_relight_model", "ImagesSpill", "MODEL_BAND_BYTES",
           "MODEL_SIDE", "report_step", "model_input"]

MODEL_BAND_BYTES = 256 * 2 ** 20     # the photographs of one band of the model's fit read from a spill, at most
FIT_ROWS_PIXELS = 1 << 22            # pixels of the normals looked at a time (`_fitted_pixels`)
# the report's model, pixels along its longest side at most (a whole multiple of the viewer's step):
# at 2144 x 1424, 536 x 356 against the viewer's 1072 x 712
MODEL_SIDE = 550


def report_step(shape, side=None):
    """The report's model's pixel step on an image of `shape` (H, W): a whole multiple of the
    viewer's (pipeline._viewer.MAX_SIDE), its longest side at most `side` (MODEL_SIDE) pixels."""
    viewer = max(1, int(np.ceil(max(shape) / MAX_SIDE)))
    side = MODEL_SIDE if side is None else side
    return viewer * max(1, int(np.ceil(-(-max(shape) // viewer) / side)))


class ImagesSpill:
    """The photographs (m, H, W, C) float32 written band by band to a temporary file (no name:
    gone with this object), read back band by band (`read`), pages handed back after each."""

    def __init__(self, m, h, w, c=3):
        self.data, self.shape = None, (m, h, w, c)
        self.rows = max(1, MODEL_BAND_BYTES // (m * w * c * 4))

    def add(self, r0, images, dirs):
        """Rows r0.. of the images (m, b, W, C); nothing with per-pixel light directions (near
        lights: the model takes one direction per light)."""
        if np.ndim(dirs) != 2:
            return
        if self.data is None:
            self.data = disk_array(self.shape, np.float32)
        self.data[:, r0:r0 + images.shape[1]] = images
        release(self.data)

    def read(self, r0, r1):
        band = np.array(self.data[:, r0:r1])
        release(self.data)
        return band

    def close(self):
        """The file goes (its space back once nothing maps it): 12 B a pixel and light, 7.2 GB at 50 MP x 12."""
        self.data = None


def model_input(images, banded):
    """What the stage fits: the whole images, else the photographs `banded` (a
    `_rti_bands.RelightBands`, --memory) kept, else None."""
    return images if images is not None or banded is None else banded.model_images


def _reader(images, st):
    """(read(r0, r1) -> (linear (m, b, W, 3), None), band rows) at every st-th pixel, from whole
    images (m, H, W, C) or an `ImagesSpill`."""
    spill = isinstance(images, ImagesSpill)
    rows = max(1, images.rows // st) if spill else None

    def read(r0, r1):
        if spill:
            band = images.read(r0 * st, min(images.shape[1], r1 * st))[:, ::st, ::st]
        else:
            band = images[:, r0 * st:r1 * st:st, ::st]
        if band.shape[-1] == 1:
            band = np.broadcast_to(band, band.shape[:-1] + (3,))
        return band, None
    return read, rows


def _every(a, st):
    """a[::st, ::st], or `a` itself (a disk array stays one) at st 1."""
    return a if st == 1 else a[::st, ::st]


def _fitted_pixels(res, pixel_pitch_mm, st, spill):
    """(the pixels the model is fitted on: the object's with a unit normal, (H', W') bool; their heights in
    the model's pixels, NaN elsewhere, or None) at every st-th pixel, made FIT_ROWS_PIXELS at a time (the
    normals may be a disk array, its pages handed back after each band); the heights in a disk array with
    `spill`."""
    mask = _every(np.asarray(res.object_mask if res.object_mask is not None else res.mask, bool), st)
    normals, height = _every(res.normals, st), None if res.height is None else _every(res.height, st)
    h, w = mask.shape
    fitted = np.empty((h, w), bool)
    heights = None if height is None else disk_array((h, w), np.float32) if spill else np.empty((h, w), np.float32)
    rows = max(1, FIT_ROWS_PIXELS // max(w, 1))
    for r0 in range(0, h, rows):
        n = np.asarray(normals[r0:r0 + rows])
        ok = mask[r0:r0 + rows] & np.all(np.isfinite(n), axis=-1) & (np.linalg.norm(n, axis=-1) > 0.5)
        fitted[r0:r0 + rows] = ok
        if heights is not None:
            hb = np.where(ok, height[r0:r0 + rows] / float(pixel_pitch_mm), np.nan)
            heights[r0:r0 + rows] = hb if st == 1 else hb / np.float32(st)
            release(heights)
        release(normals)
    return fitted, heights


def relight_model_stage(res, images, light_dirs, pixel_pitch_mm=1.0, write=None, every_pixel=True):
    """res.relight_model fitted (and res.timings["relight_model"]), then write("relight") (process's
    writer of relight_model.npz; run after the heights: the cast shadows need them); returns the notes. images
    (m, H, W, C) linear, an `ImagesSpill` (read by bands), or None (read by bands with no spill: no
    model, a note says so); light_dirs (m, 3) or None (near lights: per-pixel directions, which the
    model does not take); every_pixel False: the model for the report (every `report_step`-th
    pixel, heights in its pixels)."""
    if images is None or (isinstance(images, ImagesSpill) and images.data is None):
        return ["relighting model: not fitted with --memory unless the relight output is asked for (it reads "
                "the photographs again after the heights, from a copy that output keeps)"]
    if light_dirs is None or np.ndim(light_dirs) != 2:
        return ["relighting model: not fitted for near lights (it takes one direction per light)"]
    t0 = time.perf_counter()
    st = 1 if every_pixel else report_step(res.mask.shape)
    spill = every_pixel and isinstance(images, ImagesSpill)      # over bands: the model's maps on disk too
    mask, heights = _fitted_pixels(res, pixel_pitch_mm, st, spill)
    read, rows = _reader(images, st)
    res.relight_model = fit_relight_bands(read, light_dirs, mask, _every(res.normals, st), heights=heights,
                                          white=None, n_planes=None if every_pixel else VIEWER_PLANES, rows=rows,
                                          spill=spill)
    if isinstance(images, ImagesSpill):      # read for the last time: its disk back before the file is written
        images.close()
    res.timings["relight_model"] = time.perf_counter() - t0
    if write is not None:
        write("relight")
    return [f"relighting model: {n}" for n in res.relight_model.notes]
