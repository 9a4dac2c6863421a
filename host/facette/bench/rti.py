"""`facette bench rti`: relighting error and fit time of the RTI exports (PTM LRGB, HSH).

For each data set: the relative RMS error of the relit images against the HDR/linear images
at the lights used in the fit, and at lights left out of it (fit on every other light,
evaluated on the others: what a user dragging the light in RTIViewer sees between the
photographs), with the fit time. Data sets:
1. simulated: a sphere on a plane rendered under the rig's 12 lights, matte and glossy;
2. DiLiGenT ball (612x512, 16-bit PNG, 96 lights) and the 8-bit crops, when the real data
   is found (../shared/data beside the repository, or --root DIR); the time to read the 96
   16-bit PNGs (facette.io.png) is printed too.
"""
import argparse
import time
from pathlib import Path

import numpy as np

import facette
from facette.io.diligent import read_diligent
from facette.recon import fit_hsh, fit_ptm_lrgb, relight_error, relight_hsh, relight_ptm
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

FITS = (("PTM LRGB (6 terms)", lambda i, l, m: fit_ptm_lrgb(i, l, mask=m), relight_ptm),
        ("HSH order 2 (4 terms/ch)", lambda i, l, m: fit_hsh(i, l, 2, mask=m), relight_hsh),
        ("HSH order 3 (9 terms/ch)", lambda i, l, m: fit_hsh(i, l, 3, mask=m), relight_hsh))


def _rows(label, images, lights, mask):
    fit_sel = np.arange(len(lights)) % 2 == 0
    for name, fit_fn, render_fn in FITS:
        t0 = time.perf_counter()
        fit = fit_fn(images, lights, mask)
        dt = time.perf_counter() - t0
        err_all = relight_error(lambda d: render_fn(fit, d), images, lights, mask)
        half = fit_fn(images[fit_sel], lights[fit_sel], mask)
        if half.valid[mask].mean() < 0.5:
            held_text = f"{'n/a':>10s}  "          # fewer lights than terms: nothing fitted
        else:
            held = relight_error(lambda d: render_fn(half, d), images[~fit_sel], lights[~fit_sel], mask)
            held_text = f"{100 * held:10.2f} %"
        print(f"  {label:34s} {name:26s} {100 * err_all:8.2f} % {held_text} {dt:8.2f} s", flush=True)


def _header():
    print(f"  {'data':34s} {'basis':26s} {'fitted':>10s} {'held out':>12s} {'fit time':>10s}")


def simulated():
    print("1. simulated sphere on a plane, 12 rig lights, 256x256 (relative RMS on the mask)")
    _header()
    lights = thesis_light_directions()
    sc = sphere_on_plane(256, 256)
    for material in ("matte", "glossy"):
        imgs = render(sc, lights, material, noise=0.01, rng=np.random.default_rng(1))
        _rows(f"sphere on plane, {material}", imgs, lights, sc.mask)


def diligent(root):
    base = Path(root)
    folders = [base / "diligent" / "ballPNG"] + sorted((base / "diligent_crop8").glob("*PNG"))
    folders = [f for f in folders if (f / "filenames.txt").is_file()]
    if not folders:
        print(f"2. DiLiGenT: no data under {base} (pass --root DIR); skipped")
        return
    print(f"2. DiLiGenT ({base}), all lights, relative RMS on the mask")
    _header()
    for folder in folders:
        t0 = time.perf_counter()
        d = read_diligent(folder)
        dt = time.perf_counter() - t0
        label = f"{folder.parent.name}/{folder.name} {d.images.shape[2]}x{d.images.shape[1]}"
        _rows(label, d.images, d.light_dirs, d.mask)
        print(f"  {'':34s} (read {len(d.names)} PNGs in {dt:.2f} s, "
              f"{1000 * dt / len(d.names):.1f} ms each)")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench rti", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    ap.add_argument("--skip-real", action="store_true", help="simulated data only")
    args = ap.parse_args(argv)
    simulated()
    if not args.skip_real:
        diligent(args.root)
    return 0
