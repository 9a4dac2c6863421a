"""`facette bench recon`: photometric-stereo accuracy and reconstruction speed.

1. Accuracy on simulated scenes with known normals (a sphere on a plane, attached and cast
   shadows, 12 lights of the rig, 1 % noise): matte (Lambert), satin and glossy
   (Cook-Torrance, sigma 0.15 / 0.05, the glossy one with strong highlights too); mean,
   median and 95th-percentile angular error of least squares and of the hierarchical method,
   with and without the least-squares shortcut, and the time of each.
2. Speed at the thesis's size, 12 lights at 2144x1424 (half of the D300's 4288x2848, the HDR
   resolution): least squares, hierarchical, integration, samples + filter, and the whole of
   `process` (EXR scan directory in, every output but brdf.json written), in seconds and as
   ratios to least squares, all measured in one run.
"""
import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from facette.io.exr import write_exr
from facette.pipeline import process
from facette.pipeline._process import _samples_stage
from facette.recon import (INTEGRATION_METHODS, integrate, integrate_frankot_chellappa1988,
                           ps_hierarchical_tautzia2016, ps_woodham1980)
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions
from facette.scan import ScanDirectory

L = thesis_light_directions()
SCENES = [("matte", "matte", 1.0), ("satin", "satin", 1.0), ("glossy", "glossy", 1.0),
          ("glossy, strong highlights (ks 5)", "glossy", 5.0)]


def _timed(fn, *a, **k):
    t = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t


def _timed_cpu(fn, *a, **k):
    """(result, (wall s, CPU s of all this process's threads)); the CPU time shows how much
    of the wall time was waiting for a core on a shared machine."""
    t, c = time.perf_counter(), time.process_time()
    out = fn(*a, **k)
    return out, (time.perf_counter() - t, time.process_time() - c)


def accuracy(size=256, noise=0.01):
    sc = sphere_on_plane(size, size)
    rows = []
    for label, material, ks in SCENES:
        imgs = render(sc, L, material, noise=noise, ks=ks, rng=np.random.default_rng(1))
        for name, fn, kw in (("least squares (woodham1980)", ps_woodham1980, {}),
                             ("hierarchical (tautzia2016)", ps_hierarchical_tautzia2016, {}),
                             ("hierarchical, no LS shortcut", ps_hierarchical_tautzia2016,
                              {"t_residual": 0}),
                             ("hierarchical, T_spec 0.05", ps_hierarchical_tautzia2016,
                              {"t_spec": 0.05})):
            r, dt = _timed(fn, imgs, L, **kw)
            e = angular_error_deg(r.normal, sc.normals, sc.mask)   # invalid pixels count (n = 0)
            rows.append((label, name, e.mean(), np.median(e), np.percentile(e, 95), dt,
                         r.info.get("skipped_fraction")))
    return rows


def integration_accuracy(size=256):
    """Height error (RMS after removing the mean, in % of the sphere radius) of each method
    from the true normals of the sphere on a plane, and its time."""
    sc = sphere_on_plane(size, size)
    inner = sc.mask & (np.sum(sc.normals[..., :2] ** 2, -1) < 0.9 ** 2)   # away from the rim
    rows = []
    for name in INTEGRATION_METHODS:
        mask = sc.mask if name == "least_squares" else None
        z, dt = _timed(integrate, sc.normals, 1.0, mask=mask, method=name)
        d = (z - sc.height)[inner]
        rows.append((name, 100 * np.sqrt(np.mean((d - d.mean()) ** 2)) / sc.radius, dt))
    return rows


def _tiled_scene(h, w, tile=356):
    """Glossy spheres on a plane tiled to (h, w): the rendering of one tile, repeated."""
    th, tw = tile, int(round(tile * w / h))
    sc = sphere_on_plane(th, tw)
    imgs = render(sc, L, "glossy", noise=0.01, ks=3.0)
    reps = (int(np.ceil(h / th)), int(np.ceil(w / tw)))
    big = np.tile(imgs, (1, reps[0], reps[1], 1))[:, :h, :w]
    normals = np.tile(sc.normals, (reps[0], reps[1], 1))[:h, :w]
    height = np.tile(sc.height, reps)[:h, :w]
    return np.ascontiguousarray(big), normals, height


def _write_scan(folder, imgs, normals, height, pitch):
    m = len(L)
    (folder / "hdr").mkdir(parents=True)
    for i in range(m):
        write_exr(folder / "hdr" / f"light_{i:02d}.exr", imgs[i])
        write_exr(folder / "hdr" / f"light_{i:02d}_var.exr", np.full_like(imgs[i], 1e-6))
    np.savez(folder / "truth.npz", normals=normals, height_mm=height * pitch,
             mask=np.ones(height.shape, bool))
    sd = ScanDirectory(folder)
    sd.create(rig={"id": "bench"}, profile=None, pixel_pitch_mm=pitch,
              lights=[{"index": i, "direction": L[i].tolist(), "position_mm": None,
                       "intensity": [1.0, 1.0, 1.0]} for i in range(m)],
              exposures=[], plan=None)
    for i in range(m):    # frames without files: the HDR images above are all there is
        sd.manifest.add_frame({"file": f"raw/L{i:02d}_E00.dng", "light": i, "exposure": 0})
    sd.manifest.set_truth("truth.npz")
    sd.save()


def speed(h, w):
    imgs, normals, height = _tiled_scene(h, w)
    t = {}
    ls, t["least squares"] = _timed_cpu(ps_woodham1980, imgs, L)
    hi, t["hierarchical (incl. its LS pass)"] = _timed_cpu(ps_hierarchical_tautzia2016, imgs, L)
    skipped = hi.info["skipped_fraction"]
    _, t["integration (Frankot-Chellappa)"] = _timed_cpu(integrate_frankot_chellappa1988, hi.normal,
                                                         0.0334)
    (fr, raw), t["samples + filter"] = _timed_cpu(_samples_stage, imgs, np.ones(imgs.shape[1:3], bool),
                                                  hi, L, 3.0)
    n_samples = int(fr.count.sum())
    with tempfile.TemporaryDirectory() as tmp:
        scan = Path(tmp) / "scan"
        _write_scan(scan, imgs, normals, height, 0.0334)
        del imgs
        outs = ["normals", "albedo", "mask", "height", "mesh", "samples", "report"]
        res, t["process, all but brdf (EXR in, files out)"] = _timed_cpu(
            process, scan, outputs=outs, out_dir=Path(tmp) / "out")
    e_ls = angular_error_deg(ls.normal, normals)
    e_hi = angular_error_deg(hi.normal, normals)
    return t, skipped, n_samples, res, (e_ls.mean(), e_hi.mean())


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench recon", description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="2144x1424", help="speed test image size WxH (default 2144x1424)")
    ap.add_argument("--accuracy-size", type=int, default=256, help="accuracy scene side (px)")
    ap.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    args = ap.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    acc_size = args.accuracy_size
    if args.quick:
        w, h, acc_size = 536, 356, 128

    print(f"Accuracy: sphere on a plane, {acc_size}x{acc_size} px, 12 lights (thesis rig), 1 % noise, "
          "attached and cast shadows")
    print(f"{'scene':34s} {'method':30s} {'mean':>7s} {'median':>7s} {'p95':>7s} {'time s':>7s}  LS-explained")
    for label, name, mean, med, p95, dt, skip in accuracy(acc_size):
        sk = f"{100 * skip:5.1f} %" if skip is not None and name.endswith("(tautzia2016)") else ""
        print(f"{label:34s} {name:30s} {mean:6.2f}° {med:6.2f}° {p95:6.2f}° {dt:7.3f}  {sk}")

    print(f"\nIntegration of the true normals ({acc_size}x{acc_size} sphere on a plane; slopes "
          "clipped at 20 near the rim)")
    for name, rms, dt in integration_accuracy(acc_size):
        print(f"  {name:24s} height RMS error {rms:6.2f} % of the radius   {dt:7.3f} s")

    print(f"\nSpeed: 12 lights at {w}x{h} (tiled glossy spheres, ks 3), one run, 2 cores")
    t, skipped, n_samples, res, (e_ls, e_hi) = speed(h, w)
    base = t["least squares"][0]
    print(f"  {'stage':44s} {'wall':>8s} {'ratio':>9s} {'CPU':>8s}")
    for k, (v, c) in t.items():
        print(f"  {k:44s} {v:7.2f} s {v / base:6.1f} x LS {c:7.2f} s")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"  (1-minute load average at the end: {load:.1f} on {os.cpu_count()} cores; CPU time "
          "counts both threads)")
    print(f"  pixels explained by least squares (hierarchy skipped): {100 * skipped:.1f} %")
    print(f"  samples filtered: {n_samples}; mean angular error LS {e_ls:.2f}°, hierarchical {e_hi:.2f}°")
    inner = {k: round(v, 2) for k, v in res.timings.items()}
    print(f"  process stages (s): {inner}")
    print("  thesis (no parallelism): about 48 s for normals + integration + reflectance at 4288x2848")
    return 0
