"""`facette bench rti`'s real captures: facette's relight.ptm / relight.rti / relight_web against plain
least-squares fits of the same photographs, on lights the fits never saw and at the captured ones.

Each capture is a folder of 8-bit photographs with an .lp (RTIBuilder's layout): the real dome capture
rti_captures/loewenkopf_240, and JPEG + .lp captures made here from the DiLiGenT crops (each 8-bit PNG
written as a JPEG, quality 95, as a camera would give it: the photograph is the JPEG, no intensities
divided out). Every 6th light is held out; `facette process` fits the others (--outputs ptm,rti,
relight-web: no photometric stereo; and --outputs ptm with --ptm-format lrgb and rgb); the files are read as
RTIViewer reads them (PTM: `_relight_ptm_reader`, written from RTIViewer's loaders; HSH) and as openlime reads the web folder, relit at the held-out lights and at the
fitted ones, and compared with the photographs as 8-bit display values: PSNR over every pixel and
channel of each photograph (mean over the photographs, as the NeuralRTI benchmark computes it) and
SSIM (Wang et al. 2004, Gaussian window σ 1.5, on the mean of the channels). The plain fits: per
channel least squares of the photographs' byte values / 255, HSH order 3 in RTIBuilder's basis and
the biquadratic PTM, kept in floats (no file, no quantisation); and the nearest photograph.
"""
import shutil
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from facette.calib.lp import read_lp
from facette.bench._relight_ptm_reader import read_ptm_as_rtiviewer
from facette.io.ptm import ptm_weights, read_ptm
from facette.io.relight_web import read_relight_web
from facette.io.rti import hsh_weights, read_hsh_rti

__all__ = ["captures_section", "psnr", "ssim", "make_jpeg_capture", "ptm_reader_control"]

HOLD_EVERY = 6


def psnr(a, b):
    """PSNR (dB) of two 8-bit pictures (H, W, 3) over every pixel and channel."""
    mse = np.mean((np.asarray(a, float) - np.asarray(b, float)) ** 2)
    return float(10 * np.log10(255.0 ** 2 / max(mse, 1e-12)))


def ssim(a, b):
    """SSIM (Wang, Bovik, Sheikh & Simoncelli 2004, eq. 13: Gaussian window σ = 1.5, K1 0.01, K2 0.03)
    of two 8-bit pictures, on the mean of their channels."""
    x, y = np.asarray(a, float).mean(-1), np.asarray(b, float).mean(-1)
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    mx, my = gaussian_filter(x, 1.5), gaussian_filter(y, 1.5)
    sxx = gaussian_filter(x * x, 1.5) - mx * mx
    syy = gaussian_filter(y * y, 1.5) - my * my
    sxy = gaussian_filter(x * y, 1.5) - mx * my
    return float(np.mean((2 * mx * my + c1) * (2 * sxy + c2) / ((mx * mx + my * my + c1) * (sxx + syy + c2))))


def _photos(folder):
    """(names as in the .lp, directions (m, 3), photographs (m, H, W, 3) uint8 RGB) of a capture."""
    lp = next(Path(folder).glob("*.lp"))
    names, dirs = read_lp(lp)
    imgs = np.stack([cv2.cvtColor(cv2.imread(str(Path(folder) / n)), cv2.COLOR_BGR2RGB) for n in names])
    return names, dirs, imgs


def make_jpeg_capture(diligent_folder, out):
    """A JPEG + .lp capture of a DiLiGenT folder's 8-bit PNGs (the photographs as they are)."""
    src = Path(diligent_folder)
    names = [l.strip() for l in (src / "filenames.txt").read_text().splitlines() if l.strip()]
    dirs = np.loadtxt(src / "light_directions.txt").reshape(-1, 3)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for n, d in zip(names, dirs):
        img = cv2.imread(str(src / n), cv2.IMREAD_UNCHANGED)
        if img.dtype != np.uint8:
            img = (img >> 8).astype(np.uint8)
        jpg = Path(n).with_suffix(".jpg").name
        cv2.imwrite(str(out / jpg), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
        rows.append(f"{jpg} {d[0]:.8f} {d[1]:.8f} {d[2]:.8f}")
    (out / "lights.lp").write_text(f"{len(rows)}\n" + "\n".join(rows) + "\n")
    return out


def _fit_folder(folder, names, fit_idx, out):
    """A capture of the fitted lights only (hard links, or copies), its .lp beside them."""
    out.mkdir(parents=True)
    lines = [l for l in (next(Path(folder).glob("*.lp"))).read_text().splitlines()[1:] if l.strip()]
    for i in fit_idx:
        dst = out / names[i]
        dst.parent.mkdir(parents=True, exist_ok=True)
        try:
            dst.hardlink_to(Path(folder) / names[i])
        except OSError:
            shutil.copy(Path(folder) / names[i], dst)
    (out / "fit.lp").write_text(f"{len(fit_idx)}\n" + "\n".join(lines[i] for i in fit_idx) + "\n")
    return out


def _plain_fits(photos, dirs):
    """Per-channel least squares of photos (m, H, W, 3) / 255 under dirs: {name: render(d) -> (H, W, 3)}."""
    y = photos.reshape(len(photos), -1).astype(np.float64) / 255.0
    out = {}
    for name, basis in (("plain HSH 3", lambda d: hsh_weights(d, 9)), ("plain PTM", ptm_weights)):
        a = basis(dirs)
        coeffs = np.linalg.lstsq(a, y, rcond=None)[0]
        out[name] = (lambda c, b: lambda d: (b(np.asarray(d)) @ c).reshape(photos.shape[1:]))(coeffs, basis)
    return out


def _score(render, photos, dirs):
    """(mean PSNR, mean SSIM) of render(d) in [0, 1] against the 8-bit photographs at dirs."""
    p, s = [], []
    for img, d in zip(photos, dirs):
        got = np.clip(np.round(np.clip(render(d), 0, 1) * 255), 0, 255)
        p.append(psnr(got, img))
        s.append(ssim(got, img))
    return float(np.mean(p)), float(np.mean(s))


def capture_rows(folder, label, work):
    """The table rows of one capture: [(label, method, held PSNR, SSIM, captured PSNR, SSIM, fit s/MP, MB/MP)]."""
    from facette.pipeline import process
    names, dirs, photos = _photos(folder)
    m, h, w, _ = photos.shape
    mp = h * w / 1e6
    held = np.arange(m) % HOLD_EVERY == HOLD_EVERY - 1
    fit_idx = np.flatnonzero(~held)
    fit_dir = _fit_folder(folder, names, fit_idx, work / "fit")
    t0 = time.perf_counter()
    res = process(fit_dir, outputs=["ptm", "rti", "relight-web"], out_dir=work / "out")
    wall = time.perf_counter() - t0
    out = work / "out"
    rti = read_hsh_rti(out / "relight.rti")
    ptm, ptm_format = read_ptm_as_rtiviewer(out / "relight.ptm")       # RTIViewer's rules, not io.ptm
    web = read_relight_web(out / "relight_web")
    web_mb = sum(p.stat().st_size for p in (out / "relight_web").rglob("*") if p.is_file()) / 1e6
    methods = [("facette relight.rti (RTIViewer)", rti.relight, res.timings.get("hsh"),
                (out / "relight.rti").stat().st_size / 1e6),
               ("facette relight.ptm (auto)", lambda d: ptm(d[0], d[1]) / 255,
                res.timings.get("ptm"), (out / "relight.ptm").stat().st_size / 1e6),
               ("facette relight_web (openlime)", web.relight, None, web_mb)]
    for fmt in ("lrgb", "rgb"):          # each format asked for, read by RTIViewer's rules
        r = process(fit_dir, outputs=["ptm"], out_dir=work / f"out_{fmt}", ptm_format=fmt)
        f, _ = read_ptm_as_rtiviewer(work / f"out_{fmt}" / "relight.ptm")
        methods.append((f"facette relight.ptm {fmt.upper()}", (lambda g: lambda d: g(d[0], d[1]) / 255)(f),
                        r.timings.get("ptm"), (work / f"out_{fmt}" / "relight.ptm").stat().st_size / 1e6))
    t0 = time.perf_counter()
    plain = _plain_fits(photos[fit_idx], dirs[fit_idx])
    t_plain = (time.perf_counter() - t0) / 2
    methods += [(k, f, t_plain, None) for k, f in plain.items()]
    near = lambda d: photos[fit_idx][np.argmax(dirs[fit_idx] @ d)] / 255.0      # noqa: E731
    methods.append(("nearest photograph", near, None, None))
    rows = []
    for name, render, secs, mb in methods:
        hp, hs = _score(render, photos[held], dirs[held])
        cp, cs = _score(render, photos[fit_idx], dirs[fit_idx]) if name != "nearest photograph" else (np.inf, 1.0)
        rows.append((label, name, hp, hs, cp, cs, None if secs is None else secs / mp, None if mb is None else mb / mp))
    rows.append((label, f"(process --outputs ptm,rti,relight-web: {wall:.2f} s wall, {m - held.sum()} lights, "
                 f"{w}x{h}; relight.ptm auto: {ptm_format})", None, None, None, None, None, None))
    return rows


def ptm_reader_control(root):
    """The RTIViewer-rules reader (`_relight_ptm_reader`) on a PTM written by others: HP's tablet1.ptm
    (PTM_FORMAT_JPEG_LRGB) with its nine planes as `io.ptm` decodes them stored again as
    PTM_FORMAT_LRGB (the same bytes, uncompressed: the reader has no JPEG planes), against `io.ptm`'s
    own RTIViewer reading; printed: the largest difference in grey levels at five lights."""
    src = Path(root) / "rti_reference" / "ptm" / "tablet1.ptm"
    if not src.is_file():
        print(f"  PTM reader control: {src} not here; skipped")
        return None
    f = read_ptm(src)
    raw = np.clip(np.round(f.coeffs / f.scale + f.bias), 0, 255).astype(np.uint8)
    header = (f"PTM_1.2\nPTM_FORMAT_LRGB\n{f.width}\n{f.height}\n" + " ".join(f"{x:.9g}" for x in f.scale) + "\n"
              + " ".join(str(int(b)) for b in f.bias) + "\n").encode()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tablet1_lrgb.ptm"
        path.write_bytes(header + raw[::-1].tobytes() + f.rgb[::-1].tobytes())
        theirs, fmt = read_ptm_as_rtiviewer(path)
        lights = [(0.0, 0.0), (0.6, 0.0), (-0.6, 0.0), (0.0, 0.6), (0.4, -0.5)]
        diff = max(float(np.abs(theirs(lx, ly) - 255 * f.relight([lx, ly, np.sqrt(1 - lx * lx - ly * ly)],
                                                                  rtiviewer=True)).max()) for lx, ly in lights)
        lit = theirs(0.6, 0.0)
        right = float(lit[:, 256:].mean() - lit[:, :256].mean())
    print(f"  PTM reader control: HP's tablet1.ptm ({f.format}, {f.width}x{f.height}) re-stored as {fmt}, read by "
          f"RTIViewer's rules: largest difference with io.ptm's reading {diff:.3f} grey levels at 5 lights; lit "
          f"from +x the right half is {right:+.1f} grey levels brighter")
    return diff


def captures_section(root):
    """Section 5 of `facette bench rti`: the table, per capture and the mean."""
    root = Path(root)
    lion = root / "rti_captures" / "loewenkopf_240" / "data"
    crops = sorted((root / "diligent_crop8").glob("*PNG"))
    if not lion.is_dir() and not crops:
        print(f"5. real captures: none under {root}; skipped")
        return []
    print(f"5. real captures, every {HOLD_EVERY}th light held out: PSNR (dB, 8-bit display values, every pixel and "
          "channel) and SSIM; fit time and file size per megapixel")
    print(f"  {'capture':16s} {'method':34s} {'held PSNR':>9s} {'SSIM':>6s} {'captured':>9s} {'SSIM':>6s} "
          f"{'fit s/MP':>9s} {'MB/MP':>7s}")
    all_rows = []
    ptm_reader_control(root)
    with tempfile.TemporaryDirectory(prefix="facette-bench-rti-") as tmp:
        tmp = Path(tmp)
        sets = ([(lion, "loewenkopf_240")] if lion.is_dir() else []) + [
            (make_jpeg_capture(c, tmp / f"{c.name}_jpeg"), c.name.replace("PNG", "") + " (JPEG)") for c in crops]
        for k, (folder, label) in enumerate(sets):
            rows = capture_rows(folder, label, tmp / f"work{k}")
            for r in rows:
                if r[2] is None:
                    print(f"  {'':16s} {r[1]}")
                    continue
                f = lambda v, fmt: (fmt % v) if v is not None and np.isfinite(v) else "-"    # noqa: E731
                print(f"  {r[0]:16s} {r[1]:34s} {f(r[2], '%9.2f')} {f(r[3], '%6.3f')} {f(r[4], '%9.2f'):>9s} "
                      f"{f(r[5], '%6.3f'):>6s} {f(r[6], '%9.2f'):>9s} {f(r[7], '%7.2f'):>7s}", flush=True)
            all_rows += [r for r in rows if r[2] is not None]
    methods = dict.fromkeys(r[1] for r in all_rows)
    print(f"  mean over {len(sets)} captures:")
    for name in methods:
        sel = [r for r in all_rows if r[1] == name]
        cap = [r[4] for r in sel if np.isfinite(r[4])]
        print(f"  {'':16s} {name:34s} {np.mean([r[2] for r in sel]):9.2f} {np.mean([r[3] for r in sel]):6.3f} "
              f"{(np.mean(cap) if cap else float('nan')):9.2f}")
    return all_rows
