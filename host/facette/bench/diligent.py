"""`facette bench diligent`: photometric stereo on real photographs with laser-scanned truth.

Reads every DiLiGenT-style folder under the root (default `../shared/data` beside the
repository, or `../../shared/data` from a git worktree; a folder holds filenames.txt and light_directions.txt, its truth is
`<folder>.truth/normals_gt.npy` beside it; folders without truth are listed and skipped).
Every figure is `facette process`'s (facette.pipeline.process on the folder, outputs=["normals"],
the method by --methods): the user's path, with the channels, the usable-value test and the mask
process uses (the RGB images divided by the light intensities, saturated values missing; the
normals solved on the channels process chooses, by default the mean of R, G, B, `--channels`
to choose another: pipeline._channels; the albedo, li_alternating's K_d, per channel).
The time is process's wall time for the normals (reading included; its CPU seconds, threads summed,
are printed to stderr as each run ends: the figure to compare on a loaded machine); `facette process` with every
output adds the integration, BRDF fit, PTM/HSH and report. The default's rows are process's
"auto" (inter-reflections removed where the images tell the albedo's scale, cast shadows where the
heights hide enough lit samples). Rows of a name ending in "+ir" are NOT process's: `run_ps` on the
same images, the albedo's scale assumed (IR_ASSUMED_P99), the steps and channels as
`process --interreflections`.
Per object and method: mean and median angular error over the mask (zero-length truth normals
left out), run time, and the published least-squares figure (Shi et al. 2016/2019, all 96
lights) beside it; then the mean over each group of objects. "rank_trimmed+ir": the same after
the inter-reflections are removed (facette.recon.remove_interreflections; the albedo's scale
assumed, see IR_ASSUMED_P99).

--lights 12 picks the 12 DiLiGenT lights nearest the rig's directions (thesis §4.2: theta 15 deg
at phi 30, 90, ..., 330 and 30 deg at phi 0, 60, ..., 300; one light each, by an optimal
assignment on the angle). (process reads them from a temporary DiLiGenT-style folder
of links to the chosen images.) --speed times each method at 2144x1424 x 12 lights (a rendered
sphere on a plane), in seconds and seconds per megapixel. --trim-study sweeps the trim of
`ps_rank_trimmed` and chooses it leaving one object out at a time. --seeds N runs the default
over N draws of its fit and profile pixels: a model choice that a draw decides shows there.
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from facette.io.diligent import is_diligent_dir, read_diligent
from facette.methods import PS_METHODS, photometric_stereo
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

DEFAULT_METHODS = ["woodham1980", "rank_trimmed", "li_alternating"]
IR_SUFFIX = "+ir"   # a method name with it: inter-reflections removed first (`run_ps`)
# DiLiGenT's images are divided by the light intensities, but their scale is not a reflectance:
# for the inter-reflection removal the albedo is scaled so that its 99th percentile is this
# (an assumption, for the figures only: a reflectance-calibrated scan needs none)
IR_ASSUMED_P99 = 0.8

# Published mean angular errors (deg), DiLiGenT, all 96 lights (Shi et al. TPAMI 2019, Table 2)
PUBLISHED_LS = {"ball": 4.10, "cat": 8.41, "pot1": 8.89, "bear": 8.39, "pot2": 14.65,
                "buddha": 14.92, "goblet": 18.50, "reading": 19.80, "cow": 25.60, "harvest": 30.62}
PUBLISHED_OTHERS = {   # ball, cat, pot2, buddha, reading (from the same table)
    "Wu 2010 RPCA": (2.06, 6.73, 13.12, 10.91, 15.39),
    "Ikehata 2012 SBL": (2.54, 7.21, 14.09, 11.11, 16.17),
    "Shi 2014 bi-polynomial": (1.74, 6.12, 8.78, 10.60, 13.63),
    "Ikehata 2014 bivariate": (3.34, 6.74, 8.77, 10.47, 14.19),
    # "Higo 2010 consensus" (HM10, the same table) is left out: its row could not be read in
    # the search corpus when ps_consensus_higo2010 was added (December 2026); add it once checked
}
SPEED_SIZE = (1424, 2144)   # rows, columns: half of the D300's 4288x2848


def default_root():
    """`../shared/data` beside the repository this package is installed from (or
    `../../shared/data`, for a git worktree kept one folder further down)."""
    repo = Path(__file__).resolve().parents[3]
    for base in (repo.parent, repo.parent.parent):
        if (base / "shared" / "data").is_dir():
            return base / "shared" / "data"
    return repo.parent / "shared" / "data"


def find_objects(root):
    """DiLiGenT-style folders under root (sorted), each with its truth path (or None)."""
    root = Path(root)
    if not root.is_dir():
        raise SystemExit(f"no folder {root}; give the data folder with --root DIR")
    out = []
    for f in sorted(p.parent for p in root.rglob("filenames.txt")):
        if is_diligent_dir(f):
            truth = f.parent / (f.name + ".truth") / "normals_gt.npy"
            out.append((f, truth if truth.is_file() else None))
    return out


def object_name(folder):
    """'ballPNG' -> 'ball' (the key of the published figures)."""
    name = Path(folder).name
    return name[:-3] if name.endswith("PNG") else name


def rig_light_indices(light_dirs):
    """Indices of the 12 lights nearest the rig's directions (one each, smallest total angle)."""
    rig = thesis_light_directions()
    if len(light_dirs) < len(rig):
        raise ValueError(f"{len(light_dirs)} lights: fewer than the rig's {len(rig)}")
    ang = np.arccos(np.clip(rig @ np.asarray(light_dirs).T, -1, 1))
    rows, cols = linear_sum_assignment(ang)
    return cols[np.argsort(rows)], np.degrees(ang[rows, cols])


def grey_input(data):
    """(m, H, W) float32 mean of RGB; NaN where a channel was saturated."""
    return data.images.mean(axis=-1)


def angular_errors(normal, truth, mask):
    """Angles (deg) on mask where the truth is a unit vector; invalid estimates count 90 deg."""
    good = mask & (np.linalg.norm(truth, axis=-1) > 0.5)
    t = truth[good] / np.linalg.norm(truth[good], axis=-1, keepdims=True)
    dot = np.clip(np.sum(normal[good] * t, axis=-1), -1, 1)
    return np.degrees(np.arccos(dot))


def base_method(name):
    """'rank_trimmed+ir' -> 'rank_trimmed'."""
    return name[:-len(IR_SUFFIX)] if name.endswith(IR_SUFFIX) else name


def run_ps(images, light_dirs, name, mask, init=None):
    """photometric_stereo by name; a name ending in IR_SUFFIX first removes the inter-reflections
    as `process --interreflections` does (the normals on the channels `process` chooses by default;
    li_alternating: its glossy second gather, `ps_li_without_interreflections`), with the albedo's
    scale assumed: its 99th percentile (the brightest channel) IR_ASSUMED_P99."""
    method = base_method(name)
    options = {"init": init} if init else {}       # li_alternating takes `init`; the other methods leave it
    if name == method:
        return photometric_stereo(images, light_dirs, method=method, mask=mask, options=options or None)
    from facette.fit import ps_li_without_interreflections
    from facette.pipeline import ProcessOptions
    from facette.pipeline._channels import images_for_solve
    from facette.recon import without_interreflections
    images, _ = images_for_solve(images, mask, ProcessOptions(), options, [])   # process's default channels
    channel = options.get("channel")
    first = photometric_stereo(images, light_dirs, method="rank_trimmed", mask=mask,
                               options={"channel": channel} if channel is not None else None)
    p99 = float(np.percentile(first.albedo[first.valid].max(-1), 99)) if first.valid.any() else 1.0
    scale = IR_ASSUMED_P99 / max(p99, 1e-12)
    if PS_METHODS.canonical(method) == "li_alternating":
        return ps_li_without_interreflections(images, light_dirs, mask, reflectance_scale=scale, **options)[0]
    images, _, _ = without_interreflections(images, light_dirs, mask, reflectance_scale=scale, channel=channel)
    return photometric_stereo(images, light_dirs, method=method, mask=mask, options=options)


def subset_folder(folder, select, dest):
    """A DiLiGenT-style folder at dest holding the lights `select` of folder: links to its images
    and mask, the rows of its text files (what `process` reads, for --lights 12)."""
    folder, dest = Path(folder), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    names = (folder / "filenames.txt").read_text().split()
    lines = {f: (folder / f).read_text().strip().splitlines()
             for f in ("light_directions.txt", "light_intensities.txt") if (folder / f).is_file()}
    for f, rows in lines.items():
        (dest / f).write_text("\n".join(rows[i] for i in select) + "\n")
    (dest / "filenames.txt").write_text("\n".join(names[i] for i in select) + "\n")
    for name in [names[i] for i in select] + ["mask.png"]:
        if (folder / name).exists() and not (dest / name).exists():
            os.symlink((folder / name).resolve(), dest / name)
    return dest


def process_normals(folder, name, init=None, channels=None):
    """(normals (H, W, 3), mask, wall seconds) of facette.pipeline.process on folder, method
    `name` (a name ending in IR_SUFFIX: `run_ps` on the images process reads, see the module doc);
    `channels`: process's (None: its default)."""
    from facette.pipeline import load_input, process
    method = base_method(name)
    opts = {"ps_options": {"init": init}} if init and PS_METHODS.canonical(method) == "li_alternating" else {}
    if channels is not None:
        opts["channels"] = channels
    t = time.perf_counter()
    if name != method:
        inp = load_input(folder)
        res = run_ps(inp.images, inp.light_dirs, name, inp.mask, init)
        return res.normal, inp.mask, time.perf_counter() - t
    res = process(folder, outputs=["normals"], method=method, **opts)
    return res.normals, res.inputs.mask, time.perf_counter() - t


def run_object(folder, truth_path, methods, lights, init=None, channels=None):
    import tempfile
    select = None
    if lights == "12":
        with open(Path(folder) / "light_directions.txt") as fh:
            dirs = np.loadtxt(fh, ndmin=2)
        select, _ = rig_light_indices(dirs / np.linalg.norm(dirs, axis=1, keepdims=True))
    t = time.perf_counter()
    data = read_diligent(folder, select=select)
    t_read = time.perf_counter() - t
    truth = np.load(truth_path)
    if truth.shape[:2] != data.mask.shape:
        raise SystemExit(f"{truth_path} is {truth.shape[:2]}, the images {data.mask.shape}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        src = folder if select is None else subset_folder(folder, select, Path(tmp) / Path(folder).name)
        for name in methods:
            c = time.process_time()
            normal, mask, dt = process_normals(src, name, init, channels)
            cpu = time.process_time() - c       # its threads summed: the cost on a loaded machine
            e = angular_errors(normal, truth, mask)
            rows.append((name, float(e.mean()), float(np.median(e)), dt))
            print(f"    {Path(folder).name} {lights} lights, {name}: {dt:.2f} s wall, {cpu:.2f} s CPU, "
                  f"{float(e.mean()):.2f} deg", file=sys.stderr, flush=True)
    return rows, t_read, data


def print_table(results, methods, lights):
    label = "all lights" if lights == "all" else "12 lights near the rig's directions"
    print(f"\n-- DiLiGenT, {label}: mean / median angular error (deg), run time (s)")
    head = f"{'object':26s} {'pixels':>7s} {'LS pub.':>7s}"
    for name in methods:
        head += f" | {name[:22]:>22s}"
    print(head)
    groups = {}
    for (key, n_px, _, rows) in results:
        pub = PUBLISHED_LS.get(key.split("/")[-1].split(" ")[0])
        line = f"{key:26s} {n_px:7d} {pub if pub is not None else float('nan'):7.2f}"
        for _, mean, med, dt in rows:
            line += f" | {mean:6.2f} {med:6.2f} {dt:7.2f}s"
        print(line)
        groups.setdefault(key.split("/")[0], []).append(rows)
    for group, members in groups.items():
        if len(members) < 2:
            continue
        line = f"{'mean ' + group:26s} {'':7s} {'':7s}"
        for j in range(len(methods)):
            mean = np.mean([r[j][1] for r in members])
            med = np.mean([r[j][2] for r in members])
            dt = np.sum([r[j][3] for r in members])
            line += f" | {mean:6.2f} {med:6.2f} {dt:7.2f}s"
        print(line)
    print("(LS pub.: published least squares, 96 lights; 'mean' rows: mean of the objects' means "
          "and medians, total time)")


def seed_study(objects, seeds):
    """The default's errors over `seeds` draws of its fit and profile pixels (ps_options seed), all
    lights, through `process`: how much one draw moves the model choice and the normals."""
    from facette.pipeline import process
    print(f"\n-- li_alternating over {seeds} seeds of its pixel draws (all lights): mean error (deg) "
          "min / median / max, seeds that took the lobe, seconds (median)")
    for folder, truth_path in objects:
        truth, errs, lobes, secs = np.load(truth_path), [], 0, []
        for seed in range(seeds):
            t = time.perf_counter()
            res = process(folder, outputs=["normals"], method="li_alternating", ps_options={"seed": seed})
            secs.append(time.perf_counter() - t)
            errs.append(float(angular_errors(res.normals, truth, res.inputs.mask).mean()))
            lobes += res.ps.info["materials"][0].get("model_choice", {}).get("model") == "lobe"
        print(f"{folder.parent.name + '/' + object_name(folder):26s} {min(errs):6.2f} {np.median(errs):6.2f} "
              f"{max(errs):6.2f}   lobe {lobes}/{seeds}   {np.median(secs):6.1f} s", flush=True)


def speed(methods, size=SPEED_SIZE):
    """Seconds and seconds per megapixel of each method at size x 12 rig lights."""
    h, w = size
    sc = sphere_on_plane(h, w)
    lights = thesis_light_directions()
    imgs = render(sc, lights, "glossy", noise=0.01, rng=np.random.default_rng(1))
    mp = h * w / 1e6
    print(f"\n-- speed: {w}x{h} x {len(lights)} lights ({mp:.2f} MP), glossy sphere on a plane")
    print(f"{'method':26s} {'wall s':>8s} {'CPU s':>8s} {'wall s/MP':>10s} {'CPU s/MP':>9s} "
          f"{'mean err':>9s}")
    for name in methods:
        t, c = time.perf_counter(), time.process_time()
        res = run_ps(imgs, lights, name, sc.mask)
        dt, dc = time.perf_counter() - t, time.process_time() - c
        good = sc.mask
        err = np.degrees(np.arccos(np.clip(np.sum(res.normal[good] * sc.normals[good], -1), -1, 1)))
        print(f"{name:26s} {dt:8.2f} {dc:8.2f} {dt / mp:10.2f} {dc / mp:9.2f} {err.mean():8.2f}°",
              flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"(CPU s counts every thread of this process; 1-minute load average {load:.1f} on "
          f"{os.cpu_count()} cores: on a busy machine wall time overstates the cost)")


def trim_study(objects, trims=(0.2, 0.25, 0.3, 0.35, 0.4)):
    """Mean error of ps_rank_trimmed per trim and object; the trim chosen on the other objects
    (leave one out) and that object's error with it."""
    tab = {}
    names = []
    for folder, truth_path in objects:
        data = read_diligent(folder)
        truth = np.load(truth_path)
        grey = grey_input(data)
        key = object_name(folder)
        names.append(key)
        for t in trims:
            res = photometric_stereo(grey, data.light_dirs, method="rank_trimmed",
                                     mask=data.mask, trim=t)
            tab[key, t] = float(angular_errors(res.normal, truth, data.mask).mean())
    print("\n-- rank_trimmed: mean error (deg) per trim; leave-one-object-out choice")
    print(f"{'object':12s}" + "".join(f" {t:6.2f}" for t in trims) + "   chosen on the others")
    loo = []
    for key in names:
        rest = [k for k in names if k != key]
        best = min(trims, key=lambda t: np.mean([tab[k, t] for k in rest]))
        loo.append(tab[key, best])
        print(f"{key:12s}" + "".join(f" {tab[key, t]:6.2f}" for t in trims)
              + f"   trim {best:.2f}: {tab[key, best]:.2f}")
    print(f"{'mean':12s}" + "".join(f" {np.mean([tab[k, t] for k in names]):6.2f}" for t in trims)
          + f"   held-out mean {np.mean(loo):.2f}")


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench diligent", description=__doc__.split("\n")[0])
    p.add_argument("--root", type=Path, default=None,
                   help="folder searched for DiLiGenT-style folders (default ../shared/data)")
    p.add_argument("--lights", choices=["all", "12"], action="append",
                   help="all lights, or the 12 nearest the rig (default: both tables)")
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                   help=f"comma-separated, from {', '.join(sorted(PS_METHODS))}; a name ending in "
                        f"{IR_SUFFIX} removes the inter-reflections first")
    p.add_argument("--init", default=None,
                   help="initial normals of li_alternating (e.g. rpca_wu2010; default: its own)")
    p.add_argument("--channels", default=None, choices=["green", "mean", "weighted"],
                   help="the channels process solves the normals on (default: process's own)")
    p.add_argument("--seeds", type=int, default=0,
                   help="also run li_alternating over this many seeds of its pixel draws (all lights)")
    p.add_argument("--speed", action="store_true", help="also time each method at 2144x1424 x 12")
    p.add_argument("--no-real", action="store_true", help="skip the DiLiGenT tables")
    p.add_argument("--trim-study", action="store_true",
                   help="sweep rank_trimmed's trim on the diligent_crop8 objects (leave one out)")
    args = p.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if base_method(m) not in PS_METHODS]
    if unknown:
        raise SystemExit(f"unknown method {unknown[0]!r}; choose from {', '.join(sorted(PS_METHODS))}")
    root = args.root or default_root()
    if not args.no_real:
        objects = find_objects(root)
        scored = [(f, t) for f, t in objects if t is not None]
        for f, t in objects:
            if t is None:
                print(f"(no truth for {f}: skipped)")
        if not scored:
            print(f"no DiLiGenT-style folder with truth under {root}; give one with --root DIR")
            return 1
        for lights in args.lights or ["all", "12"]:
            results = []
            for folder, truth_path in scored:
                rows, t_read, data = run_object(folder, truth_path, methods, lights, args.init, args.channels)
                key = f"{folder.parent.name}/{object_name(folder)} {data.bit_depth}-bit"
                m = len(data.names)
                results.append((key, int(data.mask.sum()), m, rows))
                print(f"  {key}: {m} lights, read in {t_read:.1f} s", file=sys.stderr, flush=True)
            print_table(results, methods, lights)
        if args.seeds:
            seed_study(scored, args.seeds)
        if args.trim_study:
            trim_study([(f, t) for f, t in scored if f.parent.name == "diligent_crop8"])
    if args.speed:
        speed(methods)
    print("\npublished on DiLiGenT, 96 lights (ball, cat, pot2, buddha, reading): "
          + "; ".join(f"{k} " + "/".join(f"{v:.2f}" for v in vals) + f" (mean {np.mean(vals):.2f})"
                      for k, vals in PUBLISHED_OTHERS.items()))
    return 0

