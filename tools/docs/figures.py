"""The documentation's pictures, made by running the tutorials' steps (`make docs` runs this first).

Each tutorial's commands run here as a user types them, on the simulated rig at a small size and
on generated data, into build/docs/work/; the pictures go to build/docs/figures/ (the mkdocs hook
adds them to the site as img/generated/NAME). A picture already made is kept: delete
build/docs/ to make them anew. `--overview PATH` also writes the README's picture there
(docs/img/overview.png is made so: `python tools/docs/figures.py --overview docs/img/overview.png`).
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / "build" / "docs"
WORK, FIGURES = BUILD / "work", BUILD / "figures"
RAW_SIZE = "256x192"            # the demo scan, small: 128x96 px maps
# The tutorials' commands this script runs, as the pages show them (host/tests/test_docs_examples.py
# checks that each is on its page, word for word).
STEPS = {
    "scan": ("tutorials/first-scan.md", f"scan --sim --press-button --raw-size {RAW_SIZE} scan-demo"),
    "calibrate": ("tutorials/calibration.md", f"calibrate --rig sim --yes -o calibration-sim --sim-raw-size {RAW_SIZE}"),
    "second scan": ("tutorials/batch.md",
                    f"scan --sim --press-button --raw-size {RAW_SIZE} --scene sphere --no-process scans/sphere"),
    "batch": ("tutorials/batch.md", "batch scans/* -o collection --outputs normals,height,brdf"),
}
NAMES = ("overview.png", "first-scan.png", "first-scan-report.png", "rti-relit.png", "calibration.png",
         "batch-summary.png", "library.png")


def placeholder_png(name):
    """A small grey PNG saying the picture is made by `make docs` (for `make docs-check`)."""
    import io

    from PIL import Image, ImageDraw

    img = Image.new("RGB", (480, 60), (236, 239, 241))
    ImageDraw.Draw(img).text((10, 22), f"{name}: made by `make docs` (tools/docs/figures.py)", fill=(60, 60, 60))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


def step(name):
    """Run one of STEPS as the page shows it (a shell pattern expanded in the work folder)."""
    import glob
    import shlex

    words = []
    for word in shlex.split(STEPS[name][1]):
        words += sorted(os.path.relpath(p, WORK) for p in glob.glob(str(WORK / word))) if "*" in word else [word]
    facette(*words)


def facette(*args):
    """Run `facette ARGS` as a user would (this tree's package), printing what it prints."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "host") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "facette.cli.main", *map(str, args)]
    print("$ facette " + " ".join(map(str, args)), flush=True)
    subprocess.run(cmd, check=True, env=env, cwd=WORK, stdout=subprocess.DEVNULL)


def _exr(path):
    from facette.io.exr import read_exr

    return read_exr(path)[0]


def _display(img, white=None):
    """Linear values to sRGB display values, `white` (default: the image's 99.5th percentile) at 1."""
    import numpy as np

    white = float(np.percentile(img, 99.5)) if white is None else white
    img = np.clip(img / max(white, 1e-12), 0, 1)
    return np.where(img <= 0.0031308, 12.92 * img, 1.055 * img ** (1 / 2.4) - 0.055)


def _hillshade(height):
    import numpy as np
    from matplotlib.colors import LightSource

    h = np.nan_to_num(height)
    return LightSource(azdeg=315, altdeg=45).hillshade(h, vert_exag=8.0 / max(np.ptp(h), 1e-9))


def _panel(axes, images, titles):
    for ax, img, title in zip(axes, images, titles):
        ax.imshow(img, cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=1)
        ax.set_title(title, fontsize=9)
        ax.axis("off")


def _save(fig, name):
    FIGURES.mkdir(parents=True, exist_ok=True)
    fig.savefig(FIGURES / name, dpi=110, bbox_inches="tight")


def first_scan():
    """Tutorial 1: `facette scan --sim --press-button --raw-size 256x192 scan-demo`."""
    scan = WORK / "scan-demo"
    if not (scan / "results" / "normal.exr").exists():
        step("scan")
    return scan


def scan_figures(scan):
    import matplotlib.pyplot as plt
    import numpy as np

    res = scan / "results"
    photos = sorted((scan / "hdr").glob("light_??.exr"))
    n = _exr(res / "normal.exr")
    normal_rgb = np.clip((n + 1) / 2, 0, 1)
    height = _exr(res / "height.exr")
    height = height[..., 0] if height.ndim == 3 else height
    relit = _relight(res / "relight.ptm", "135,40", "demo-relit.png")
    fig, axes = plt.subplots(1, 4, figsize=(11, 2.6))
    _panel(axes, [_display(_exr(photos[0])), normal_rgb, relit, _hillshade(height)],
           [f"photograph 1 of {len(photos)} (HDR)", "normals", "relit from a new light (PTM)",
            "heights, shaded"])
    _save(fig, "overview.png")
    fig, axes = plt.subplots(1, 3, figsize=(9, 2.8))
    _panel(axes, [normal_rgb, _display(_exr(res / "albedo.exr")), _hillshade(height)],
           ["normal.exr (x, y, z as R, G, B)", "albedo.exr", "height.exr, shaded"])
    _save(fig, "first-scan.png")
    plt.close("all")
    _screenshot(res / "report.html", "first-scan-report.png")


def _relight(path, light, out):
    from facette.io.png import read_png

    facette("relight", path, "--light", light, "-o", WORK / out)
    img = read_png(WORK / out)
    return img / (65535.0 if img.dtype.itemsize == 2 else 255.0)


def _screenshot(html, name, size="1280,900"):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        print(f"(no chromium: {name} left as a placeholder)")
        return
    FIGURES.mkdir(parents=True, exist_ok=True)
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--screenshot={FIGURES / name}", f"--window-size={size}",
                    "--virtual-time-budget=8000", Path(html).resolve().as_uri()],
                   check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)


def rti_capture(scan):
    """Tutorial 2: the scan's photographs as a dome's JPEGs and .lp, processed to .ptm/.rti."""
    import matplotlib.pyplot as plt
    import numpy as np

    from facette.calib.lp import write_lp
    from facette.scan import ScanDirectory

    capture = WORK / "dome-capture"
    if not (capture / "capture.lp").exists():
        import cv2

        capture.mkdir(parents=True, exist_ok=True)
        lights = ScanDirectory(scan).manifest.lights
        photos = [_exr(scan / "hdr" / f"light_{light.index:02d}.exr") for light in lights]
        white = max(float(np.percentile(p, 99.5)) for p in photos)      # one exposure for every light
        names = []
        for light, photo in zip(lights, photos):
            img = _display(photo, white)
            names.append(f"IMG_{light.index:04d}.jpg")
            cv2.imwrite(str(capture / names[-1]), np.round(img[..., ::-1] * 255).astype(np.uint8))
        write_lp(capture / "capture.lp", names, [light.direction for light in lights])
    if not (WORK / "dome-results" / "relight.rti").exists():
        facette("process", "dome-capture", "-o", "dome-results", "--outputs", "normals,ptm,rti")
    lights = ("0,25", "90,25", "180,25", "270,25")
    views = [_relight(WORK / "dome-results" / "relight.rti", light, f"dome-{i}.png") for i, light in enumerate(lights)]
    fig, axes = plt.subplots(1, 4, figsize=(11, 2.6))
    _panel(axes, views, [f"relight.rti, light at {light} (az, el)" for light in lights])
    _save(fig, "rti-relit.png")
    plt.close("all")


def calibration():
    """Tutorial 3: `facette calibrate --rig sim --yes -o calibration-sim --sim-raw-size 256x192`."""
    import matplotlib.pyplot as plt
    import numpy as np

    profile = WORK / "calibration-sim"
    if not (profile / "profile.json").exists():
        step("calibrate")
    data = json.loads((profile / "profile.json").read_text())
    dirs = np.array([light["direction"] for light in data["lights"]])
    fig = plt.figure(figsize=(3.6, 3.6))
    ax = fig.add_subplot(projection="polar")
    ax.scatter(np.arctan2(dirs[:, 1], dirs[:, 0]), np.degrees(np.arccos(np.clip(dirs[:, 2], -1, 1))), c="C1")
    for i, d in enumerate(dirs):
        ax.annotate(str(i), (np.arctan2(d[1], d[0]), np.degrees(np.arccos(d[2]))), fontsize=7)
    ax.set_rmax(60)
    ax.set_title("measured light directions\n(angle from the view, degrees)", fontsize=9)
    _save(fig, "calibration.png")
    plt.close("all")


def batch(scan):
    """Tutorial 4: `facette batch scans/* -o collection` on the demo scan and a second one."""
    scans = WORK / "scans"
    second = scans / "sphere"
    if not (scans / "scan-demo").exists():
        scans.mkdir(parents=True, exist_ok=True)
        (scans / "scan-demo").symlink_to(scan)
    if not (second / "scan.json").exists():
        step("second scan")
    if not (WORK / "collection" / "summary.html").exists():
        step("batch")
    _screenshot(WORK / "collection" / "summary.html", "batch-summary.png", size="1280,500")


def library():
    """Tutorial 5: the library from Python, on a generated DiLiGenT-style folder."""
    import matplotlib.pyplot as plt
    import numpy as np

    import facette
    from sample_data import diligent_folder

    folder = diligent_folder(WORK / "sphere-folder")
    result = facette.process(folder, outputs=["normals", "height"])
    fig, axes = plt.subplots(1, 2, figsize=(6, 2.6))
    _panel(axes, [np.clip((result.normals + 1) / 2, 0, 1), _hillshade(result.height)],
           ["result.normals", "result.height, shaded"])
    _save(fig, "library.png")
    plt.close("all")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--overview", help="also copy the overview picture here (the README's)")
    args = p.parse_args(argv)
    WORK.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    missing = [n for n in NAMES if not (FIGURES / n).exists()]
    if missing:
        scan = first_scan()
        scan_figures(scan)
        rti_capture(scan)
        calibration()
        batch(scan)
        library()
    if args.overview:
        shutil.copyfile(FIGURES / "overview.png", args.overview)
    print(f"figures: {len(NAMES)} in {FIGURES} ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()
