"""`facette bench capture`: RTI captures (photographs + .lp) as the input of `process`, against
the DiLiGenT path on the same photographs.

For each shared DiLiGenT object (../shared/data, or --root DIR) an RTI folder is made in a
temporary directory: its PNGs, its mask.png, and an .lp written from light_directions.txt. The
normals `process` gives on it are compared with the DiLiGenT path's (mean and worst angle over
the pixels both keep, and the time of each): with the object's light_intensities.txt beside the
.lp (what the DiLiGenT path divides by), and without it (a plain .lp carries no intensity)
against the DiLiGenT path given no intensities either. Then a JPEG copy of one 8-bit object
(quality 95, the same linear values) read as linear, and read as sRGB (the default for 8-bit
files, wrong for these), against the PNG capture, with the chosen method and least squares.
"""
import argparse
import shutil
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

import facette
from facette.calib.lp import write_lp
from facette.pipeline import process


def _rti_folder(src, dst, jpeg=False, intensities=False):
    """An RTI capture made of a DiLiGenT folder's photographs (copies) and an .lp."""
    dst.mkdir(parents=True)
    names = (src / "filenames.txt").read_text().split()
    out = []
    for n in names:
        if jpeg:
            img = cv2.imread(str(src / n), cv2.IMREAD_UNCHANGED)
            if img.dtype == np.uint16:
                img = np.round(img / 257.0).astype(np.uint8)
            n = n.rsplit(".", 1)[0] + ".jpg"
            cv2.imwrite(str(dst / n), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
        else:
            shutil.copy(src / n, dst / n)
        out.append(n)
    shutil.copy(src / "mask.png", dst / "mask.png")
    write_lp(dst / "capture.lp", out, np.loadtxt(src / "light_directions.txt"))
    if intensities:
        shutil.copy(src / "light_intensities.txt", dst / "light_intensities.txt")
    return dst


def _without_intensities(src, dst):
    """The DiLiGenT folder without its light_intensities.txt (links)."""
    dst.mkdir(parents=True)
    for p in src.iterdir():
        if p.name != "light_intensities.txt":
            (dst / p.name).symlink_to(p)
    return dst


def _run(folder, method, **kw):
    t0 = time.perf_counter()
    res = process(folder, outputs=["normals"], method=method, **kw)
    return res, time.perf_counter() - t0


def _apart(a, b):
    m = a.mask & b.mask
    e = np.degrees(np.arccos(np.clip(np.sum(a.normals[m] * b.normals[m], -1), -1, 1)))
    return e


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench capture", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    ap.add_argument("--method", default="rank_trimmed", help="photometric stereo (default rank_trimmed)")
    ap.add_argument("--objects", default="ballPNG,catPNG,pot2PNG,buddhaPNG,readingPNG",
                    help="DiLiGenT folders to use (the 16-bit ball, the 8-bit crops)")
    ap.add_argument("--jpeg-object", default="catPNG",
                    help="the object copied to JPEG (default catPNG: 8 bits already, so the JPEG "
                         "differs by its compression only)")
    args = ap.parse_args(argv)
    base = Path(args.root)
    folders = []
    for name in args.objects.split(","):
        for parent in ("diligent", "diligent_crop8"):
            if (base / parent / name / "filenames.txt").is_file():
                folders.append(base / parent / name)
                break
    if not folders:
        print(f"no DiLiGenT folders under {base} (pass --root DIR); skipped")
        return 0
    tmp = Path(tempfile.mkdtemp(prefix="facette_bench_capture_"))
    try:
        print(f"1. RTI folder (PNGs + .lp) against the DiLiGenT path, {args.method}: angle between the "
              "normal maps (mean / worst), time of each")
        print(f"  {'object':24s} {'with intensities':>22s} {'without (both)':>22s} {'DiLiGenT':>9s} {'RTI':>7s}")
        for src in folders:
            work = tmp / src.name
            ref, t_ref = _run(src, args.method)
            rti, t_rti = _run(_rti_folder(src, work / "rti_i", intensities=True), args.method,
                              capture={"encoding": "linear"})
            e1 = _apart(rti, ref)
            ref0, _ = _run(_without_intensities(src, work / "dil0"), args.method)
            rti0, _ = _run(_rti_folder(src, work / "rti"), args.method, capture={"encoding": "linear"})
            e0 = _apart(rti0, ref0)
            label = f"{src.parent.name}/{src.name}"
            print(f"  {label:24s} {e1.mean():9.4f}° / {e1.max():7.4f}° {e0.mean():9.4f}° / {e0.max():7.4f}° "
                  f"{t_ref:7.2f} s {t_rti:5.2f} s", flush=True)
        src = next((f for f in folders if f.name == args.jpeg_object), folders[0])
        work = tmp / (src.name + "_jpeg")
        png_dir = _rti_folder(src, work / "png")
        jpg_dir = _rti_folder(src, work / "jpg", jpeg=True)
        print(f"2. JPEG copy (quality 95, 8 bits) of {src.parent.name}/{src.name} against the PNG capture: "
              "angle (mean / median / 95th percentile), time")
        for method in dict.fromkeys((args.method, "woodham1980")):
            png, _ = _run(png_dir, method, capture={"encoding": "linear"})
            for enc in ("linear", "srgb"):
                jpg, t = _run(jpg_dir, method, capture={"encoding": enc})
                e = _apart(jpg, png)
                print(f"  {method:13s} read as {enc:7s} {e.mean():7.3f}° / {np.median(e):6.3f}° / "
                      f"{np.percentile(e, 95):6.3f}°  {t:6.2f} s"
                      + ("   (the values are linear: sRGB decoding is wrong here)" if enc == "srgb" else ""))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0
