"""A small scan directory (scan.json + hdr/ + truth.npz) from synthetic images: the input of
the report viewer's test and benchmark (facette.recon.synthetic scenes, no rig)."""
import json

import numpy as np

from facette.io.exr import write_exr
from facette.scan.directory import ScanDirectory
from facette.recon.synthetic import thesis_light_directions

__all__ = ["write_scan"]


def write_scan(folder, scene, images, pixel_pitch_mm=0.1, truth_brdf=None, albedo=(0.6, 0.5, 0.4)):
    """Write `images` (12, H, W, 3), rendered under the thesis lights with unit intensity, as a
    scan directory in `folder` (created), with scene's normals, heights and mask as truth.

    truth_brdf : dict stored as truth.npz's "brdf" (default: the "satin" Cook–Torrance of
    facette.recon.synthetic.render). Returns the folder.
    """
    L = thesis_light_directions()
    if len(images) != len(L):
        raise ValueError(f"expected one image per thesis light ({len(L)}), got {len(images)}")
    lights = [{"index": i, "direction": L[i].tolist(), "position_mm": None, "intensity": [1.0, 1.0, 1.0]}
              for i in range(len(L))]
    (folder / "hdr").mkdir(parents=True)   # FileExistsError rather than mixing two scans in one folder
    for i in range(len(L)):
        write_exr(folder / "hdr" / f"light_{i:02d}.exr", images[i])
    brdf = truth_brdf or {"model": "cook_torrance", "params": {"sigma": 0.15, "n_i": 1.3}}
    np.savez(folder / "truth.npz", normals=scene.normals, height_mm=scene.height * pixel_pitch_mm,
             mask=scene.mask, albedo=np.broadcast_to(albedo, scene.normals.shape).astype(np.float32),
             light_dirs=L, brdf=json.dumps(brdf))
    sd = ScanDirectory(folder)
    sd.create(rig={"id": "synthetic"}, profile=None, pixel_pitch_mm=pixel_pitch_mm, lights=lights,
              exposures=[], plan=None)
    sd.manifest.set_truth("truth.npz")
    sd.save()
    return folder
