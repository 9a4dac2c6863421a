"""`facette bench rti`: relighting error and fit time of the RTI exports (PTM LRGB, HSH).

For each data set: the relative RMS error of the relit images against the HDR/linear images
at the lights used in the fit, and at lights left out of it (fit on every other light,
evaluated on the others: what a user dragging the light in RTIViewer sees between the
photographs), with the fit time. Data sets:
1. simulated: a sphere on a plane rendered under the rig's 12 lights, matte and glossy;
2. DiLiGenT ball (612x512, 16-bit PNG, 96 lights) and the 8-bit crops, when the real data
   is found (../shared/data beside the repository, or --root DIR); the time to read the 96
   16-bit PNGs (facette.io.png) is printed too.
3. the reference tools' own files (rti_reference/: RTIBuilder's HSH, HP's JPEG PTM, Relight's web
   folders of openlime) read by facette.io's readers (written from RTIViewer's, Relight's and
   openlime's loaders): read time, and the
   orientation figures (light from +x / +y brightens the right / upper side of the object);
5. real captures (rti_captures/loewenkopf_240 and JPEG + .lp captures made of the DiLiGenT crops),
   every 6th light held out: facette's files as RTIViewer and openlime read them against plain
   least-squares fits of the same photographs, PSNR / SSIM in 8-bit display values (bench._rti_captures);
4. with --results DIR (a `facette process` output of a scan): relight.ptm and relight.rti
   read back as RTIViewer (integer PTM coefficients) and Relight (float) read them, relative
   RMS against the (fall-off corrected) HDR images at the captured lights on the object
   (mask.png), in display space (sRGB of image / white, what the viewer should show) and in
   linear; and the fit time of each encoding on those images.
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

import facette
from facette.bench._rti_captures import captures_section
from facette.io.diligent import read_diligent
from facette.io.png import read_mask
from facette.io.ptm import read_ptm
from facette.io.relight_web import read_relight_web
from facette.io.rti import hsh_weights, read_hsh_rti
from facette.recon import (fit_hsh, fit_ptm_lrgb, near_light_directions, relight_error, relight_hsh,
                           relight_ptm, srgb_decode, srgb_encode)
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


def _side_ratio(picture_at, coords, lit):
    """Median over the object's far (+) side over its near (-) side of the ratio
    picture(+light) / picture(-light), light 45° from the axis along `coords`' axis."""
    axis, co = coords
    s = np.sqrt(0.5)
    plus = np.zeros(3)
    plus[axis], plus[2] = s, s
    minus = plus * [-1, -1, 1]
    ratio = picture_at(plus).mean(-1) / np.maximum(picture_at(minus).mean(-1), 1e-3)
    c = co[lit].mean()
    return float(np.median(ratio[lit & (co > c)]) / np.median(ratio[lit & (co < c)]))


def reference_files(root):
    base = Path(root) / "rti_reference"
    files = sorted(base.glob("hsh/*.rti")) + sorted(base.glob("ptm/*.ptm")) + \
        sorted(p.parent for p in base.glob("relight_web/*/info.json"))
    if not files:
        print(f"3. reference RTI files: none under {base}; skipped")
        return
    print("3. the reference tools' files, read by facette.io (rows as RTIViewer/Relight load them)")
    print("   right/left: how much more light from +x brightens the right half than the left (> 1 ="
          " upright); top/bottom: the same for +y and the upper half")
    print(f"  {'file':28s} {'size':>9s} {'read':>8s} {'right/left':>11s} {'top/bottom':>11s}")
    for f in files:
        t0 = time.perf_counter()
        rti = read_hsh_rti(f) if f.suffix == ".rti" else read_ptm(f) if f.suffix == ".ptm" else read_relight_web(f)
        dt = time.perf_counter() - t0
        lit = rti.relight([0, 0, 1]).mean(-1) > 0.15
        yy, xx = np.mgrid[0:rti.height, 0:rti.width]
        rl = _side_ratio(rti.relight, (0, xx), lit)
        tb = _side_ratio(rti.relight, (1, -yy), lit)
        print(f"  {f.parent.name + '/' + f.name:28s} {rti.width}x{rti.height:<4d} {dt:7.2f}s {rl:11.2f} {tb:11.2f}")


def _rms(pairs):
    num = den = 0.0
    for got, want in pairs:
        num += float(((got - want) ** 2).sum())
        den += float((want ** 2).sum())
    return np.sqrt(num / den)


def demo_results(results):
    """Section 4: the files of a processed scan against its HDR images."""
    from facette.pipeline._inputs import load_input       # bench: any layer below
    results = Path(results)
    rec = json.loads((results / "process.json").read_text())
    inp = load_input(rec["source"])
    m, h, w, _ = inp.images.shape
    dirs, images = inp.light_dirs, inp.images
    if rec["options"].get("near_light", True) and inp.positions_mm is not None:
        dirs, falloff = near_light_directions(inp.positions_mm, (h, w), inp.pixel_pitch_mm)
        images = images / np.transpose(falloff, (2, 0, 1))[..., None]
    obj = read_mask(results / "mask.png")
    exposure = rec.get("quality", {}).get("rti_exposure", {})
    enc = exposure.get("encoding", rec["options"].get("rti_encoding", "linear"))
    print(f"4. {results}: {m} lights, {w}x{h} px, object {int(obj.sum())} of {obj.size} px "
          f"(mask.png), files encoded {enc}")
    per_light = [np.moveaxis(dirs, 2, 0)[k] if dirs.ndim == 4 else dirs[k] for k in range(m)]
    fits = {}
    white = exposure.get("white")          # the files' scale (pipeline._rti_exposure); older runs: a percentile
    for name, fn in (("ptm", lambda e: fit_ptm_lrgb(images, dirs, mask=obj, encoding=e, white=white,
                                                    photographed=white is not None)),
                     ("hsh", lambda e: fit_hsh(images, dirs, rec["options"].get("hsh_order", 3), mask=obj,
                                               encoding=e, white=white, photographed=white is not None))):
        for e in ("linear", "srgb"):
            t0 = time.perf_counter()
            fits[name, e] = fn(e)
            fits[name, e, "s"] = time.perf_counter() - t0
    ptm, rti = read_ptm(results / "relight.ptm"), read_hsh_rti(results / "relight.rti")
    readers = [("relight.ptm, RTIViewer (int coefficients)", lambda d: ptm.relight(d, rtiviewer=True), "ptm"),
               ("relight.ptm, Relight (float)", lambda d: ptm.relight(d), "ptm"),
               ("relight.rti, RTIViewer/Relight", rti.relight, "hsh")]
    print(f"  {'file, as read by':42s} {'display RMS':>12s} {'linear RMS':>11s} {'flipped':>9s} "
          f"{'< 0 at 60°':>11s}  (relative, object, {m} captured lights)")
    ok = obj & np.isfinite(images).all(axis=(0, 3))      # the same for every reader
    for label, shown_at, kind in readers:
        white = fits[kind, enc].white
        disp, lin, flip = [], [], []
        for k in range(m):
            shown = shown_at(per_light[k])
            want = np.clip(images[k] / white, 0, None)
            want_d = srgb_encode(want) if enc == "srgb" else np.minimum(want, 1.0)
            disp.append((shown[ok], want_d[ok]))
            lin.append(((srgb_decode(shown) if enc == "srgb" else shown)[ok] * white, images[k][ok]))
            flip.append((shown[::-1][ok], want_d[ok]))
        # raking light, 60° from the axis at 8 azimuths: pixels the model drives below zero
        neg = []
        for az in np.radians(np.arange(0, 360, 45)):
            d = np.array([np.sin(np.radians(60)) * np.cos(az), np.sin(np.radians(60)) * np.sin(az),
                          np.cos(np.radians(60))])
            raw = (ptm.luminance(d) if kind == "ptm" else rti.coeffs @ hsh_weights(d, rti.terms))
            raw = raw if raw.ndim == 2 else raw.min(-1)
            neg.append(float((raw[ok] < 0).mean()))
        print(f"  {label:42s} {_rms(disp):12.4f} {_rms(lin):11.4f} {_rms(flip):9.4f} {100 * np.mean(neg):10.1f}%")
    print("  fit time on these images (s): " + ", ".join(
        f"{k} {e} {fits[k, e, 's']:.2f}" for k in ("ptm", "hsh") for e in ("linear", "srgb")))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench rti", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    ap.add_argument("--skip-real", action="store_true", help="simulated data only")
    ap.add_argument("--results", help="a `facette process` output folder of a scan: its relight.ptm and "
                                      "relight.rti against the scan's HDR images (section 4)")
    ap.add_argument("--files-only", action="store_true", help="sections 3 and 4 only (the files)")
    ap.add_argument("--captures-only", action="store_true", help="section 5 only (the real captures)")
    args = ap.parse_args(argv)
    if args.captures_only:
        captures_section(args.root)
        return 0
    if not args.files_only:
        simulated()
        if not args.skip_real:
            diligent(args.root)
    if not args.skip_real:
        reference_files(args.root)
    if args.results:
        demo_results(args.results)
    if not args.skip_real and not args.files_only:
        captures_section(args.root)
    return 0
