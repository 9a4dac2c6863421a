"""`facette bench channels`: which colour channels the normal solve should use, on renders.

Mitsuba renders (facette.bench._mitsuba_scenes, cached under --cache; textured and coloured albedos,
the two-material relief) with the camera's noise added: the scene scaled so that the green channel's
99th percentile on the object collects --peak-e electrons, then shot noise (Poisson, as a Gaussian of
the same variance) and the sensor's read noise (facette.camera.sensor.DEFAULT_SENSOR, 4 e-) per
photosite, green the mean of two photosites of the RGGB cell (half size, as the rig's binning).
Each method then solves as `process` hands it the images (pipeline._channels): "green" (the
methods' own channel), "mean" and "weighted" (the reduced channel appended to R, G, B, the weights
mean/variance with the variance estimated from the images, as process does). Printed: the mean
angular error per scene (eroded mask, as `bench mitsuba`), the mean over the scenes and the time.
Never run on DiLiGenT: the choice is made here; `bench diligent --channels` confirms it.
"""
import argparse
import time

import numpy as np
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.bench.mitsuba import angular_errors, two_materials
from facette.camera.sensor import DEFAULT_SENSOR
from facette.methods import photometric_stereo
from facette.pipeline._channels import CHANNELS, SOLVE_CHANNEL, channel_weights, with_solve_channel

SCENES = [("relief", "satin", True), ("sphere", "paint_0.10", True), ("vase", "paint_0.08", True),
          ("shell", "lacquer", True), ("sphere", "metallic_paint", True), ("relief", "rough_plastic", True),
          ("relief", "plaster", False), ("relief", "paint_0.05", False), ("two", "materials", False)]
PHOTOSITES = np.array([1.0, 2.0, 1.0])       # R, G (two, averaged), B per binned RGGB cell


def with_sensor_noise(images, mask, peak_e, rng):
    """(m, H, W, 3) float32 `images` with shot and read noise, the green 99th percentile on `mask` at
    `peak_e` electrons (see the module doc)."""
    g = images[..., 1][:, mask]
    k = peak_e / np.percentile(g[np.isfinite(g)], 99)
    e = np.clip(images * k, 0, None)
    r = DEFAULT_SENSOR.read_noise_e
    sd = np.sqrt((e + r * r) / PHOTOSITES)
    return ((e + rng.normal(size=e.shape) * sd) / k).astype(np.float32)


def solve(images, light_dirs, mask, method, channels, params):
    """(PSResult, weights, seconds) as `process` solves: the reduction inside the seconds."""
    options = {"mask": mask, **({"materials": "auto"} if params.get("two_materials") else {})}
    t = time.perf_counter()
    w, _ = channel_weights(images, mask, channels)
    if w is not None:
        images, options["channel"] = with_solve_channel(images, w), SOLVE_CHANNEL
    r = photometric_stereo(images, light_dirs, method=method, options=options)
    return r, w, time.perf_counter() - t


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench channels", description=__doc__.splitlines()[0])
    p.add_argument("--methods", default="woodham1980,rank_trimmed,li_alternating")
    p.add_argument("--peak-e", default="3000,20000", help="electrons at green's 99th percentile, comma-separated "
                   "(0: the renders as they are, Monte Carlo noise only)")
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--scenes", type=int, default=len(SCENES), help="the first N scenes only")
    p.add_argument("--cache", default="out/mitsuba-cache")
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--spp", type=int, default=256)
    args = p.parse_args(argv)
    methods = args.methods.split(",")
    table = {}
    for peak in [float(x) for x in args.peak_e.split(",")]:
        print(f"-- noise: green's 99th percentile at {peak:g} e-" if peak else "-- no noise added")
        for shape, mat, tex in SCENES[:args.scenes]:
            d = two_materials(args) if shape == "two" else render_scene(
                shape, mat, size=args.size, spp=args.spp, textured=tex, cache_dir=args.cache)
            ev = binary_erosion(d["mask"], iterations=1)
            for seed in range(args.seeds):
                im = d["images"].astype(np.float32) if not peak else \
                    with_sensor_noise(d["images"], d["mask"], peak, np.random.default_rng(seed))
                for method in methods:
                    line = []
                    for ch in CHANNELS:
                        r, w, dt = solve(im, d["light_dirs"], d["mask"], method, ch, d["params"])
                        err = float(angular_errors(r.normal, d["normals"], ev & r.valid).mean())
                        table.setdefault((peak, method, ch), []).append((err, dt))
                        line.append(f"{ch} {err:6.3f} deg {dt:5.2f} s" + (f" w={[round(float(x), 2) for x in w]}"
                                                                        if ch == "weighted" else ""))
                    print(f"  {shape}/{mat}{' textured' if tex else ''} s{seed} {method:15s} " + " | ".join(line),
                          flush=True)
        print(f"   mean over {args.scenes} scenes x {args.seeds} seeds (error, total time):")
        for method in methods:
            print(f"   {method:15s} " + " | ".join(
                f"{ch} {np.mean([e for e, _ in table[(peak, method, ch)]]):6.3f} deg "
                f"{np.sum([t for _, t in table[(peak, method, ch)]]):6.1f} s" for ch in CHANNELS), flush=True)
    return 0
