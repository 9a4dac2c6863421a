"""The report viewer's relit picture against the photographs, for the size its model is fitted at.

`viewer_psnr(res)`: the relighting model exactly as report.html ships it (`pipeline._viewer.viewer_data`,
arrays["sv_model"]) rendered under each captured light, against that photograph at the viewer's
size, in 8-bit display values (the model's white = 1, sRGB), over the viewer's pixels: the median
over lights of the PSNR (dB). The lights are the fitted ones: this says what the page shows of
the photographs, not how the model predicts a light it never saw (bench relight does that).
`facette bench e2e --viewer SCAN_DIR` runs `process` (report's outputs) with the model fitted at
each side asked for and prints its PSNR and the model stage's time.
"""
import time
from pathlib import Path

import numpy as np

__all__ = ["viewer_psnr", "viewer_rows"]


def viewer_psnr(res):
    """(median PSNR dB over lights, (min, max)) of the report viewer's model against res.inputs.images."""
    from facette.bench.relight import psnr8, to8
    from facette.pipeline._viewer import viewer_data
    from facette.recon import srgb_encode

    inp = res.inputs
    data, arrays = viewer_data(res.normals, res.mask, res.brdf, albedo=res.albedo, height=res.height,
                               pitch_mm=inp.pixel_pitch_mm, material_mask=inp.sample_mask(),
                               relight_model=res.relight_model)
    model, st = arrays["sv_model"], data["decimation"]
    values = []
    for i, light in enumerate(np.asarray(inp.light_dirs, np.float64)):
        photo = np.asarray(inp.images[i, ::st, ::st], np.float32)
        if photo.shape[-1] == 1:
            photo = np.repeat(photo, 3, axis=-1)
        ok = model.mask & np.all(np.isfinite(photo), axis=-1)
        photo8 = to8(srgb_encode(np.clip(np.nan_to_num(photo) / model.white, 0, 1)))
        values.append(psnr8(to8(model.display(light)), photo8, ok))
    return float(np.median(values)), (float(np.min(values)), float(np.max(values)))


def viewer_rows(scan_dir, sides):
    """[(side, model stage wall s, its thread CPU s, median PSNR, (min, max))] of `process` (what the
    viewer needs: normals, height, the report's model; nothing written) with the report's model
    fitted at each `side` (pipeline._relight_model_stage.MODEL_SIDE)."""
    import facette.pipeline._process as proc
    import facette.pipeline._relight_model_stage as stage
    from facette.pipeline import process

    rows, saved = [], stage.MODEL_SIDE
    try:
        for side in sides:
            stage.MODEL_SIDE = side
            cpu = {}
            fit = stage.relight_model_stage

            def timed(*a, **k):
                c0 = time.process_time()      # the only stage running: the heights are done
                try:
                    return fit(*a, **k)
                finally:
                    cpu["model"] = time.process_time() - c0
            proc.relight_model_stage = timed
            try:
                res = process(Path(scan_dir), outputs=["normals", "height", "report"], out_dir=None)
            finally:
                proc.relight_model_stage = fit
            rows.append((side, res.timings.get("relight_model", np.nan), cpu.get("model", np.nan),
                         *viewer_psnr(res)))
    finally:
        stage.MODEL_SIDE = saved
    return rows
