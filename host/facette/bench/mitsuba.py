"""`facette bench mitsuba`: photometric stereo and the BRDF fit on scenes from an independent renderer.

Scenes are rendered once by Mitsuba 3 (facette.bench._mitsuba_scenes; `roughplastic` with
Beckmann α = σ, int_ior = n_i, diffuse_reflectance = K_d) and cached under --cache
(default out/mitsuba-cache; never committed). For each scene and method: mean and median
angular error of the normals (against Mitsuba's shading normals, on the object mask eroded by
one pixel: the silhouette's pixels mix object and background), and the time. Each method solves
as `process` does (its channels, pipeline._channels); rows "+ir" run its inter-reflection step
first (a first rank_trimmed pass gives the shape; for li_alternating also the glossy walls, with
its lobe), as its default "auto" does on a calibrated scan: the renders are radiance factors, so
"li_alternating +ir" is `process`'s default here, marked "(default)". Then:

1. the thesis's test (§4.3.2): one shape in plaster and in the three fitted paints; each paint's
   normals against the plaster's (mean angle), per method, beside the plaster against itself
   rendered with other noise (the test's floor), at the bench's spp and at --thesis-spp;
2. the whole pipeline (`facette process` from a DiLiGenT-style folder of the renders: normals →
   reflectance samples → hemisphere filter → LI fit, no true normals anywhere): σ, n_i, K_d
   against the renderer's, per method;
3. heights: two domes on a dark table (rank_trimmed normals), each integration method against
   Mitsuba's positions, in pixels: one constant over both domes, and one per dome; the flat
   margin with the table found as `process` finds it (`facette.pipeline.margin_of`) and without.
"""
import argparse
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import MATERIALS, NON_LI_SCENES, TABLE_MATERIAL, render_scene
from facette.bench.e2e import height_errors
from facette.errors import NotAReflectance
from facette.methods import PROCESS_DEFAULT, PS_DEFAULT, PS_METHODS, photometric_stereo
from facette.pipeline import IR_AUTO, ProcessOptions, auto_masks, margin_of
from facette.pipeline._channels import images_for_solve, results_in_rgb
from facette.pipeline._filled import normals_of
from facette.pipeline._quality import carried, usable_from_levels
from facette.pipeline._interreflections import solve_without_interreflections
from facette.recon import INTEGRATION_METHODS, integrate

METHODS = ("woodham1980", "hierarchical_tautzia2016", "rank_trimmed", "rpca_wu2010", "li_alternating")
PIPELINE_METHODS = ("woodham1980", "hierarchical_tautzia2016", "rank_trimmed", "li_alternating")
SCENES = [  # (shape, material, textured, near_distance)
    ("sphere", "plaster", False, None), ("sphere", "paint_0.10", False, None),
    ("sphere", "paint_0.08", False, None), ("sphere", "paint_0.05", False, None),
    ("sphere", "satin", False, None), ("sphere", "paint_0.10", True, None),
    ("relief", "plaster", False, None), ("relief", "paint_0.10", False, None),
    ("relief", "paint_0.08", False, None), ("relief", "paint_0.05", False, None),
    ("relief", "satin", True, None), ("vase", "paint_0.08", True, None), ("vase", "plaster", False, None),
    ("sphere", "paint_0.10", False, 12.0),
    ("shell", "lacquer", True, None), ("shell", "plaster", False, None),   # the check scenes
] + [(shape, mat, tex, None) for shape, mat, tex in NON_LI_SCENES]      # metals, metallic paint, broad lobes
THESIS_SHAPE = "relief"
IR_METHODS = ("woodham1980", "rank_trimmed", "li_alternating")   # also run with inter-reflections removed
IR_SUFFIX = " +ir"
# what `process` runs by default on these renders: they are radiance factors, as a calibrated scan's
# images are, so its interreflections "auto" removes them (pipeline._interreflections)
DEFAULT_LABEL = PROCESS_DEFAULT + IR_SUFFIX
# Monte Carlo noise of the renders (two seeds of the relief in plaster): a relative standard
# deviation per value of 1.6 % at 64 spp, 0.8 % at 256, against 0.7 % for the rig's HDR images at
# midtones (42.7 dB); on its own it moves least-squares normals by 0.68 deg at 64 spp, 0.34 at 256
SPP = 256
# the thesis's test again with less noise: at 256 spp the plaster relief rendered twice (two seeds)
# gives normals 0.50° apart (li_alternating +ir), at 1024 spp 0.25° (its renders: ~5 min, cached)
THESIS_SPP = 1024
PNG_TOP = 60000.0   # the brightest value of a render written as 16-bit PNG (whole_pipeline)


def angular_errors(n, truth, mask):
    dot = np.clip(np.sum(n * truth, -1), -1, 1)
    return np.degrees(np.arccos(dot))[mask]


def _images_and_dirs(d):
    """Images and light directions as photometric stereo sees them (near lights: per pixel, with
    the 1/r² fall-off divided out, from the true surface points)."""
    im, L = d["images"], d["light_dirs"]
    near = d["params"].get("near_distance")
    if near is None:
        return im, L
    pos = d["positions"]
    lp = L * near
    v = lp[None, None] - pos[:, :, None, :]
    r2 = np.sum(v * v, -1)
    dirs = (v / np.sqrt(r2)[..., None]).astype(np.float32)
    fall = (near ** 2) / r2
    dirs[~d["mask"]] = L
    fall[~d["mask"]] = 1
    return im / np.transpose(fall, (2, 0, 1))[..., None], dirs


def run_ps(d, method, init=None, interreflections=False):
    """(PSResult, seconds) as `process` solves: on its default channels (images_for_solve), and with
    `interreflections` through its removal step as its default "auto" runs it on a calibrated scan
    (pipeline._interreflections; the renders are radiance factors): where the albedo is no
    reflectance (a metal's Lambertian albedo) it is left in; the pixels without MIN_LIGHTS samples
    above the noise (as process reads the 16-bit folder of `whole_pipeline`) are not solved but filled
    with the others no light reached (pipeline._filled). All inside the seconds."""
    im, L = _images_and_dirs(d)
    t = time.perf_counter()
    inp = SimpleNamespace(mask=d["mask"], images=im, light_dirs=L,
                          usable=usable_from_levels(im[..., 1] * (PNG_TOP / float(np.nanmax(im)))))
    # one bag for every method: each takes its own (li_alternating: materials, init)
    options = {"mask": carried(inp.mask, inp.usable), **({"init": init} if init else {}),
               **({"materials": "auto"} if d["params"].get("two_materials") else {})}
    o = ProcessOptions(interreflections=IR_AUTO if interreflections else False)   # a refusal leaves them in
    solve_in, used = images_for_solve(im, d["mask"], o, options, [])
    direct, r = solve_in, None
    if interreflections:
        said = SimpleNamespace(notes=[], timings={}, interreflections=None)
        direct, r = solve_without_interreflections(said, o, solve_in, L, d["mask"], PS_METHODS.canonical(method),
                                                   options)
    if r is None:
        r = photometric_stereo(direct, L, method=method, options=options)
    r = results_in_rgb(r, direct, solve_in, im, used)[0]
    said = SimpleNamespace(options={}, notes=[], timings={})
    normals_of(said, inp, r)
    r.normal = said.normals
    return r, time.perf_counter() - t


def _valid_note(r, d, sel, ls_normal):
    """Where a method leaves pixels without a normal (no light reaches them above the noise, as on
    a sharp metal), its error on the pixels that have one, beside least squares' there."""
    seen = sel & r.valid
    if seen.sum() == sel.sum() or not seen.any():
        return ""
    return (f"  valid {100 * seen.sum() / sel.sum():.0f} %: {angular_errors(r.normal, d['normals'], seen).mean():.2f}°"
            + ("" if ls_normal is None else
               f" (least squares {angular_errors(ls_normal, d['normals'], seen).mean():.2f}°)"))


def _verdict(fit):
    """The fitted model, its relative RMS and the verdict over every model tried, in one line."""
    if fit is None:
        return "no fit"
    return (f"{fit.model}, relative RMS {fit.error.get('relative_rms', np.nan):.3f}, {fit.verdict or 'no verdict'}: "
            + ", ".join(f"{t['model']} {t['relative_rms'] or np.nan:.3f}" for t in fit.models_tried))


def whole_pipeline(d, method, workdir, init=None, interreflections=False):
    """σ, n_i, K_d (mean over channels ratio) from `process` on a DiLiGenT-style folder."""
    from facette.io.diligent import write_diligent
    from facette.pipeline import process
    im = d["images"]
    k = PNG_TOP / float(np.nanmax(im))
    folder = Path(workdir) / f"{d['params']['shape']}_{d['params']['material']}"
    write_diligent(folder, np.clip(np.round(im * k), 0, 65535).astype(np.uint16), d["light_dirs"],
                   np.full((len(im), 3), k / 65535.0), d["mask"])
    t = time.perf_counter()
    options = ProcessOptions(method=method, interreflections=interreflections,
                             ps_options={"init": init} if init else None)
    res = process(folder, outputs=["normals", "albedo", "samples", "brdf"], options=options)
    return res, time.perf_counter() - t


def two_materials(args):
    """The relief, its left half in the glossy paint (reddish K_d), its right half in satin (bluish
    K_d): one (σ, n_i) per region is what photometric stereo has to find (materials="auto")."""
    a = render_scene("relief", "paint_0.05", size=args.size, spp=args.spp, kd=(0.7, 0.3, 0.2), cache_dir=args.cache)
    b = render_scene("relief", "satin", size=args.size, spp=args.spp, kd=(0.3, 0.5, 0.7), cache_dir=args.cache)
    half = args.size // 2
    d = dict(a)
    d["images"] = a["images"].copy()
    d["images"][:, :, half:] = b["images"][:, :, half:]
    d["kd"] = a["kd"].copy()
    d["kd"][:, half:] = b["kd"][:, half:]
    d["params"] = {**a["params"], "two_materials": True}
    return d


def table_heights(args, material="paint_0.10"):
    """Rows (label, global px, per-dome px, s) of each integration method on the rank_trimmed
    normals of two domes on a dark table, heights against Mitsuba's positions."""
    d = render_scene("table", material, size=args.size, spp=args.spp, cache_dir=args.cache)
    pitch = 2.0 / args.size                         # the orthographic view spans [-1, 1]
    z = d["positions"][..., 2].astype(np.float64)
    truth = {"height_mm": z, "mask": z > 0.01}      # the domes (the table is at 0)
    normals = photometric_stereo(d["images"], d["light_dirs"], method=PS_DEFAULT, mask=d["mask"]).normal
    table = margin_of(*auto_masks(d["images"]))
    runs = [(name, name, None) for name in INTEGRATION_METHODS]
    runs.append(("poisson_flat_margin", "poisson_flat_margin, table found", table))
    rows = []
    for method, label, background in runs:
        t = time.perf_counter()
        hgt = integrate(normals, pitch, None, method, background=background)
        dt = time.perf_counter() - t
        g, per = height_errors(truth, hgt, d["mask"])
        rows.append((label, g / pitch, per / pitch, dt))
    found = "none" if table is None else f"{table.sum()} px, {np.mean(table == ~truth['mask']):.3f} agree"
    return rows, f"table {found}"


def thesis_test(args, variants, normals):
    """The thesis's test (§4.3.2), printed: each paint's normals against the plaster's (mean angle),
    per method, beside the test's own floor, the plaster against itself rendered with other Monte
    Carlo noise (seed 1); at the bench's spp from `normals` {(material, label): (normal, sel)}, then
    at --thesis-spp (the renders' noise alone moves the 256-spp plaster by 0.50° against itself)."""
    paints = ("paint_0.10", "paint_0.08", "paint_0.05")
    print(f"\nThesis test (§4.3.2): the same relief in plaster and in three paints; mean angle between "
          f"each paint's normals and the plaster's (target ≤ 0.5°), and the plaster's against itself "
          f"rendered with other noise (the test's floor)")
    for spp in dict.fromkeys((args.spp, args.thesis_spp)):
        if not spp or (spp != args.spp and not normals):
            continue
        got = dict(normals) if spp == args.spp else {}
        scenes = [("plaster", 1)] + ([] if spp == args.spp else [("plaster", 0)] + [(m, 0) for m in paints])
        for mat, seed in scenes:
            d = render_scene(THESIS_SHAPE, mat, size=args.size, spp=spp, cache_dir=args.cache, seed=seed)
            sel = binary_erosion(d["mask"], iterations=1)
            for method, ir, name in variants:
                if spp == args.spp and ("plaster", name) not in normals:
                    continue
                if method in ("woodham1980", "li_alternating"):
                    key = (mat if seed == 0 else "plaster seed 1", name)
                    got[key] = (run_ps(d, method, args.init, ir)[0].normal, sel)
        print(f"  {spp} spp")
        for _, _, name in variants:
            if ("plaster", name) not in got:
                continue
            ref, sel = got[("plaster", name)]
            row = [f"{mat} {angular_errors(got[(mat, name)][0], ref, sel).mean():5.2f}°"
                   for mat in paints + ("plaster seed 1",) if (mat, name) in got]
            print(f"    {_marked(name):30s} " + "   ".join(row))


def _marked(name):
    """A row's method label, with "(default)" on what `process` runs by default on these renders."""
    return name + (" (default)" if name == DEFAULT_LABEL else "")


def _variants(methods, interreflections):
    """(method, remove inter-reflections first?, label) in the order printed."""
    out = []
    for m in methods:
        if interreflections in ("off", "both"):
            out.append((m, False, m))
        if interreflections in ("on", "both") and m in IR_METHODS:
            out.append((m, True, m + IR_SUFFIX))
    return out


def pipeline_rows(args, variants):
    """The whole pipeline's rows: `process` on a DiLiGenT-style folder of each render, per method."""
    print("\nWhole pipeline (process: normals → samples → hemisphere filter → LI fit; no true normals); "
          "its normals' mean error on the eroded mask, the pixels it filled included")
    print(f"{'scene':22s} {'method':30s} {'σ':>7s} {'(true)':>6s} {'n_i':>6s} {'(true)':>6s} "
          f"{'K_d/true':>18s} {'s':>6s}")
    with tempfile.TemporaryDirectory() as tmp:
        for shape, mat in (("sphere", "paint_0.10"), ("sphere", "paint_0.05"), ("sphere", "satin"),
                           ("relief", "paint_0.08"), ("sphere", "rough_plastic"), ("sphere", "metallic_paint"),
                           ("relief", "gold"), ("sphere", "gold"), ("sphere", "aluminium")):
            d = render_scene(shape, mat, size=args.size, spp=args.spp, cache_dir=args.cache)
            truth = {"sigma": np.nan, "n_i": np.nan, **MATERIALS[mat]}
            for method, ir, name in [v for v in variants if v[0] in PIPELINE_METHODS]:
                left_in = ""
                try:
                    res, dt = whole_pipeline(d, method, tmp, args.init, ir)
                except NotAReflectance:       # a metal's Lambertian albedo is above 1: "auto" leaves them in
                    res, dt = whole_pipeline(d, method, tmp, args.init, False)
                    left_in = "; inter-reflections left in: the albedo is no reflectance"
                p = res.brdf.params if res.brdf is not None and res.brdf.success else {}
                kd = np.array(p.get("kd", [np.nan] * 3)) / np.array(d["params"].get("kd", [np.nan] * 3))
                sel = binary_erosion(d["mask"])
                shape_err = (f"normals {angular_errors(res.normals, d['normals'], sel).mean():.2f}°"
                             + ("" if res.filled is None else f", {100 * res.filled[sel].mean():.0f} % filled"))
                print(f"{shape + '/' + mat:22s} {_marked(name):30s} {p.get('sigma', np.nan):7.4f} "
                      f"{truth['sigma']:6.3f} "
                      f"{p.get('n_i', np.nan):6.3f} {truth['n_i']:6.2f} {' '.join(f'{x:5.3f}' for x in kd):>18s} "
                      f"{dt:6.1f}  {shape_err}  ({_verdict(res.brdf)}{left_in})", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench mitsuba", description=__doc__.splitlines()[0])
    ap.add_argument("--cache", default="out/mitsuba-cache", help="folder for the cached renders")
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=SPP, help=f"samples per pixel (default {SPP}: see SPP)")
    ap.add_argument("--quick", action="store_true", help="three scenes only")
    ap.add_argument("--thesis-spp", type=int, default=THESIS_SPP,
                    help=f"also run the thesis's test at this many samples per pixel (default {THESIS_SPP}; 0: not)")
    ap.add_argument("--init", default=None, help="li_alternating's initial normals (default: its own, rank_trimmed)")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated (default: all five)")
    ap.add_argument("--interreflections", choices=("off", "on", "both"), default="both",
                    help=f"also run {', '.join(IR_METHODS)} on the images with the inter-reflections "
                         f"removed (rows '{IR_SUFFIX.strip()}'; default both)")
    args = ap.parse_args(argv)
    scenes = SCENES[1:2] + SCENES[4:5] + SCENES[0:1] if args.quick else SCENES
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    variants = _variants(methods, args.interreflections)
    print(f"Mitsuba 3 scenes, {args.size}x{args.size} px, {args.spp} spp, 12 lights of the rig "
          f"(cached in {args.cache}); error on the mask eroded by 1 px; '{IR_SUFFIX.strip()}': "
          "inter-reflections removed first (facette.recon.remove_interreflections); the renders are radiance "
          f"factors, as a calibrated scan's images: `process`'s default on them is {DEFAULT_LABEL}")
    print(f"{'scene':34s} {'method':30s} {'mean°':>6s} {'median°':>7s} {'p95°':>6s} {'s':>6s}  BRDF-aware rounds")
    normals = {}
    for shape, mat, tex, near in scenes + ([] if args.quick else [("relief", "two_materials", False, None)]):
        t = time.perf_counter()
        if mat == "two_materials":
            d = two_materials(args)
        else:
            d = render_scene(shape, mat, size=args.size, spp=args.spp, textured=tex, near_distance=near,
                             cache_dir=args.cache)
        label = f"{shape}/{mat}{' textured' if tex else ''}{f' near {near:g}' if near else ''}"
        if time.perf_counter() - t > 1:
            print(f"  (rendered {label} in {time.perf_counter() - t:.0f} s)")
        sel = binary_erosion(d["mask"], iterations=1)
        ls_mean, ls_normal = None, None
        for method, ir, name in variants:
            try:
                r, dt = run_ps(d, method, args.init, ir)
            except ValueError as exc:      # rpca_wu2010 takes distant lights only
                print(f"{label:34s} {name:30s}   n/a ({exc})"[:140], flush=True)
                continue
            e = angular_errors(r.normal, d["normals"], sel)
            ls_mean, ls_normal = (e.mean(), r.normal) if name == "woodham1980" else (ls_mean, ls_normal)
            extra = ""
            if method == "li_alternating":
                rounds = r.info.get("rounds", [])
                if len(r.info.get("materials", [])) > 1:
                    extra = "materials: " + ", ".join(
                        f"(σ {q['sigma']:.3f}, n_i {q['n_i']:.3f}, {q['pixels']} px)" for q in r.info["materials"]) + " "
                    rounds = []
                extra += " ".join(f"[σ {q['sigma']:.3f} n_i {q['n_i']:.3f} Δ{q['median_change_deg']:.2f}°]"
                                  for q in rounds)
                extra += "".join(f" {q['model_choice']['model']}, {q.get('diffuse', '?')} diffuse, lobe gain "
                                 f"{100 * q['model_choice']['gain']:.1f} %;" for q in r.info.get("materials", [])
                                 if "gain" in q.get("model_choice", {}))
                kd_true = d["kd"][sel]
                kd_est = r.albedo[sel]
                ok = kd_true.min(1) > 0
                extra += f"  K_d/true median {np.median(kd_est[ok] / kd_true[ok]):.3f}"
            if method == "li_alternating" or ir:
                if ls_mean is None:     # least squares not among --methods: for the ratio only
                    ls_normal = run_ps(d, "woodham1980")[0].normal
                    ls_mean = angular_errors(ls_normal, d["normals"], sel).mean()
                extra += f"  ({e.mean() / ls_mean:.2f}× least squares)"
            extra += _valid_note(r, d, sel, ls_normal)
            print(f"{label:34s} {_marked(name):30s} {e.mean():6.2f} {np.median(e):7.2f} {np.percentile(e, 95):6.2f} "
                  f"{dt:6.2f}  {extra}", flush=True)
            if shape == THESIS_SHAPE and not tex and near is None:
                normals[(mat, name)] = (r.normal, sel)
    if not args.quick:
        thesis_test(args, variants, normals)
    pipeline_rows(args, variants)
    rows, found = table_heights(args)
    print(f"\nHeights: two domes in paint_0.10 on a dark table (K_d 0.04, {TABLE_MATERIAL}), rank_trimmed "
          f"normals; RMS against Mitsuba's positions in pixels, one constant over both domes / one per dome; "
          f"{found}")
    for label, g, per, dt in rows:
        print(f"  {label:40s} {g:7.3f} {per:7.3f}  {dt:6.3f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
