"""`facette bench lights`: the default method's cost per megapixel-light, on 12, 48 and 96 lights.

A relief slab (facette.bench._large.relief_surface: slopes up to 50°, every orientation) in a
glossy dielectric (Cook–Torrance: "satin", σ 0.15, or "glossy", σ 0.05; facette.recon.synthetic)
is rendered under the rig's 12 lights and under domes of 48 and 96 (a spiral over elevations
10–80°), 1 % noise, and solved by the robust Lambertian `rank_trimmed` and the BRDF-aware default
`li_alternating`. Per size, light count and method: wall and CPU seconds, both per megapixel-light
(the CPU figure counts every thread; on a busy machine the wall figure overstates the cost), the
normals' mean angular error against the truth, and li_alternating's parts (initial solve, coarse
pass, BRDF-aware step). The default sizes: 481x466 (a real dome capture's, below the coarse-to-fine
threshold: the whole alternation at full size) and 1024x768 (coarse-to-fine, as every large capture).

With --banded WxH[,WxH] the default runs instead over bands of a relief rendered band by band
(never held whole; a band's photographs within BAND_BYTES: 31 rows at 6000 px x 60 lights), its
model fitted across the same bands (`fit.li_model`): the model's and the bands' CPU seconds, both
per megapixel-light, the wall seconds (the rendering's included, twice: the model's pass and the
solve's), the process's peak memory so far, the error, and 24 MP x 60 lights estimated at these
rates (the model's cost is bounded by its sample and coarse pass; the bands' grows with pixels x
lights).

With --capture WxH the same relief, with the shadows it casts (its slopes up to 49 deg hide 4 % of the lit
samples from the dome's lights at 10-80 deg; --no-cast-shadows: without, as before December 2026, when the
cast-shadow step's 5 % hidden on it was read as false alarms), is written once as a DiLiGenT folder of 16-bit
PNGs (`_dome_capture`; kept with --keep and reused), then `facette process FOLDER --outputs normals,height` runs on it with no
flag in a process of its own: the product's CPU and wall seconds (reading, the budget's bands, the model,
the solve, the heights), its peak and its error, apart from the rendering (the bench's input).
The photographs are rendered by a kernel (`_render_jit`: recon.synthetic.render's images, ~4x cheaper).

With --shadow-rates WxH, the cast-shadow step's hit and false-hidden rates per margin on that relief, with
and without its cast shadows, and on bench concave's scenes (`_shadow_rates`).

Usage: facette bench lights [--sizes 481x466,1024x768] [--lights 12,48,96] [--material satin|glossy]
       facette bench lights --banded 4096x1024 --lights 60
       facette bench lights --capture 6000x4000 --lights 60 --keep DIR
       facette bench lights --shadow-rates 1500x1000 [--margins=-3,-1.5,0] [--concave-cache DIR]
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np

from facette.methods import photometric_stereo
from facette.recon.synthetic import Scene, render, thesis_light_directions

from ._large import relief_surface
from ._render_jit import render_lights

__all__ = ["main", "dome_lights", "relief_scene", "band_rows", "relief_heights", "render_band", "banded"]

METHODS = ("rank_trimmed", "li_alternating")
# the photographs of one band of --banded (float32): 128 MB, so a band and its solve's copies
# stay well under 1 GB whatever the width and light count (6000 px x 60 lights: 31 rows)
BAND_BYTES = 1 << 27


def dome_lights(m):
    """(m, 3) unit directions on a spiral over elevations 10–80° (12: the rig's own)."""
    if m == 12:
        return thesis_light_directions()
    i = np.arange(m) + 0.5
    elev = np.radians(10 + 70 * i / m)
    phi = i * np.pi * (3 - np.sqrt(5))
    return np.stack([np.cos(elev) * np.cos(phi), np.cos(elev) * np.sin(phi), np.sin(elev)], axis=1)


def relief_scene(h, w):
    """The relief slab at h x w px as a recon.synthetic Scene (the whole frame masked)."""
    _, normals = relief_surface(np.arange(h), np.arange(w), min(h, w))
    return Scene(normals, np.zeros((h, w)), np.ones((h, w), bool), np.zeros((h, w), bool),
                 ((h - 1) / 2, (w - 1) / 2), 1.0)


def _parts(info):
    """li_alternating's seconds: initial solve, coarse pass, BRDF-aware step (from its info)."""
    levels = info.get("levels", {})
    return (levels.get("init", {}).get("seconds", 0.0), info.get("coarse", {}).get("seconds", 0.0),
            levels.get("brdf_aware", {}).get("seconds", 0.0))


def run(h, w, m, material, methods=METHODS):
    """Rows (method, wall s, CPU s, mean error deg, info) of each method on one rendered case."""
    scene = relief_scene(h, w)
    lights = dome_lights(m)
    images = render(scene, lights, material, noise=0.01, rng=np.random.default_rng(1), cast_shadows=False)
    rows = []
    for name in methods:
        t, c = time.perf_counter(), time.process_time()
        res = photometric_stereo(images, lights, method=name, mask=scene.mask)
        dt, dc = time.perf_counter() - t, time.process_time() - c
        dot = np.clip(np.sum(res.normal[scene.mask] * scene.normals[scene.mask], -1), -1, 1)
        rows.append((name, dt, dc, float(np.degrees(np.arccos(dot)).mean()), res.info or {}))
    return rows


def band_rows(w, m, budget=BAND_BYTES):
    """Rows per band: the band's photographs (m x rows x w x 3 float32) within `budget` bytes."""
    return max(1, int(budget) // (m * w * 3 * 4))


def relief_heights(h, w, rows=256):
    """(h, w) float32: the relief's heights in pixel pitches (`relief_surface`), computed `rows` rows at a time."""
    out = np.empty((h, w), np.float32)
    for r0 in range(0, h, rows):
        out[r0:r0 + rows] = relief_surface(np.arange(r0, min(h, r0 + rows)), np.arange(w), min(h, w))[0]
    return out


def render_band(r0, r1, w, scale, lights, material, noise=0.01, hidden=None):
    """(images (m, r1 - r0, w, 3) float32, true normals) of rows r0:r1 of a w-wide relief whose
    smaller side is `scale`: rendered into the band by a kernel (`_render_jit`: render's images), the
    noise seeded by the row (the same values whichever band holds the row: the model's reads and
    the solve's bands need not share their edges). hidden: (m, r1 - r0, w) bool, the lights the relief
    hides from each pixel (`_render_jit.cast_hidden` of `relief_heights`: its cast shadows), which give
    it 0 (no inter-reflections are rendered either); None: no shadows cast (the relief hides 4 % of the
    lit samples from 60 dome lights)."""
    _, normals = relief_surface(np.arange(r0, r1), np.arange(w), scale)
    images = render_lights(normals, lights, material, np.empty((len(lights), r1 - r0, w, 3), np.float32))
    if hidden is not None:
        images[np.broadcast_to(hidden[..., None], images.shape)] = 0
    for row in range(r0, r1):
        z = np.random.default_rng(row).standard_normal((len(lights), w, 3), dtype=np.float32)
        images[:, row - r0] *= 1 + noise * z
    np.maximum(images, 0, out=images)
    return images, normals


def banded(w, h, m, material, rows=None, **options):
    """li_alternating over bands of `rows` rows (default: `band_rows`, the band's photographs
    within BAND_BYTES) of a w x h relief rendered band by band (never whole: sizes a machine
    cannot hold as one image), its model fitted across the bands (fit.li_model), which reads the
    same bands; options: li_alternating's. Returns (model CPU s, bands' CPU s, wall s, mean error
    deg, the bands' wall s in the initial solve and the BRDF-aware step); the rendering's CPU is
    in neither."""
    from facette.fit import li_model

    lights = dome_lights(m)
    rows = band_rows(w, m) if rows is None else int(rows)
    render_c = 0.0

    def read(r0, r1):
        nonlocal render_c
        c = time.process_time()
        images, _ = render_band(r0, r1, w, min(h, w), lights, material)
        render_c += time.process_time() - c
        return images, lights, np.ones((r1 - r0, w), bool)
    t, c = time.perf_counter(), time.process_time()
    model = li_model(read, (h, w), h * w, rows, **options)
    model_c = time.process_time() - c - render_c
    total, count, parts, bands_c = 0.0, 0, np.zeros(2), 0.0
    rows = rows if model is not None else h      # no model (below coarse_pixels): the image is one band
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        images, normals = render_band(r0, r1, w, min(h, w), lights, material)
        c = time.process_time()
        part = photometric_stereo(images, lights, method="li_alternating", model=model, row0=r0, **options)
        bands_c += time.process_time() - c
        del images
        parts += _parts(part.info)[::2]          # the initial solve's and the BRDF-aware step's wall s
        dot = np.clip(np.sum(part.normal * normals, -1), -1, 1)
        total, count = total + float(np.degrees(np.arccos(dot)).sum()), count + dot.size
    return model_c, bands_c, time.perf_counter() - t, total / count, parts


def _peak_gb():
    """This process's peak resident memory so far (GB; Linux's ru_maxrss is in kB)."""
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def _banded_main(sizes, lights, material):
    print(f"-- li_alternating over bands, its model fitted across them (rendered band by band, Cook-Torrance "
          f"{material}, 1 % noise); CPU s without the rendering, wall s with it; peak: the process's so far")
    print(f"{'size':>10s} {'lights':>6s} {'rows':>4s} {'model CPU s':>11s} {'bands CPU s':>11s} {'CPU s/MPl':>9s} "
          f"{'bands s/MPl':>11s} {'wall s':>7s} {'peak GB':>7s} {'error':>7s}   24 MP x 60 lights at these rates; "
          "the bands' wall s: init / BRDF")
    for size in sizes.split(","):
        w, h = (int(v) for v in size.lower().split("x"))
        for m in (int(v) for v in lights.split(",")):
            model_c, bands_c, wall, err, parts = banded(w, h, m, material)
            mpl = h * w * m / 1e6
            at = model_c + bands_c / mpl * 24 * 60        # the model's cost is bounded (SAMPLE_PIXELS, coarse_pixels)
            print(f"{size:>10s} {m:6d} {band_rows(w, m):4d} {model_c:11.1f} {bands_c:11.1f} "
                  f"{(model_c + bands_c) / mpl:9.3f} {bands_c / mpl:11.3f} {wall:7.1f} {_peak_gb():7.2f} "
                  f"{err:6.3f}°   {at:.0f} CPU s ({at / 2:.0f} s on 2 cores); {parts[0]:.1f} / {parts[1]:.1f}",
                  flush=True)


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--_write"]:                # the capture of --capture, in a process of its own
        from ._dome_capture import write_dome_capture
        write_dome_capture(argv[1], int(argv[2]), int(argv[3]), int(argv[4]), argv[5], cast_shadows=argv[6:] != ["0"])
        return 0
    p = argparse.ArgumentParser(prog="facette bench lights", description=__doc__.split("\n")[0])
    p.add_argument("--sizes", default="481x466,1024x768", help="WxH, comma-separated")
    p.add_argument("--lights", default="12,48,96", help="light counts, comma-separated (12: the rig's)")
    p.add_argument("--material", default="satin", choices=["satin", "glossy"])
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--banded", metavar="WxH", help="instead: li_alternating over bands of these sizes (comma-"
                                                   "separated), rendered band by band, and the 24 MP x 60 estimate")
    p.add_argument("--capture", metavar="WxH", help="instead: the capture (the --banded relief) written once as a "
                                                    "folder of PNGs, then `facette process` on it with no flag")
    p.add_argument("--keep", help="with --capture: the folder for the capture and results (reused; default: "
                                  "a temporary one)")
    p.add_argument("--outputs", default="normals,height", help="with --capture: process's --outputs")
    p.add_argument("--shadow-rates", metavar="WxH", help="instead: the cast-shadow step's hidden lights against the "
                                                         "geometry's on the relief at WxH (`_shadow_rates`)")
    p.add_argument("--margins", default="-3,-1.5,-0.75,0,1.5", help="with --shadow-rates: the horizon test's margins")
    p.add_argument("--concave-cache", help="with --shadow-rates: also bench concave's scenes under 96 lights, "
                                           "rendered into (or read from) this folder")
    p.add_argument("--concave-shapes", default="bowl,grooves,craters,cup", help="with --concave-cache: which")
    p.add_argument("--no-cast-shadows", action="store_true", help="with --capture: the relief rendered without the "
                                                                   "shadows it casts (a folder of its own)")
    args = p.parse_args(argv)
    if args.shadow_rates:
        from ._shadow_rates import shadow_rates_main
        w, h = (int(v) for v in args.shadow_rates.lower().split("x"))
        shadow_rates_main(w, h, [float(v) for v in args.margins.split(",")], args.concave_cache,
                          args.concave_shapes.split(","))
        return 0
    if args.capture:
        from ._dome_capture import measure_capture
        w, h = (int(v) for v in args.capture.lower().split("x"))
        with tempfile.TemporaryDirectory(prefix="facette-bench-lights-") as tmp:
            for m in (int(v) for v in args.lights.split(",")):
                measure_capture(w, h, m, args.material, args.keep or tmp, args.outputs, not args.no_cast_shadows)
        return 0
    if args.banded:
        run(32, 32, 12, args.material, ["li_alternating"])       # the kernels compiled first
        _banded_main(args.banded, args.lights, args.material)
        return 0
    methods = [s.strip() for s in args.methods.split(",") if s.strip()]
    # the kernels compiled (or loaded from numba's cache) before anything is timed
    run(32, 32, 12, args.material, methods)
    print(f"-- relief slab, Cook-Torrance {args.material}, 1 % noise: seconds per megapixel-light "
          "(wall and CPU), mean angular error")
    print(f"{'size':>10s} {'lights':>6s} {'method':16s} {'wall s':>7s} {'CPU s':>7s} {'wall s/MPl':>10s} "
          f"{'CPU s/MPl':>9s} {'error':>7s}   li_alternating: init / coarse / BRDF-aware s")
    for size in args.sizes.split(","):
        w, h = (int(v) for v in size.lower().split("x"))
        for m in (int(v) for v in args.lights.split(",")):
            for name, dt, dc, err, info in run(h, w, m, args.material, methods):
                mpl = h * w * m / 1e6
                extra = " / ".join(f"{v:.2f}" for v in _parts(info)) if name == "li_alternating" else ""
                print(f"{size:>10s} {m:6d} {name:16s} {dt:7.2f} {dc:7.2f} {dt / mpl:10.3f} {dc / mpl:9.3f} "
                      f"{err:6.3f}°   {extra}", flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"(1-minute load average {load:.1f} on {os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
