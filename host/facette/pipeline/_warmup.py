"""Compile every numba kernel once, ahead of the first real run: `python -m facette.pipeline._warmup`.

The kernels are `@njit(cache=True)`: numba writes the machine code it compiles to a cache (a folder
named by a digest of the kernels' sources, facette._kernel_cache, or NUMBA_CACHE_DIR when set) and
later processes load
it instead of compiling (0.1 s against ~15 s for the whole set). On a fresh machine that cache
is empty, so the first `facette process` paid for the compilation (the demo scan's photometric
stereo: 18.3 s the first time, 1.45 s the second). `make setup` runs this module: it runs the
real chain, `process` with every output, on two tiny generated inputs (a scan directory and a
DiLiGenT-style folder, 96x128 px) and every photometric-stereo method on the same images, so that
each kernel is compiled for the array types the real runs hand it, and cached.

When any kernel's source changes (a `git pull`), the digest changes and every kernel is compiled
again on its next use (numba alone would recompile only the changed file's kernels, and keep the old
code of a kernel it inlined into another file's). Run this module again after an update to pay that
before a scan rather than during one; it deletes the caches of earlier sources.
"""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["warm_up"]

SIZE = (96, 128)       # rows, columns: large enough for the light-gains step, which a smaller capture skips
COARSE = 2000          # li_alternating's coarse-to-fine path (scans above 250 000 pixels), forced here


def _scan_folder(folder, scene, images, lights):
    """A scan directory (scan.json + hdr/*.exr) of `images` (m, H, W, 3) under `lights` (m, 3)."""
    from facette.io.exr import write_exr
    from facette.scan.directory import ScanDirectory
    (folder / "hdr").mkdir(parents=True)
    for i, img in enumerate(images):
        write_exr(folder / "hdr" / f"light_{i:02d}.exr", img)
    sd = ScanDirectory(folder)
    sd.create(rig={"id": "warm-up"}, profile=None, pixel_pitch_mm=0.1,
              lights=[{"index": i, "direction": lights[i].tolist(), "position_mm": None,
                       "intensity": [1.0, 1.0, 1.0]} for i in range(len(lights))],
              exposures=[], plan=None)
    sd.save()
    return folder


def _inputs(root, size):
    """Two tiny inputs of a glossy sphere on a plane under the rig's 12 lights: (scan, folder)."""
    from facette.io.diligent import write_diligent
    from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
    lights = thesis_light_directions()
    scene = sphere_on_plane(*size)
    images = render(scene, lights, "glossy", noise=0.002, rng=np.random.default_rng(0))
    scan = _scan_folder(root / "scan", scene, images.astype(np.float32), lights)
    u16 = np.round(np.clip(images / images.max(), 0, 1) * 50000).astype(np.uint16)
    write_diligent(root / "folder", u16, lights, None, scene.mask)
    return scan, root / "folder", images.astype(np.float32), lights, scene.mask


def warm_up(verbose=True, size=SIZE):
    """Run `process` (every output) on a tiny scan and folder of `size` (rows, columns), every
    method once on a partial and a whole mask, li_alternating coarse-to-fine; returns seconds."""
    from facette.methods import PS_METHODS, photometric_stereo
    from facette.pipeline._process import process
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="facette-warmup-") as tmp:
        root = Path(tmp)
        scan, folder, images, lights, mask = _inputs(root, size)
        for name, src in (("scan", scan), ("folder", folder)):
            t = time.perf_counter()
            process(src, out_dir=root / f"out-{name}")
            if verbose:
                print(f"warm-up: process on a {name}: {time.perf_counter() - t:.1f} s", flush=True)
        whole = np.ones_like(mask)         # a mask of every pixel takes other array layouts
        for method in dict.fromkeys(PS_METHODS.canonical(m) for m in PS_METHODS.names()):
            t = time.perf_counter()
            for m in (mask, whole):
                photometric_stereo(images, lights, method=method, options={"mask": m})
            if verbose:
                print(f"warm-up: {method}: {time.perf_counter() - t:.1f} s", flush=True)
        photometric_stereo(images, lights, method="li_alternating", options={"mask": mask, "coarse_pixels": COARSE})
        from facette.pipeline._shadows import binned       # the shadow step's binning (above SHADOW_PIXELS only)
        from facette.pipeline._shadows import _without     # the hidden values taken out of a copy
        from facette.pipeline._shadows import upsampled    # the bins' hidden lights at every pixel
        for im in (images, np.ascontiguousarray(images[..., 1]), images[..., 1]):    # RGB, grey, a channel's view
            binned(im, lights, mask, 2)
            _without(im, np.zeros(im.shape[:3], bool), "rank_trimmed")
        upsampled(np.zeros((len(lights), mask.shape[0] // 2, mask.shape[1] // 2), bool), 2, mask)
    return time.perf_counter() - t0


def main():
    import shutil

    from facette._kernel_cache import stale_kernel_caches
    for old in stale_kernel_caches():
        shutil.rmtree(old, ignore_errors=True)
    seconds = warm_up()
    print(f"warm-up: every kernel compiled and cached in {seconds:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
