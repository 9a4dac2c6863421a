"""`facette bench concave`: cast shadows and inter-reflections on path-traced concave scenes.

Mitsuba 3 (`path` integrator, max_depth 4: every wall lights the others, and a wall hides the
lights behind it) renders four concave height fields of our own (bench._mitsuba_scenes.CONCAVE_SHAPES:
a bowl, three grooves, a crater field, a flat-bottomed cup) in matte plaster, a glossy paint and a
dark glossy paint (MATERIALS),
under 96 lights (a DiLiGenT-like grid of 8 x 12, up to 45 deg from the axis) and under the rig's
12 (15 and 30 deg from the axis). Each scene goes through `facette process` as a user's folder
(16-bit PNGs, DiLiGenT-style, relative intensities: no Spectralon): least squares; the default as
it was before the shadow step ("before": no inter-reflection removal, no shadows); the default
(shadows "auto", inter-reflections "auto": removed where the images identify the albedo's scale); the
default with the inter-reflections left in (as "auto" was before it removed them on relative images); the
default without the shadow step; the default with `--interreflections` (the albedo's scale estimated from the
images, facette.recon._interreflect_scale), without and with the shadows. Printed per scene: mean, median
and 95th percentile of the angular error, the ratio to least squares' mean, process's seconds.
Renders are cached (--cache, default /tmp/facette-concave); the first run renders them
(about 1 CPU s per image at 128 px, 32 spp).
"""
import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import CONCAVE_SHAPES, render_scene, rig_light_directions

__all__ = ["grid_light_directions", "main"]

SIZE, SPP = 128, 32
# "@dark": the material with a dark K_d (a dark glossy object, as DiLiGenT's reading: little light
# gathered, a highlight that is most of what the camera sees)
MATERIALS = ("plaster", "paint_0.10", "paint_0.05@dark")
KD = {"": (0.6, 0.5, 0.4), "dark": (0.06, 0.05, 0.04)}
PNG_TOP = 60000.0


def grid_light_directions(rows=8, cols=12, max_deg=45.0):
    """rows x cols directions from a planar grid of lights in front of the object (as DiLiGenT's
    96), the grid's corners `max_deg` from the axis."""
    t = np.tan(np.radians(max_deg)) / np.hypot(1.0, rows / cols)
    x, y = np.meshgrid(np.linspace(-t, t, cols), np.linspace(-t * rows / cols, t * rows / cols, rows))
    d = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


LIGHT_SETS = {"96": grid_light_directions, "rig12": rig_light_directions}


def scene(shape, material, lights, cache, size=SIZE, spp=SPP):
    """The render (cached) of `shape` in `material` ("name" or "name@dark", KD) under a light set."""
    name, _, kd = material.partition("@")
    return render_scene(shape, name, size=size, spp=spp, lights=LIGHT_SETS[lights](), max_depth=4,
                        cache_dir=cache, kd=KD[kd])


def _folder(d, workdir, name, bits=16):
    """The render as a user's DiLiGenT-style folder (16-bit PNGs, the light intensities relative);
    bits=8: its values cut to 256 levels first (as DiLiGenT's shipped crops: a dark value of 3 / 255
    carries a quantisation error of ~10 %), written as 16-bit levels × 257."""
    from facette.io.diligent import write_diligent
    im = d["images"]
    step = 1 if bits == 16 else 257
    k = PNG_TOP / step / float(np.nanmax(im))
    folder = Path(workdir) / name
    if not folder.is_dir():
        levels = np.clip(np.round(im * k), 0, 65535 // step) * step
        write_diligent(folder, levels.astype(np.uint16), d["light_dirs"], np.full((len(im), 3), k * step / 65535.0),
                       d["mask"])
    return folder


def run(folder, **options):
    """(normals, seconds, ProcessResult) of `facette process` on the folder, normals only."""
    from facette.pipeline import process
    t = time.perf_counter()
    res = process(folder, outputs=["normals"], **options)
    return res.normals, (time.perf_counter() - t, res.timings["cpu"]), res


VARIANTS = {   # label: process options
    "least squares": {"method": "woodham1980", "shadows": "off", "interreflections": False},
    "before (no ir or shadows)": {"shadows": "off", "interreflections": False},
    "default": {},
    "default (ir left in)": {"interreflections": False},
    "default, no shadows": {"shadows": "off"},
    "default +ir (no shadows)": {"interreflections": True, "shadows": "off"},
    "default +ir": {"interreflections": True},
}


ESTIMATE_FIGURES = ("gather_correlation", "diffuse_correlation", "growth_kept")     # printed per row


def errors(n, d):
    sel = binary_erosion(d["mask"], iterations=1)
    return np.degrees(np.arccos(np.clip(np.sum(n * d["normals"], -1), -1, 1)))[sel]


def _row(label, d, folder, variants, ratios, key):
    """`process` on one scene's folder under each variant: a printed row per variant; the ratio to least
    squares (or to the first variant when there is no least squares) appended to ratios[(key, variant)]."""
    ref = None
    for v in variants:
        n, dt, res = run(folder, **VARIANTS[v])
        e = errors(n, d)
        ref = e.mean() if ref is None or v == "least squares" else ref
        ratio = e.mean() / ref if ref else np.nan
        ratios.setdefault((key, v), []).append(ratio)
        shadows = res.quality.get("shadows")
        extra = "" if shadows is None else \
            f"  hidden {shadows.get('decided_on')} (binned {shadows.get('bin')}) -> {shadows['hidden_share']}"
        ir = res.interreflections
        if ir is not None:
            est = ir.get("identified_on") or ir.get("scale_estimate") or {}
            extra += (f"  ir scale {ir.get('reflectance_scale', np.nan):.2f} "
                      + ("removed" if ir["applied"] else "left in")
                      + "".join(f" {k} {est[k]:.2f}" for k in ESTIMATE_FIGURES if est.get(k) is not None)
                      + f" ({ir.get('cpu_seconds', np.nan):.2f} cpu s)"
                      + (" model reused" if ir.get("model_reused") else ""))
        print(f"{label:34s} {v:22s} {e.mean():6.2f} {np.median(e):7.2f} {np.percentile(e, 95):6.2f} "
              f"{ratio:6.2f} {dt[0]:6.2f} {dt[1]:6.2f}{extra}", flush=True)


def _scenes(args):
    """(label, lights, scene) of the concave renders, or with --controls of the convex controls."""
    for lights in args.lights.split(","):
        if args.controls:
            from facette.bench._convex_controls import local_controls, mitsuba_controls
            dirs = LIGHT_SETS[lights]()
            for name, d in (local_controls(dirs) | mitsuba_controls(dirs, args.cache)).items():
                yield f"{name}/{lights}", lights, d
            continue
        for material in args.materials.split(","):
            for shape in args.shapes.split(","):
                yield f"{shape}/{material}/{lights}", lights, scene(shape, material, lights, args.cache)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench concave", description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default="/tmp/facette-concave", help="folder for the cached renders")
    ap.add_argument("--lights", default="rig12,96", help="light sets: rig12, 96 (comma-separated)")
    ap.add_argument("--shapes", default=",".join(CONCAVE_SHAPES))
    ap.add_argument("--materials", default=",".join(MATERIALS))
    ap.add_argument("--variants", default="least squares,before (no ir or shadows),default",
                    help=f"comma-separated labels of: {', '.join(VARIANTS)}")
    ap.add_argument("--controls", action="store_true",
                    help="the convex controls instead (bench._convex_controls: textured, no inter-reflections; "
                         "'auto' must leave them as they are)")
    ap.add_argument("--model-reuse", choices=("on", "off"), default="on",
                    help="off: li_alternating's solves after the inter-reflection decision make their own model "
                         "choice again (pipeline._interreflections.REUSE_DECISION_MODEL), to compare")
    ap.add_argument("--bits", type=int, choices=(8, 16), default=16,
                    help="8: the renders cut to 8-bit levels before process reads them (as DiLiGenT's crops)")
    args = ap.parse_args(argv)
    from facette.pipeline import _interreflections
    _interreflections.REUSE_DECISION_MODEL = args.model_reuse == "on"
    variants = [v.strip() for v in args.variants.split(",")]
    print(f"Mitsuba 3 path-traced concave scenes, {SIZE}x{SIZE} px, {SPP} spp, max_depth 4, through "
          f"`facette process` on {args.bits}-bit DiLiGenT-style folders (cached in {args.cache}); error on the frame "
          "eroded by 1 px; ratio = mean / least squares' mean (or the first variant's); s: process's wall "
          "seconds, cpu s its CPU seconds")
    print(f"{'scene':34s} {'variant':22s} {'mean°':>6s} {'median°':>7s} {'p95°':>6s} {'ratio':>6s} {'s':>6s} {'cpu s':>6s}")
    ratios = {}
    with tempfile.TemporaryDirectory() as work:
        for label, lights, d in _scenes(args):
            _row(label, d, _folder(d, work, label.replace("/", "_").replace(" ", "_"), args.bits), variants, ratios,
                 lights)
    print("\nMean ratio over the scenes:")
    for (lights, v), r in ratios.items():
        print(f"  {lights:6s} {v:22s} {np.nanmean(r):.2f} (scenes: {', '.join(f'{x:.2f}' for x in r)})")
    _few_against_many(ratios)
    return 0


def _few_against_many(ratios):
    """The issue's test: each variant's mean ratio to least squares under the rig's 12 lights against
    under 96 (printed when both ran on the same scenes): 12 lights as good as 96 when ≤ 1."""
    for v in dict.fromkeys(v for _, v in ratios):
        few, many = ratios.get(("rig12", v)), ratios.get(("96", v))
        if v == "least squares" or not few or not many or len(few) != len(many):
            continue
        print(f"  rig12 / 96 {v:22s} {np.nanmean(few) / np.nanmean(many):.2f} "
              f"({np.nanmean(few):.3f} against {np.nanmean(many):.3f})")


if __name__ == "__main__":
    raise SystemExit(main())
