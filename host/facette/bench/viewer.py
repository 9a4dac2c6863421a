"""`facette bench viewer`: the report's relighting viewer in headless Chromium.

Prints, for a synthetic 2144 × 1424 result (a sphere on a textured plane, the LI lobe of a
glossy material) and for the small simulated scan of the browser test:
1. the browser-vs-reference pixel difference (8-bit sRGB levels over the object) at three
   light directions, against facette.pipeline._relight.relight (facette.brdf);
2. the frame time at 2144 × 1424: draw + gl.finish + a one-pixel read-back (which, unlike
   Chromium's gl.finish, waits for the frame) per frame (median over N frames, one per
   requestAnimationFrame) and the start-up time (decode, texture upload, first frame);
   and the same while the light is dragged (a preview of at most ~1 MP);
3. screenshots (PNG) of the report and of the viewer at two light directions in --out.

The WebGL here is SwiftShader (CPU, 2 cores shared): a GPU is one to two orders faster.

Usage: facette bench viewer [--out DIR] [--frames N] [--report REPORT.html] [--size H W]
                            [--skip-large] [--skip-report]
"""
import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from facette.bench._browser import By, chromium, console_errors, viewer_pixels, wait_for_viewer
from facette.bench._sim_scan import write_scan
from facette.pipeline import process
from facette.pipeline._relight import BACKGROUND, light_from_angles, relight, to_srgb8
from facette.pipeline._viewer import viewer_data, viewer_section
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

LIGHTS = [(135.0, 45.0), (0.0, 20.0), (270.0, 70.0)]
RAKING = (135.0, 15.0)          # 75° from the camera axis
GLOSSY_LI = {"model": "li", "distribution": "beckmann", "masking": "smith", "volume": "approx",
             "success": True, "parameters": {"sigma": 0.044, "n_i": 1.14, "kd": [0.65, 0.56, 0.45]}}


def _synthetic(h, w, seed=0):
    """Normals, mask, heights and an albedo with 16 × 16 patches of ±30 % (a texture)."""
    sc = sphere_on_plane(h, w)
    rng = np.random.default_rng(seed)
    patches = rng.uniform(0.7, 1.3, size=(16, 16, 1))
    tex = np.repeat(np.repeat(patches, -(-h // 16), 0), -(-w // 16), 1)[:h, :w]
    return sc, np.clip(tex * [0.65, 0.56, 0.45], 0, 1)


def _page(path, data):
    path.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>"
                    f"{viewer_section(data)}</body></html>", encoding="utf-8")


def reference_pixels(arr, light):
    """The page's Python reference (8-bit): the relighting model as shipped when the page draws
    it, else the fitted BRDF (pipeline._relight.relight)."""
    if arr.get("sv_model") is not None:
        shown = np.round(arr["sv_model"].display(light) * 255)
        return np.where(arr["mask"][..., None], shown, np.round(BACKGROUND * 255)).astype(np.uint8)
    return to_srgb8(relight(arr["normals"], arr["kd_map"], arr["mask"], arr["model"], light),
                    arr["mask"], arr["exposure"])


def pixel_differences(driver, arr, lights=LIGHTS):
    """{light: (mean, p99, max)} of |browser − reference| in 8-bit levels over the mask."""
    out = {}
    for az, el in lights:
        got = viewer_pixels(driver, az, el)
        t0 = time.perf_counter()
        want = reference_pixels(arr, light_from_angles(az, el))
        t_ref = time.perf_counter() - t0
        d = np.abs(got.astype(int) - want.astype(int))[arr["mask"]]
        out[(az, el)] = (float(d.mean()), float(np.percentile(d, 99)), int(d.max()), t_ref)
    return out


def _print_diffs(diffs):
    for (az, el), (mean, p99, mx, t_ref) in diffs.items():
        print(f"  light az {az:5.0f}° el {el:4.0f}°: |browser − reference| mean {mean:.2f}, "
              f"99th pct {p99:.0f}, max {mx} levels (reference render {t_ref:.2f} s)")


def bench_large(out, h, w, frames):
    sc, albedo = _synthetic(h, w)
    t0 = time.perf_counter()
    data, arr = viewer_data(sc.normals, sc.mask, GLOSSY_LI, albedo=albedo, height=sc.height, pitch_mm=0.05)
    t_pack = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "viewer.html"
        _page(page, data)
        size_mb = page.stat().st_size / 1e6
        with chromium(1400, 1000) as driver:
            t0 = time.perf_counter()
            wait_for_viewer(driver, page, timeout=300)
            t_open = time.perf_counter() - t0
            start_ms = driver.execute_script("return window.facetteViewer.startMs")
            timing = "window.facetteViewer.frameTimes(arguments[0], arguments[1]).then(arguments[arguments.length - 1])"
            ft = driver.execute_async_script(timing, frames, False)
            ft_preview = driver.execute_async_script(timing, frames, True)
            diffs = pixel_differences(driver, arr)
            errors = console_errors(driver)
    draw = np.array(ft["draw_ms"][3:])          # the first frames include shader warm-up
    raf = np.diff(ft["raf_ms"][3:])
    print(f"1. {w} × {h} px (sphere on a textured plane, LI σ = 0.044, n_i = 1.14, approx volume)")
    print(f"  page {size_mb:.0f} MB, packed in {t_pack:.1f} s; opened in {t_open:.1f} s "
          f"(viewer start-up {start_ms / 1000:.1f} s: decode, upload, first frame)")
    print(f"  frame time (draw, gl.finish, 1-pixel read-back): median {np.median(draw):.0f} ms, "
          f"95th pct {np.percentile(draw, 95):.0f} ms over {len(draw)} frames; "
          f"requestAnimationFrame interval median {np.median(raf):.0f} ms")
    pv = np.array(ft_preview["draw_ms"][3:])
    print(f"  while dragging (preview {ft_preview['size'][0]} × {ft_preview['size'][1]}): median {np.median(pv):.0f} ms, "
          f"95th pct {np.percentile(pv, 95):.0f} ms")
    _print_diffs(diffs)
    print(f"  console errors: {len(errors)}")
    return diffs, draw


def bench_report(out, report=None):
    """Screenshots of a report (default: `process` on the test's small simulated scan)."""
    with tempfile.TemporaryDirectory() as tmp:
        arr = None
        if report is None:
            sc = sphere_on_plane(48, 64)
            write_scan(Path(tmp) / "scan", sc, render(sc, thesis_light_directions(), "satin", noise=0.002))
            res = process(Path(tmp) / "scan", outputs=["normals", "albedo", "height", "samples", "brdf", "relight",
                                                       "report"], out_dir=Path(tmp) / "out")
            report = Path(tmp) / "out" / "report.html"
            _, arr = viewer_data(res.normals, res.mask, res.brdf, albedo=res.albedo, height=res.height,
                                 pitch_mm=res.inputs.pixel_pitch_mm, material_mask=res.inputs.sample_mask(),
                                 relight_model=res.relight_model)
        with chromium(1400, 1000) as driver:
            wait_for_viewer(driver, report)
            height = driver.execute_script("return document.body.scrollHeight")
            driver.set_window_size(1400, min(height + 150, 16000))
            driver.save_screenshot(str(out / "report.png"))
            canvas = driver.find_element(By.ID, "facette-relight")
            driver.execute_script("arguments[0].scrollIntoView()", canvas)
            for name, (az, el) in (("viewer-light-a.png", LIGHTS[0]), ("viewer-light-b.png", LIGHTS[1]),
                                   ("viewer-raking.png", RAKING)):
                driver.execute_script("window.facetteViewer.setLight(arguments[0], arguments[1])", az, el)
                driver.find_element(By.ID, "viewer").screenshot(str(out / name))
            diffs = pixel_differences(driver, arr, LIGHTS + [RAKING]) if arr is not None else None
            errors = console_errors(driver)
    print(f"2. report {report if arr is None else '(process on a 64 × 48 simulated scan, satin material)'}")
    if diffs:
        _print_diffs(diffs)
    print(f"  console errors: {len(errors)}; screenshots: {out / 'report.png'}, {out / 'viewer-light-a.png'} "
          f"(az {LIGHTS[0][0]:.0f}°, el {LIGHTS[0][1]:.0f}°), {out / 'viewer-light-b.png'} "
          f"(az {LIGHTS[1][0]:.0f}°, el {LIGHTS[1][1]:.0f}°), {out / 'viewer-raking.png'} "
          f"(az {RAKING[0]:.0f}°, el {RAKING[1]:.0f}°: 75° from the axis)")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench viewer", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench-viewer"), help="where the screenshots go")
    ap.add_argument("--frames", type=int, default=30, help="frames timed at full size")
    ap.add_argument("--size", type=int, nargs=2, default=(1424, 2144), metavar=("H", "W"))
    ap.add_argument("--report", type=Path, help="screenshot this report.html instead of a simulated one")
    ap.add_argument("--skip-large", action="store_true", help="no full-size timing")
    ap.add_argument("--skip-report", action="store_true", help="no report screenshots")
    a = ap.parse_args(argv)
    if a.frames < 5:
        raise SystemExit("--frames: time at least 5 frames (the first 3 are warm-up)")
    a.out.mkdir(parents=True, exist_ok=True)
    if not a.skip_large:
        bench_large(a.out, *a.size, a.frames)
    if not a.skip_report:
        bench_report(a.out, a.report)
    return 0
