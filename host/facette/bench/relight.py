"""`facette bench relight`: relighting judged on lights it never saw.

Each method is fitted on all but k photographs and predicts the k held out; the table gives,
per method, the relative RMS error (sqrt(Σ|pred − photo|² / Σ|photo|²) over the mask and the
known values), the PSNR (peak: the 99.9th percentile of the held-out values on the mask), the
share of the object's pixels that come out negative under lights 75° from the axis (8 azimuths;
counted before any clipping, which every RTI viewer then does), and the time (fit + predictions).

Methods: PTM LRGB (6 terms), HSH of order 2 and 3 (4 and 9 terms per channel), the fits of
`facette.recon` as they are; an RBF interpolation over the lights' (x, y) as Relight's default
basis does it (Gaussian kernel, its width and smoothing chosen on the fitted photographs alone,
scipy's `RBFInterpolator`), the peer; and, from one `process` run on the fitted photographs
(normals, albedo, the LI BRDF fitted to them; its time charged to each of these rows):
Lambert's law with the photometric-stereo albedo; facette's physically based relighting as the
report's viewer does it (`pipeline._relight.relight`, its Python reference, K_d map from the
albedo); and the same with a per-pixel gain fitted to the fitted photographs.

Data (../shared/data, or --root DIR): the DiLiGenT objects (96 lights, every 8th held out: 12
predicted from 84) and the DiLiGenT-Π reliefs (5 lights, each left out in turn: predicted from
4; 1216×1216 px cropped to the object and taken every `--pi-step` px). A method with more terms
than fitted lights is "n/a".
"""
import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import RBFInterpolator

import facette
from facette.errors import InsufficientData
from facette.io.diligent import read_diligent, write_diligent
from facette.pipeline import process
from facette.pipeline._relight import kd_map_from_albedo, relight, viewer_model
from facette.recon import fit_hsh, fit_ptm_lrgb, hsh_basis, ptm_basis, relight_hsh, relight_ptm

METHODS = ("PTM", "HSH 2", "HSH 3", "RBF (Relight)", "Lambert (PS)", "facette PB", "facette PB+gain")
PB_METHODS = METHODS[4:]
GAINS = []          # the per-pixel gains' median (green) of each process() run: the viewer's scale error
RAKING_DEG = 75.0


def raking_lights(theta_deg=RAKING_DEG, n=8):
    """n unit directions at theta_deg from the camera axis, evenly around it."""
    az = np.radians(np.arange(n) * 360.0 / n)
    t = np.radians(theta_deg)
    return np.c_[np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.full(n, np.cos(t))]


def _load(folder, step=1, margin=8):
    """(images (m, H, W, 3), dirs (m, 3), mask) cropped to the mask's box + margin, every step px."""
    d = read_diligent(folder)
    rows, cols = np.nonzero(d.mask)
    r0, r1 = max(rows.min() - margin, 0), min(rows.max() + margin + 1, d.mask.shape[0])
    c0, c1 = max(cols.min() - margin, 0), min(cols.max() + margin + 1, d.mask.shape[1])
    sl = (slice(r0, r1, step), slice(c0, c1, step))
    return np.ascontiguousarray(d.images[:, sl[0], sl[1]]), d.light_dirs, d.mask[sl]


class _Scores:
    """Sums of one method over the held-out photographs and the raking lights."""

    def __init__(self):
        self.num = self.den = 0.0
        self.sq = []
        self.neg = []
        self.seconds = 0.0
        self.why = ""
        self.unknown = 0
        self.failed = False

    def add(self, pred, photo, mask):
        sel = mask & np.all(np.isfinite(photo), axis=-1)
        bad = sel & ~np.all(np.isfinite(pred), axis=-1)
        self.unknown += int(bad.sum())              # a pixel the method gives no value: 0 counted
        diff = (np.nan_to_num(pred) - photo)[sel]
        self.num += float(np.sum(diff * diff))
        self.den += float(np.sum(photo[sel].astype(np.float64) ** 2))
        self.sq.append(np.mean(diff * diff))

    def rel_rms(self):
        return np.sqrt(self.num / self.den) if self.den > 0 else np.nan

    def psnr(self, peak):
        return 10 * np.log10(peak ** 2 / np.mean(self.sq)) if self.sq else np.nan


def _ptm(train, dirs, mask):
    fit = fit_ptm_lrgb(train, dirs, mask=mask)
    if fit.valid[mask].mean() < 0.5:
        return None, "fewer lights than terms"
    return (lambda d: relight_ptm(fit, d),
            lambda d: (fit.coeffs @ ptm_basis(d)) < 0), ""


def _hsh(order):
    def fit_fn(train, dirs, mask):
        if len(dirs) < order * order:
            return None, "fewer lights than terms"
        fit = fit_hsh(train, dirs, order, mask=mask)
        if fit.valid[mask].mean() < 0.5:
            return None, "fewer lights than terms"
        return (lambda d: relight_hsh(fit, d),
                lambda d: np.any(fit.coeffs @ hsh_basis(d, order) < 0, axis=-1)), ""
    return fit_fn


def _rbf_fit(xy, vals, mult, smoothing, spacing):
    return RBFInterpolator(xy, vals, kernel="gaussian", epsilon=1.0 / (mult * spacing), smoothing=smoothing)


def _rbf(train, dirs, mask, widths=(1, 2, 4, 8), smoothings=(1e-3, 1e-2), n_check=20000):
    """Gaussian RBF over the lights' (x, y), every pixel of the mask at once (one system, many
    right-hand sides). A clipped (unknown) value is filled with its pixel's brightest known one.
    The width (1–8 × the median spacing of the lights) and the smoothing are chosen on the
    fitted photographs alone: every 8th of them (each in turn with fewer than 16) predicted from
    the others, on up to `n_check` values."""
    vals = train[:, mask].reshape(len(train), -1)                  # (m, N*3)
    top = np.nanmax(np.where(np.isfinite(vals), vals, -np.inf), axis=0)
    vals = np.where(np.isfinite(vals), vals, np.where(np.isfinite(top), top, 0.0)[None])
    xy = dirs[:, :2]
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    spacing = float(np.median(dist.min(axis=1)))
    m = len(xy)
    folds = [np.arange(7, m, 8)] if m >= 16 else [[i] for i in range(m)]
    cols = np.linspace(0, vals.shape[1] - 1, min(n_check, vals.shape[1])).astype(int)
    best = None
    for mult in widths:
        for sm in smoothings:
            err = 0.0
            for f in folds:
                keep = np.setdiff1d(np.arange(m), f)
                if len(keep) < 2:
                    continue
                pred = _rbf_fit(xy[keep], vals[keep][:, cols], mult, sm, spacing)(xy[f])
                err += float(np.sum((pred - vals[f][:, cols]) ** 2))
            if best is None or err < best[0]:
                best = (err, mult, sm)
    interp = _rbf_fit(xy, vals, best[1], best[2], spacing)
    shape = mask.shape + (3,)

    def render(d):
        out = np.zeros(shape)
        out[mask] = interp(np.asarray(d, float)[None, :2]).reshape(-1, 3)
        return out

    return (lambda d: np.clip(render(d), 0, None), lambda d: np.any(render(d) < 0, axis=-1)), ""


def _physically_based(train, dirs, mask, work, ps_method="rank_trimmed"):
    """process() on the fitted photographs (a DiLiGenT folder of them, 16-bit PNGs scaled to the
    brightest known value). Returns ({name: (render, negative)}, why): the viewer's relighting as
    it is (K_d map from the albedo, `kd_map_from_albedo`); the same with a per-pixel, per-channel
    gain fitted by least squares to the fitted photographs (what the K_d map's scale misses);
    and Lambert's law with the photometric-stereo albedo (ρ/π n·l)."""
    finite = np.isfinite(train)
    top = float(np.max(train[finite])) if finite.any() else 1.0
    u16 = np.where(finite, np.round(np.clip(train / top, 0, 1) * 65534), 65535).astype(np.uint16)
    # The BRDF fit wants radiance factors (a K_d within [0, 1]): one intensity for every light
    # that brings the typical bright pixel's albedo to about 0.8 (its median over the lights is
    # about ρ/π · 0.8); the predictions are scaled back by the same factor.
    with np.errstate(invalid="ignore"):
        med = np.nanmedian(np.where(finite, train / top, np.nan)[:, mask][..., 1], axis=0)
    c = float(np.nanpercentile(med, 99)) / (0.8 * 0.8 / np.pi) if np.isfinite(med).any() else 1.0
    write_diligent(work, u16, dirs, light_intensities=np.full((len(dirs), 3), c), mask=mask)
    top *= c
    try:
        res = process(work, outputs=["normals", "albedo", "brdf"], method=ps_method,
                      fit_options={"model": "li"})
    except InsufficientData as exc:
        return None, f"process: {exc}"
    finally:
        shutil.rmtree(work, ignore_errors=True)
    n = res.normals
    rho = np.nan_to_num(res.albedo)          # NaN where photometric stereo gave no albedo: dark

    def lambert(d):
        return top * rho / np.pi * np.clip(n @ np.asarray(d, float), 0, None)[..., None] * res.mask[..., None]

    def never_negative(render):
        return lambda d: np.any(render(d) < 0, axis=-1)

    fns = {"Lambert (PS)": (lambert, never_negative(lambert))}
    try:
        m = viewer_model(res.brdf if res.brdf is not None else {"success": False, "message": "no BRDF fitted"})
    except ValueError as exc:
        return fns, str(exc)
    kd = kd_map_from_albedo(rho, res.mask, m.kd, res.inputs.material_mask)

    def viewer(d):
        return top * relight(res.normals, kd, res.mask, m, d)

    num = np.zeros(mask.shape + (3,))
    den = np.zeros(mask.shape + (3,))
    for img, d in zip(train, dirs):
        pred = viewer(d)
        ok = np.isfinite(img)
        num += np.where(ok, pred * np.nan_to_num(img), 0.0)
        den += np.where(ok, pred * pred, 0.0)
    # where the model gives (almost) no light under every fitted light there is nothing to scale:
    # gain 1; elsewhere bounded to [0, 4] (a pixel the model gets wrong is not rescued by a gain)
    tiny = den <= 1e-6 * max(float(np.median(den[res.mask])) if res.mask.any() else 0.0, 1e-30)
    gain = np.clip(np.where(tiny, 1.0, num / np.where(tiny, 1.0, den)), 0.0, 4.0)
    GAINS.append(float(np.median(gain[res.mask][:, 1])))
    fns.update({k: (f, never_negative(f)) for k, f in
                (("facette PB", viewer), ("facette PB+gain", lambda d: gain * viewer(d)))})
    return fns, ""


FITS = {"PTM": _ptm, "HSH 2": _hsh(2), "HSH 3": _hsh(3), "RBF (Relight)": _rbf}


def _score(sc, fns, why, images, dirs, held, mask, raking, t0):
    if fns is None:              # one fold without a fit: the method is n/a on this object
        sc.why = sc.why or why
        sc.failed = True
    else:
        render, negative = fns
        for h in held:
            sc.add(render(dirs[h]), images[h], mask)
        if raking:
            sc.neg = [float(np.mean(negative(d)[mask])) for d in raking_lights()]
    sc.seconds += time.perf_counter() - t0


def evaluate(images, dirs, mask, folds, work, ps_method="rank_trimmed"):
    """Scores of every method over the folds (lists of held-out indices)."""
    scores = {name: _Scores() for name in METHODS}
    held_all = []
    for k, held in enumerate(folds):
        fit_sel = np.setdiff1d(np.arange(len(dirs)), held)
        train, tdirs = images[fit_sel], dirs[fit_sel]
        held_all.extend(images[h][mask] for h in held)
        for name in METHODS[:4]:
            t0 = time.perf_counter()
            fns, why = FITS[name](train, tdirs, mask)
            _score(scores[name], fns, why, images, dirs, held, mask, k == 0, t0)
        t0 = time.perf_counter()
        pb, why = _physically_based(train, tdirs, mask, work / f"fold{k}", ps_method)
        shared = time.perf_counter() - t0          # one process() run: each PB row is charged it
        for name in PB_METHODS:
            _score(scores[name], (pb or {}).get(name), why, images, dirs, held, mask, k == 0,
                   time.perf_counter() - shared)
    vals = np.concatenate(held_all).ravel()
    peak = float(np.percentile(vals[np.isfinite(vals)], 99.9))
    return scores, peak


def _print(label, scores, peak):
    if GAINS and not scores["facette PB+gain"].failed:
        scores["facette PB+gain"].why = f"median gain {np.median(GAINS):.3f}"
        GAINS.clear()
    for name in METHODS:
        sc = scores[name]
        if sc.failed or not sc.sq:
            print(f"  {label:22s} {name:15s} {'n/a':>8s} {'':>8s} {'':>11s} {sc.seconds:7.2f} s  ({sc.why})")
        else:
            neg = f"{100 * np.mean(sc.neg):9.2f} %" if sc.neg else f"{'n/a':>11s}"
            why = "; ".join(filter(None, [sc.why, f"{sc.unknown} values NaN, counted 0" if sc.unknown else ""]))
            print(f"  {label:22s} {name:15s} {100 * sc.rel_rms():7.2f} % {sc.psnr(peak):6.2f} dB {neg} "
                  f"{sc.seconds:7.2f} s" + (f"  ({why})" if why else ""), flush=True)
        label = ""


def _header():
    print(f"  {'object':22s} {'method':15s} {'rel. RMS':>8s} {'PSNR':>9s} {'neg. @75°':>11s} {'time':>9s}")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench relight", description=__doc__.splitlines()[0])
    default_root = Path(facette.__file__).resolve().parents[2].parent / "shared" / "data"
    ap.add_argument("--root", default=str(default_root), help=f"real data folder (default {default_root})")
    ap.add_argument("--diligent", default="ballPNG,catPNG,pot2PNG,buddhaPNG,readingPNG",
                    help="DiLiGenT objects ('' for none)")
    ap.add_argument("--pi", default="Bagua-R,Cloud-R,Bear,Bird",
                    help="DiLiGenT-Π objects, comma separated, 'all' or '' (default: two rough plaques, a "
                         "specular relief, a metal coin: 5 process() runs each)")
    ap.add_argument("--pi-step", type=int, default=8, help="DiLiGenT-Π: every N-th pixel (default 8)")
    args = ap.parse_args(argv)
    base = Path(args.root)
    work = Path(tempfile.mkdtemp(prefix="facette_bench_relight_"))
    try:
        names = [n for n in args.diligent.split(",") if n]
        folders = [next((base / p / n for p in ("diligent", "diligent_crop8")
                         if (base / p / n / "filenames.txt").is_file()), None) for n in names]
        folders = [f for f in folders if f is not None]
        if folders:
            print("1. DiLiGenT, 96 lights: every 8th held out (12 predicted from 84)")
            _header()
            for f in folders:
                images, dirs, mask = _load(f)
                scores, peak = evaluate(images, dirs, mask, [np.arange(7, len(dirs), 8)], work)
                _print(f"{f.name} {mask.shape[1]}x{mask.shape[0]}", scores, peak)
        pi_base = base / "diligent_pi"
        if args.pi == "all":
            pi = sorted(p.name for p in pi_base.iterdir() if (p / "filenames.txt").is_file()) \
                if pi_base.is_dir() else []
        else:
            pi = [n for n in args.pi.split(",") if n and (pi_base / n / "filenames.txt").is_file()]
        if pi:
            print(f"2. DiLiGenT-Π reliefs, 5 lights: each left out in turn (predicted from 4), every "
                  f"{args.pi_step} px")
            _header()
            for n in pi:
                images, dirs, mask = _load(pi_base / n, step=args.pi_step)
                # 4 lights: least squares (rank_trimmed needs lights to trim)
                scores, peak = evaluate(images, dirs, mask, [[k] for k in range(len(dirs))], work, "woodham1980")
                _print(f"{n} {mask.shape[1]}x{mask.shape[0]}", scores, peak)
        if not folders and not pi:
            print(f"no DiLiGenT data under {base} (pass --root DIR); skipped")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0
