"""`facette bench uncertainty`: does each normal's uncertainty (normal.exr's uncertainty_deg) rank
the true errors, and does its 90 % band hold 90 % of the normals?

Per case: Spearman's rank correlation between the uncertainty and the angular error against the
truth, the share of pixels whose error is within the band (coverage; the aim: 0.9), the
medians of both, and the seconds the uncertainty took. Three sources:
- synthetic renders (facette.recon.synthetic: a sphere on a plane, cast shadows, matte, satin
  and glossy Cook-Torrance, noise 0.5 % and 2 %, the rig's 12 lights and 40 lights over the
  upper hemisphere): made here in seconds;
- Mitsuba 3 renders (path-traced: inter-reflections, a relief, a vase), unless --no-mitsuba;
- DiLiGenT with truth (`facette bench diligent`'s folders, through `facette process`), unless --no-real.
The renders choose BAND_SCALE: the line "pooled over the renders" prints the scale that would
put 90 % of their normals inside the band (`--calibrate`: from the raw u, whatever BAND_SCALE
is now); DiLiGenT only confirms it.
"""
import argparse
import time

import numpy as np
from scipy.stats import spearmanr

from facette.bench.diligent import angular_errors, default_root, find_objects, object_name
from facette.methods import photometric_stereo
from facette.recon import normal_uncertainty
from facette.recon import _uncertainty as unc
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

MITSUBA_SCENES = (("sphere", "paint_0.10"), ("relief", "plaster"), ("relief", "paint_0.05"), ("vase", "satin"))


def hemisphere_lights(n=40, min_z=0.4, seed=3):
    """n unit directions spread at random over the upper hemisphere above elevation asin(min_z)."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(20 * n, 3))
    v[:, 2] = np.abs(v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v[v[:, 2] > min_z][:n]


def synthetic_cases(size=64):
    """(name, images, light_dirs, truth normals, mask) of the synthetic renders."""
    for lights, lname in ((thesis_light_directions(), "12 rig lights"), (hemisphere_lights(), "40 lights")):
        for mat in ("matte", "satin", "glossy"):
            for noise in (0.005, 0.02):
                sc = sphere_on_plane(size, size)
                im = render(sc, lights, mat, noise=noise, rng=np.random.default_rng(2)).astype(np.float32)
                yield f"sphere/{mat} {lname} noise {noise:.1%}", im, lights, sc.normals, sc.mask


def mitsuba_cases(cache, size, spp):
    from facette.bench._mitsuba_scenes import render_scene
    from scipy.ndimage import binary_erosion
    for shape, mat in MITSUBA_SCENES:
        d = render_scene(shape, mat, size=size, spp=spp, cache_dir=cache)
        yield (f"mitsuba {shape}/{mat} 12 rig lights", d["images"], d["light_dirs"], d["normals"],
               binary_erosion(d["mask"], iterations=1))


def score(u, err):
    """(spearman, coverage, median u, median error) of uncertainties u and errors err (deg)."""
    rho = float(spearmanr(u, err).statistic) if len(u) > 2 else float("nan")
    return rho, float(np.mean(err <= u)), float(np.median(u)), float(np.median(err))


def _line(name, s, dt):
    rho, cov, mu, me = s
    return f"{name:46s} | {rho:8.2f} | {cov:8.2f} | {mu:7.2f} | {me:7.2f} | {dt:6.2f}s"


HEAD = f"{'case':46s} | {'spearman':>8s} | {'coverage':>8s} | {'u med':>7s} | {'err med':>7s} | time"


def render_table(cases, method):
    """Rows for rendered cases; returns the pooled (u / BAND_SCALE, error) for calibration."""
    pooled_u, pooled_e = [], []
    for name, im, lights, truth, mask in cases:
        r = photometric_stereo(im, lights, method=method, options={"mask": mask})
        t = time.perf_counter()
        u = normal_uncertainty(im, lights, r.normal, mask & r.valid)
        dt = time.perf_counter() - t
        sel = mask & r.valid
        err = angular_errors(r.normal, truth, sel)
        uu = u[sel & (np.linalg.norm(truth, axis=-1) > 0.5)]
        print(_line(name, score(uu, err), dt), flush=True)
        pooled_u.append(uu / unc.BAND_SCALE)
        pooled_e.append(err)
    return np.concatenate(pooled_u), np.concatenate(pooled_e)


def diligent_table(root, method):
    from facette.pipeline import process
    rows = []
    for folder, truth_path in find_objects(root):
        if truth_path is None:
            continue
        res = process(folder, outputs=["normals"], method=method)
        truth = np.load(truth_path)
        good = res.mask & (np.linalg.norm(truth, axis=-1) > 0.5)
        err = angular_errors(res.normals, truth, good)
        s = score(res.uncertainty[good], err)
        rows.append(s)
        name = f"{folder.parent.name}/{object_name(folder)}"
        print(_line(name, s, res.timings.get("uncertainty", float("nan"))) + f"  (mean error {err.mean():.2f})",
              flush=True)
    if rows:
        print(f"{'mean over the DiLiGenT objects':46s} | {np.mean([r[0] for r in rows]):8.2f} | "
              f"{np.mean([r[1] for r in rows]):8.2f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench uncertainty", description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="li_alternating", help="the photometric-stereo method (default: process's)")
    ap.add_argument("--root", default=None, help="folder searched for DiLiGenT-style folders (default ../shared/data)")
    ap.add_argument("--no-real", action="store_true", help="skip DiLiGenT")
    ap.add_argument("--no-mitsuba", action="store_true", help="skip the Mitsuba renders (about 2 min to render once)")
    ap.add_argument("--cache", default="out/mitsuba-cache", help="folder for the cached renders")
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--spp", type=int, default=64)
    args = ap.parse_args(argv)
    print(f"uncertainty of {args.method}'s normals: the 90 % band = {unc.BAND_SCALE} x u (recon._uncertainty)")
    print(HEAD)
    u, e = render_table(synthetic_cases(), args.method)
    if not args.no_mitsuba:
        mu, me = render_table(mitsuba_cases(args.cache, args.size, args.spp), args.method)
        u, e = np.concatenate([u, mu]), np.concatenate([e, me])
    scale = float(np.percentile(e / np.maximum(u, 1e-9), 90))
    print(f"pooled over the renders: spearman {spearmanr(u, e).statistic:.2f}, coverage "
          f"{np.mean(e <= unc.BAND_SCALE * u):.2f}; the scale that holds 90 %: {scale:.2f} "
          f"(BAND_SCALE {unc.BAND_SCALE})")
    if not args.no_real:
        diligent_table(args.root or default_root(), args.method)
    return 0
