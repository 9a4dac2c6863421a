"""`facette bench bands`: a concave capture read whole and band by band, the cast-shadow step on.

A field of cups (flat-bottomed, steep-walled, twice as deep as wide, on a grid) rendered analytically under the
rig's 12 lights, Lambertian, with the shadows the walls cast found by a ray march on the true
heights (a hidden light still leaves 30 % of its direct value: the walls' light, too bright to be
told by darkness alone), written as a DiLiGenT-style folder of 16-bit PNGs. `facette process`
runs it (normals only, shadows "auto") read whole (no flag: the capture fits the default budget),
as one band of the band loop (`--memory 16GB`) and band by band (`--memory` small); then band by
band with `--shadows off`.
Printed per run: wall s, peak RSS, the bands, the mean angular error against the truth on the
pixels some light is hidden from and on all, and the normals' largest difference to the whole run.
--code DIR runs the `facette` of another tree (DIR/host first on the path: before/after).
"""
import argparse
import os
import tempfile
from pathlib import Path

import numpy as np

from facette.bench.size import FACETTE, _angles_deg, _measured, _run_rss
from facette.io.diligent import write_diligent
from facette.io.exr import read_exr
from facette.recon.synthetic import thesis_light_directions

__all__ = ["crater_field", "main"]

# px: a cup every 64 px, 26 px in radius, 55 deep (its walls hide the rig's 30° lights from much of its floor)
PERIOD, RADIUS, DEPTH = 64, 26.0, 55.0
FILL = 0.3                                  # a hidden light's share left (the walls' light)


def _heights(x, y):
    """The crater field's heights (px) at image coordinates x (columns), y (rows)."""
    dx = (x % PERIOD) - PERIOD / 2
    dy = (y % PERIOD) - PERIOD / 2
    return -DEPTH * np.maximum(0.0, 1 - ((dx * dx + dy * dy) / RADIUS ** 2) ** 2)


def crater_field(width, height, lights, albedo=0.7):
    """dict: images (m, H, W) float32, normals (H, W, 3) camera frame (y up), hidden (m, H, W)."""
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    eps = 1e-3
    zx = (_heights(cols + eps, rows) - _heights(cols - eps, rows)) / (2 * eps)
    zy = -(_heights(cols, rows + eps) - _heights(cols, rows - eps)) / (2 * eps)    # y up = rows down
    n = np.stack([-zx, -zy, np.ones_like(zx)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    z0 = _heights(cols, rows)
    images, hidden = [], []
    for s in np.asarray(lights, np.float64):
        flat = np.hypot(s[0], s[1])
        hid = np.zeros((height, width), bool)
        if flat > 1e-9:
            for t in np.arange(0.5, 2 * RADIUS, 0.5):       # a wall is at most a crater's width away
                xs, ys = cols + t * s[0] / flat, rows - t * s[1] / flat
                hid |= _heights(xs, ys) > z0 + t * s[2] / flat
        shade = albedo * np.clip(n @ s, 0, None)
        images.append(np.where(hid, FILL * shade, shade))
        hidden.append(hid)
    return {"images": np.stack(images).astype(np.float32), "normals": n.astype(np.float32),
            "hidden": np.stack(hidden)}


def _run(folder, out, code, *flags):
    env = None if code is None else {"PYTHONPATH": str(Path(code) / "host")}
    stdout, wall, gb = _run_rss(_measured(FACETTE + ["process", folder, "-o", out, "--outputs", "normals",
                                                     "--overwrite", *flags]), env=env)
    bands = next((line.split("over ")[1].split(" bands")[0] for line in stdout.splitlines()
                  if "photometric stereo over" in line), "1 (whole)")
    return read_exr(out / "normal.exr")[0][..., :3], wall, gb, bands


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench bands", description=__doc__.splitlines()[0])
    p.add_argument("--size", default="1024x768", help="WxH of the capture (default 1024x768)")
    p.add_argument("--memory", default="600MB", help="the banded runs' budget (default 600MB)")
    p.add_argument("--code", help="run the facette of this tree (its host/ first on the path)")
    p.add_argument("--work", help="keep the capture and results here (default: temporary); a capture "
                                  "already there is reused")
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.size.lower().split("x"))
    lights = thesis_light_directions()
    with tempfile.TemporaryDirectory(prefix="facette-bench-bands-") as tmp:
        work = Path(args.work or tmp)
        folder, truth = work / f"craters_{w}x{h}", work / f"craters_{w}x{h}_truth.npz"
        if truth.is_file():             # made by an earlier run with the same --work
            d = dict(np.load(truth))
        else:
            d = crater_field(w, h, lights)
            top = 60000.0 / float(d["images"].max())
            write_diligent(folder, np.round(d.pop("images") * top).astype(np.uint16), lights,
                           np.full((len(lights), 3), top / 65535.0), np.ones((h, w), bool))
            np.savez(truth, **d)
        hid = d["hidden"].any(0)
        print(f"crater field {w}x{h}, {len(lights)} lights: {hid.mean():.1%} of the pixels hide some light, "
              f"{d['hidden'].mean():.1%} of the samples hidden; code: {args.code or os.path.dirname(__file__)}")
        print(f"{'run':34s} {'wall s':>7s} {'peak GB':>7s} {'bands':>6s} {'err hidden':>10s} {'err all':>8s} "
              f"{'max vs whole':>12s}")
        whole = None
        runs = (("whole (no flag)", []), ("one band (--memory 16GB)", ["--memory", "16GB"]),
                (f"bands (--memory {args.memory})", ["--memory", args.memory]),
                ("bands, --shadows off", ["--memory", args.memory, "--shadows", "off"]))
        for i, (label, flags) in enumerate(runs):
            n, wall, gb, bands = _run(folder, work / f"run{i}", args.code, *flags)
            err = _angles_deg(n, d["normals"])
            whole = n if whole is None else whole
            print(f"{label:34s} {wall:7.1f} {gb:7.2f} {bands:>6s} {err[hid].mean():10.3f} {err.mean():8.3f} "
                  f"{_angles_deg(n, whole).max():12.5f}", flush=True)
    return 0
