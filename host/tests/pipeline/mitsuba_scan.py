"""Scan directories written from Mitsuba renders (the tests of `process` on an independent renderer)."""
import json
import tempfile

import numpy as np

from facette.io.exr import write_exr

SCALE = 4.0            # the Spectralon's HDR units per unit irradiance written into scan.json


def render(shape, material, size=64, spp=32, max_depth=4):
    """One Mitsuba scene (facette.bench._mitsuba_scenes.render_scene), rendered afresh; max_depth 2:
    direct light only (no inter-reflections)."""
    from facette.bench._mitsuba_scenes import render_scene
    with tempfile.TemporaryDirectory() as tmp:
        return render_scene(shape, material, size=size, spp=spp, cache_dir=tmp, max_depth=max_depth)


def calibrated_scan(folder, d, scale=SCALE, truth=None, noise=None):
    """A scan directory of the render: HDR images in the calibration's units (the radiance factor
    x intensity x scale), scan.json with the radiometric scale; `truth` keys into truth.npz; noise:
    a Gaussian standard deviation (radiance factor) added to every value and written as its variance."""
    m = len(d["light_dirs"])
    inten = np.full((m, 3), 2.0)
    rng = np.random.default_rng(7)
    (folder / "hdr").mkdir(parents=True)
    for i in range(m):
        im = d["images"][i] + (0 if noise is None else rng.normal(scale=noise, size=d["images"][i].shape))
        var = 1e-8 if noise is None else (noise * inten[i, 1] * SCALE) ** 2
        write_exr(folder / "hdr" / f"light_{i:02d}.exr", (im * inten[i] * SCALE).astype(np.float32))
        write_exr(folder / "hdr" / f"light_{i:02d}_var.exr", np.full(d["images"][i].shape, var, np.float32))
    if truth is not None:
        np.savez(folder / "truth.npz", **truth)
    (folder / "scan.json").write_text(json.dumps({
        "schema": 1, "rig": {"id": "test"}, "profile": None, "pixel_pitch_mm": 0.1,
        "lights": [{"index": i, "direction": d["light_dirs"][i].tolist(), "position_mm": None,
                    "intensity": inten[i].tolist()} for i in range(m)],
        "exposures": [{"index": 0, "time_us": 1000, "current_mA": 100, "mode": "camera"}],
        "frames": [{"file": f"raw/L{i:02d}_E00.dng", "light": i, "exposure": 0, "time_us": 1000,
                    "current_set_mA": 100, "current_meas_mA": 100, "start_us": 0, "sync": True, "sha256": ""}
                   for i in range(m)],
        "rig_time_s": 0.0, "radiometric_scale": None if scale is None else [scale] * 3,
        "truth": None if truth is None else "truth.npz"}))
    return folder
