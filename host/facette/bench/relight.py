"""`facette bench relight`: relighting judged on lights it never saw.

Each method is fitted on all but the held-out photographs and predicts them; the score is the
NeuralRTI benchmark's: the PSNR of the 8-bit display values (sRGB-encoded, clipped, rounded) over
every pixel of the object and every channel, per held-out photograph, then averaged; the SSIM
of the same 8-bit values (Wang et al. 2004: Gaussian window σ 1.5, K1 0.01, K2 0.03, per channel,
averaged over the object); the share of the object's pixels whose raw value (before the viewer's
clip) is negative under lights 75° from the axis (8 azimuths); the fit's time (wall and CPU, which
holds on a busy machine) and its size (bytes per pixel as 8-bit planes = MB per megapixel).

Methods (`bench._relight_methods`): PTM LRGB, HSH of order 2 and 3, Relight's RBF (principal
components + Gaussian RBF over the lights), facette's report viewer before this change (process():
normals, albedo, one LI BRDF; --no-before to skip it), and facette's relighting model
(`recon._relight_model`: normals, a per-pixel diffuse, lobe and gathered-light map, cast shadows
from the integrated heights (kept per capture by leave-one-light-out error; never in "no shadows"), and a residual interpolated over the lights).

Captures (../shared/data, or --root DIR): DiLiGenT (96 lights, every 8th held out), DiLiGenT-Π
(5 lights, each left out in turn; every `--pi-step` px), the Loewenkopf dome (JPEG + .lp, 240
lights, every 6th held out), the Harvard set (20 lights, every 6th held out; ≤ 320 px) and
JPEG + .lp captures written from DiLiGenT's crops (8-bit sRGB, every 6th held out).
"""
import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter

import facette
from facette._memory import parse_size
from facette.bench._relight_data import (diligent_capture, harvard_capture, hold_every, lp_capture,
                                         make_jpeg_capture)
from facette.bench._relight_large import run_large
from facette.bench._relight_methods import METHODS

RAKING_DEG = 75.0
BASELINE = "HSH 3"


def raking_lights(theta_deg=RAKING_DEG, n=8):
    """n unit directions at theta_deg from the camera axis, evenly around it."""
    az = np.radians(np.arange(n) * 360.0 / n)
    t = np.radians(theta_deg)
    return np.c_[np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.full(n, np.cos(t))]


def to8(display):
    """8-bit display values of display values (clipped to [0, 1], rounded), float64."""
    return np.round(np.clip(np.nan_to_num(display), 0, 1) * 255.0)


def psnr8(pred8, photo8, mask):
    mse = float(np.mean((pred8[mask] - photo8[mask]) ** 2))
    return 10 * np.log10(255.0 ** 2 / max(mse, 1e-10))


def ssim8(pred8, photo8, mask, sigma=1.5):
    """Mean SSIM (Wang et al. 2004, eq 13; Gaussian window σ 1.5) over the mask and channels."""
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    vals = []
    for c in range(pred8.shape[-1]):
        x, y = pred8[..., c], photo8[..., c]
        mx, my = gaussian_filter(x, sigma), gaussian_filter(y, sigma)
        sxx = gaussian_filter(x * x, sigma) - mx * mx
        syy = gaussian_filter(y * y, sigma) - my * my
        sxy = gaussian_filter(x * y, sigma) - mx * my
        s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
        vals.append(s[mask])
    return float(np.mean(vals))


def score(cap, names, work):
    """{method: dict(psnr, ssim, neg, fit_s, size, why)} over the capture's folds; None: n/a."""
    out = {}
    for name in names:
        ps, ss, neg, secs, cpu, size, why = [], [], [], 0.0, 0.0, 0.0, ""
        for k, held in enumerate(cap.folds):
            train = np.setdiff1d(np.arange(len(cap.dirs)), held)
            t0, c0 = time.perf_counter(), time.process_time()
            if "before" in name and len(cap.folds) > 1:
                ps, why = None, "skipped: one process() per fold"
                break
            args = (cap, train, work / f"{name}{k}") if "before" in name else (cap, train)
            fitted = METHODS[name](*args)
            secs += time.perf_counter() - t0
            cpu += time.process_time() - c0
            if fitted is None or fitted.raw is None:
                why = fitted.why if fitted is not None else "fewer lights than terms"
                ps = None
                break
            size, why = fitted.size, fitted.why or why
            for h in held:
                pred8, photo8 = to8(fitted.raw(cap.dirs[h])), to8(cap.shown[h])
                ps.append(psnr8(pred8, photo8, cap.mask))
                ss.append(ssim8(pred8, photo8, cap.mask))
            if k == 0:
                neg = [float(np.mean(np.any(fitted.raw(d) < 0, axis=-1)[cap.mask])) for d in raking_lights()]
        mpx = cap.mask.sum() / 1e6
        out[name] = None if ps is None else dict(psnr=np.mean(ps), ssim=np.mean(ss), neg=100 * np.mean(neg),
                                                 fit_s_mpx=secs / len(cap.folds) / mpx,
                                                 fit_cpu_mpx=cpu / len(cap.folds) / mpx, size=size, why=why)
        if ps is None:
            out[name] = dict(why=why)
    return out


def _row(label, name, r):
    if "psnr" not in r:
        return f"  {label:22s} {name:20s} {'n/a':>8s}   ({r['why']})"
    return (f"  {label:22s} {name:20s} {r['psnr']:6.2f} dB {r['ssim']:6.3f} {r['neg']:8.2f} % "
            f"{r['fit_s_mpx']:9.1f} s/MP {r['fit_cpu_mpx']:9.1f} CPU s/MP {r['size']:5.0f} B/px" + (f"  ({r['why']})" if r["why"] else ""))


def _captures(base, args, work):
    """Yields the captures one by one (each loaded when its turn comes)."""
    groups = set(args.groups.split(","))
    crops = []
    for n in filter(None, args.diligent.split(",")):
        f = next((base / p / n for p in ("diligent_crop8", "diligent")
                  if (base / p / n / "filenames.txt").is_file()), None)
        if f is None:
            continue
        cap = diligent_capture(f, "DiLiGenT", lambda m: hold_every(m, 8))
        crops.append(cap)
        if "diligent" in groups:
            yield cap
    pi_base = base / "diligent_pi"
    for n in filter(None, args.pi.split(",")) if "pi" in groups else []:
        if (pi_base / n / "filenames.txt").is_file():
            yield diligent_capture(pi_base / n, "DiLiGenT-Π", lambda m: [[j] for j in range(m)], args.pi_step)
    lp = base / "rti_captures" / "loewenkopf_240" / "data" / "dirs.lp"
    if "dome" in groups and lp.is_file():
        yield lp_capture(lp, "dome (JPEG + .lp)", "loewenkopf_240")
    for n in filter(None, args.harvard.split(",")) if "harvard" in groups else []:
        if (base / "harvard_psdata" / n / "light_directions.txt").is_file():
            yield harvard_capture(base / "harvard_psdata" / n)
    for cap in crops if "jpeg" in groups else []:
        yield make_jpeg_capture(cap, work / f"jpeg_{cap.name}")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench relight", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    ap.add_argument("--groups", default="diligent,pi,dome,harvard,jpeg",
                    help="capture groups to run (default all: diligent,pi,dome,harvard,jpeg)")
    ap.add_argument("--diligent", default="ballPNG,catPNG,pot2PNG,buddhaPNG,readingPNG",
                    help="DiLiGenT objects (their JPEG + .lp captures too)")
    ap.add_argument("--pi", default="Bagua-R,Cloud-R,Bear,Bird", help="DiLiGenT-Π objects")
    ap.add_argument("--pi-step", type=int, default=8, help="DiLiGenT-Π: every N-th pixel (default 8)")
    ap.add_argument("--harvard", default="frog,hippo,lizard,pig,scholar,turtle", help="Harvard objects")
    ap.add_argument("--methods", default=",".join(METHODS), help="methods (default all)")
    ap.add_argument("--no-before", action="store_true",
                    help="skip the viewer before this change (a process() per fold)")
    ap.add_argument("--large", default=None, metavar="WxH",
                    help="also fit the model on a generated WxH slab through process (e.g. 4000x3000: "
                         "12 MP); prints its time and peak memory")
    ap.add_argument("--large-memory", default=None, metavar="SIZE",
                    help="--large: process's --memory (e.g. 3GB: read band by band; default: none given)")
    ap.add_argument("--large-free", default=None, metavar="SIZE",
                    help="--large: the free memory process's default budget is told of (e.g. 64GB: as a large "
                         "machine decides; default: this machine's)")
    ap.add_argument("--large-outputs", default="relight",
                    help="--large: process's outputs, comma-separated, or all (default relight)")
    ap.add_argument("--large-capture", default=None, metavar="DIR",
                    help="--large: a slab folder already written (bench._large), instead of generating one")
    args = ap.parse_args(argv)
    names = [n for n in args.methods.split(",") if n in METHODS and not (args.no_before and "before" in n)]
    work = Path(tempfile.mkdtemp(prefix="facette_bench_relight_"))
    table = {}
    print(f"  {'capture':22s} {'method':20s} {'PSNR':>9s} {'SSIM':>6s} {'neg@75°':>10s} {'fit':>14s} {'fit CPU':>18s} {'size':>8s}")
    try:
        for cap in _captures(Path(args.root), args, work):
            label = f"{cap.name} ({len(cap.dirs)}, {cap.mask.sum() / 1e3:.0f}k px)"
            rows = score(cap, names, work)
            table[(cap.group, cap.name)] = rows
            print(f"{cap.group}:")
            for name in names:
                print(_row(label, name, rows[name]), flush=True)
                label = ""
        if args.large:
            run_large(tuple(int(v) for v in args.large.lower().split("x")), work, memory=args.large_memory,
                      free=None if args.large_free is None else parse_size(args.large_free, "--large-free", limit=0),
                      outputs=args.large_outputs, capture=args.large_capture)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if not table:
        print(f"no data under {args.root} (pass --root DIR); skipped")
        return 0
    _summary(table, names)
    return 0


def _summary(table, names):
    """The mean PSNR of every method over the captures it ran on, and the best's margin over HSH 3."""
    print("mean over the captures (PSNR, SSIM; captures where the method is n/a left out):")
    for name in names:
        got = [r[name] for r in table.values() if "psnr" in r[name]]
        if got:
            print(f"  {name:20s} {np.mean([g['psnr'] for g in got]):6.2f} dB {np.mean([g['ssim'] for g in got]):6.3f}"
                  f"  ({len(got)} of {len(table)} captures)")
    for name in names:
        if BASELINE not in names or name == BASELINE:
            continue
        both = [(r[name]["psnr"], r[BASELINE]["psnr"]) for r in table.values()
                if "psnr" in r[name] and "psnr" in r[BASELINE]]
        if both:
            d = np.array([a - b for a, b in both])
            print(f"  {name:20s} vs {BASELINE}: mean {d.mean():+.2f} dB, worst {d.min():+.2f} dB "
                  f"over {len(d)} captures")
