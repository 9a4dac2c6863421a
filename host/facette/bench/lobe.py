"""`facette bench lobe`: li_alternating's lobe-or-not choice on renders, its gain against the error.

For each Mitsuba scene (facette.bench._mitsuba_scenes, cached under --cache), li_alternating solves
as `process` hands it the images (the mean of R, G, B appended, pipeline._channels) twice: with the
lobe taken whatever its gain (facette.fit._li_model.LOBE_MIN_GAIN 0) and with Lambert's model
forced (the bar out of reach). Printed per scene and seed: the lobe's gain (the profile's trimmed
robust cost against Lambert's, `choose_material_model`), the mean angular error of each (eroded
mask, as `bench mitsuba`), which the default bar picks, and the time. Under the rig's 12 lights
and under a dome of 96 (a Fibonacci set up to 55° from the axis; there the profile is a sample of
the fit pixels, and the seeds show how much the draw moves the choice). The bar is chosen here,
never on DiLiGenT: the gains of matte scenes against those of any gloss, weak gloss included
(roughplastic with specular_reflectance < 1, which no LI (σ, n_i) renders exactly).
--peak-e adds the camera's noise first (`bench channels`).
"""
import argparse
import time

import numpy as np
from scipy.ndimage import binary_erosion

import facette.fit._li_model as li_model
from facette.bench._mitsuba_scenes import render_scene
from facette.bench.channels import with_sensor_noise
from facette.methods import photometric_stereo
from facette.pipeline._channels import SOLVE_CHANNEL, with_solve_channel

SCENES = [("sphere", "plaster", False), ("relief", "plaster", False), ("vase", "plaster", False),
          ("shell", "plaster", False), ("sphere", "glaze_0.05", False), ("sphere", "glaze_0.10", False),
          ("sphere", "glaze_0.20", False), ("relief", "glaze_0.10", True), ("vase", "glaze_0.10", True),
          ("relief", "glaze_0.20", False), ("sphere", "paint_0.10", False), ("relief", "paint_0.05", False),
          ("sphere", "satin", False), ("sphere", "rough_plastic", False)]
DOME_SCENES = [("sphere", "plaster", False), ("vase", "plaster", False), ("relief", "plaster", False),
               ("sphere", "glaze_0.05", False), ("sphere", "glaze_0.10", False), ("relief", "glaze_0.20", True),
               ("sphere", "paint_0.10", False)]


def dome(n=96, theta_max_deg=55.0):
    """(n, 3) light directions spread evenly (a Fibonacci set) over the cap up to theta_max."""
    k = np.arange(n) + 0.5
    cz = 1 - k / n * (1 - np.cos(np.radians(theta_max_deg)))
    phi = np.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - cz ** 2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), cz], -1)


def solve(d, bar, seed):
    """(mean error deg, gain, model chosen, seconds) of li_alternating with LOBE_MIN_GAIN = bar."""
    keep = li_model.LOBE_MIN_GAIN
    li_model.LOBE_MIN_GAIN = bar
    try:
        im = with_solve_channel(d["images"], np.full(3, 1 / 3, np.float32))
        t = time.perf_counter()
        r = photometric_stereo(im, d["light_dirs"], method="li_alternating",
                               options={"mask": d["mask"], "channel": SOLVE_CHANNEL, "seed": seed})
        dt = time.perf_counter() - t
    finally:
        li_model.LOBE_MIN_GAIN = keep
    sel = binary_erosion(d["mask"], iterations=1)
    e = np.degrees(np.arccos(np.clip(np.sum(r.normal * d["normals"], -1), -1, 1)))[sel]
    choice = r.info["materials"][0].get("model_choice", {})
    return float(e.mean()), float(choice.get("gain", np.nan)), choice.get("model"), dt


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench lobe", description=__doc__.splitlines()[0])
    p.add_argument("--cache", default="out/mitsuba-cache", help="folder for the cached renders")
    p.add_argument("--lights", default="12,96", help="12 (the rig's) and/or 96 (a dome), comma-separated")
    p.add_argument("--seeds", type=int, default=3, help="seeds of the fit and profile pixels' draw (96 lights)")
    p.add_argument("--peak-e", type=float, default=0.0, help="electrons at green's 99th percentile (0: no noise)")
    args = p.parse_args(argv)
    bar = li_model.LOBE_MIN_GAIN
    print(f"li_alternating, lobe taken whatever its gain / Lambert forced; the default bar: gain >= {bar:g}")
    print(f"{'scene':28s} {'lights':>6s} {'seed':>4s} {'gain':>7s} {'lobe°':>6s} {'Lambert°':>8s} "
          f"{'default°':>8s} {'s':>6s}")
    rows = []
    for lights in [x.strip() for x in args.lights.split(",") if x.strip()]:
        dirs, scenes, seeds = (None, SCENES, [0]) if lights == "12" else (dome(int(lights)), DOME_SCENES,
                                                                          range(args.seeds))
        for shape, material, textured in scenes:
            d = dict(render_scene(shape, material, size=128, spp=256, textured=textured, lights=dirs,
                                  cache_dir=args.cache))
            if args.peak_e:
                d["images"] = with_sensor_noise(d["images"], d["mask"], args.peak_e, np.random.default_rng(0))
            label = f"{shape}/{material}{' textured' if textured else ''}"
            for seed in seeds:
                lobe, lam = solve(d, 0.0, seed), solve(d, np.inf, seed)
                chosen = lobe[0] if lobe[1] >= bar else lam[0]
                rows.append((lobe[1], lobe[0], lam[0]))
                print(f"{label:28s} {lights:>6s} {seed:4d} {lobe[1]:7.3f} {lobe[0]:6.2f} {lam[0]:8.2f} "
                      f"{chosen:8.2f} {lobe[3]:6.1f}", flush=True)
    gains = np.array([r[0] for r in rows])
    for b in sorted({0.02, 0.05, bar, 0.2, 0.5}):
        err = np.mean([r[1] if r[0] >= b else r[2] for r in rows])
        print(f"bar {b:4.2f}: mean error over the rows {err:.3f}° ({int(np.sum(gains >= b))} of {len(rows)} with the lobe)")
    return 0
