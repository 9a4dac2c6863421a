#!/usr/bin/env python3
"""BRDF-aware photometric stereo (li_alternating) against least squares and the hierarchy on the
DiLiGenT crops (real photographs, laser-scanned truth).

    .venv/bin/python tools/diligent_li_alternating.py [--root ../shared/data/diligent_crop8] [--lights all|12]

Per object and method: mean and median angular error (zero-length truth normals skipped) and
seconds. --lights 12 keeps the 12 lights nearest the thesis rig's directions.
"""
import argparse
import time
from pathlib import Path

import numpy as np

import facette.fit  # noqa: F401  (registers li_alternating)
from facette.io.diligent import read_diligent
from facette.recon import photometric_stereo

OBJECTS = ("ballPNG", "catPNG", "pot2PNG", "buddhaPNG", "readingPNG")
METHODS = ("woodham1980", "hierarchical_tautzia2016", "li_alternating")


def rig_like(dirs):
    """Indices of the lights nearest the thesis rig's 12 directions (each used once)."""
    from facette.bench._mitsuba_scenes import rig_light_directions
    chosen = []
    for r in rig_light_directions():
        order = np.argsort(-(dirs @ r))
        chosen.append(next(i for i in order if i not in chosen))
    return np.array(chosen)


def main():
    here = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=str(here.parent / "shared" / "data" / "diligent_crop8"))
    ap.add_argument("--lights", default="all", choices=("all", "12"))
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--init", default="hierarchical_tautzia2016",
                    help="initial normals of li_alternating (any registered method, e.g. rpca_wu2010)")
    args = ap.parse_args()
    root = Path(args.root)
    if not root.is_dir():
        raise SystemExit(f"{root} not found: give --root DIR (a folder of DiLiGenT-style object folders)")
    methods = args.methods.split(",")
    print(f"{'object':12s} " + " ".join(f"{m:>28s}" for m in methods) + "   (mean° / median° / s)")
    means = {m: [] for m in methods}
    for obj in OBJECTS:
        folder = root / obj
        if not folder.is_dir():
            continue
        d = read_diligent(folder)
        truth = np.load(root / f"{obj}.truth" / "normals_gt.npy")
        sel = d.mask & (np.linalg.norm(truth, axis=-1) > 0.5)
        images, dirs = d.images, d.light_dirs
        if args.lights == "12":
            keep = rig_like(dirs)
            images, dirs = images[keep], dirs[keep]
        cells = []
        for m in methods:
            t = time.perf_counter()
            extra = {"init": args.init} if m == "li_alternating" else {}
            r = photometric_stereo(images, dirs, method=m, mask=d.mask, **extra)
            dt = time.perf_counter() - t
            err = np.degrees(np.arccos(np.clip(np.sum(r.normal * truth, -1), -1, 1)))[sel]
            means[m].append(err.mean())
            cells.append(f"{err.mean():7.2f} {np.median(err):6.2f} {dt:7.1f}s")
        print(f"{obj:12s} " + " ".join(f"{c:>28s}" for c in cells), flush=True)
    print(f"{'mean':12s} " + " ".join(f"{np.mean(v):>28.2f}" for v in means.values()))


if __name__ == "__main__":
    main()
