"""`facette bench e2e`: the one-button scan end to end on the simulated rig, per RAW size.

For each size, `facette scan --sim --press-button --raw-size WxH` runs as a user runs it
(adaptive bracket, lights merged during acquisition, then every default processing stage)
in a process of its own, and the bench reports:

- rig time (device timeline, metering included) and the whole command's wall time;
- the merge (sum over lights of decode + merge + EXR write, on the worker during the scan),
  and the merge alone of the finished scan again in a fresh process (all lights, forced, with
  the `facette` command's allocator settings, facette._memory);
- reconstruction (photometric stereo + integration) and BRDF fit, from `facette process`;
- "results ready after the last frame": from the last frame's capture (journal) to the
  last result file written (results/process.json, written last: every output asked for, the
  report and model.glb included); "maps ready": to the last of the maps (normal.exr, albedo.exr,
  mask.png, height.exr: what photometric stereo and the integration give, written before the
  report and model.glb are made); and to the command's end (the interpreter's exit after that:
  freeing gigabytes takes a few tenths of a second); the scan command's CPU seconds (simulator
  included: on a shared machine, wall time waits for a core), and those after the last frame
  (the journal records the process's CPU at each frame: the figure a loaded machine does not
  stretch);
- peak memory (max RSS) of the scan command (simulator included) and of `facette process`
  alone on the finished scan;
- "rig apart": the same scan with the simulated rig in a process of its own (`facette sim`)
  and `facette scan --device PORT --camera-dir DIR`, as a real rig is driven: the scan
  command's peak memory and ready time without the simulator's renderer in its process (at
  4288x2848 that renderer holds 3.7 GB of its own);
- SNR of the merged radiance on the object (truth mask), shadows (2–10 % of its values)
  and midtones (45–55 %), from the variance the merge reports; clipped object pixels;
- height RMS error against the simulator's truth (`height_errors`) over the pixels that have
  a result and are on the object, up to one constant (what `facette process` reports), also
  in pixel pitches, and with each object (a connected piece of the truth mask) up to its own.

The sizes are the command's default (`default`: `facette scan --sim` without --raw-size) and
a quarter of the thesis camera, 1072x712; `--full` adds the full 4288x2848. At the first size
the fixed thesis bracket (`--exposures thesis`) runs too, for its rig time and shadow SNR
beside the adaptive plan's. Medians over `--runs` runs.

Large captures: `--memory 2GB` runs `facette scan --sim --memory 2GB` (the simulator renders in
bands, each light's HDR is written and not held, the processing after the last frame runs as
`facette process --memory` does), `--outputs` chooses what it writes, and `--scan-only` leaves
out the runs beside it (merge alone, process alone, rig apart: minutes at 100 MP). E.g. the
one-button scan of a 100 MP camera and the thesis camera with and without a budget:

    facette bench e2e --sizes 11648x8736 --memory 2GB --outputs normals,height --scan-only --no-fixed
    facette bench e2e --sizes 4288x2848 [--memory 2GB] --outputs normals,height --scan-only --no-fixed

Where the time after the last frame goes: each run prints a line (bench/_e2e_after.py) of when the last
light's merge was stored, each stage's wall seconds and when each result file was written, after the last
frame. On a kept scan (`--keep`): `--stages SCAN_DIR` runs
`facette process` on it and prints each stage's wall and CPU seconds (bench/_e2e_stages.py);
`--viewer SCAN_DIR [--sides 1100,550]` the report viewer's PSNR against the photographs with its
relighting model fitted at each side, and that stage's time (bench/_e2e_viewer.py).

Usage: facette bench e2e [--sizes default,1072x712,128x96] [--full] [--runs N] [--keep DIR]
                         [--memory SIZE] [--outputs LIST] [--scan-only]
       facette bench e2e --stages SCAN_DIR [--held held|arriving] | --viewer SCAN_DIR [--sides 1100,550]
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from facette.bench._e2e_after import stage_times as _times, timeline, timeline_line   # _times: bench/size.py's too
from facette.io.exr import read_exr
from facette.io.png import read_mask
from facette.scan import read_scan_manifest

DEFAULT_SIZES = "default,1072x712"
FACETTE = [sys.executable, "-m", "facette.cli.main"]
FULL = "4288x2848"


def _run_rss(cmd):
    """(stdout, wall s, max RSS GB, end time UTC, CPU s) of a command in a process of its own
    (max RSS and CPU time of that child alone, from wait4)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out = proc.stdout.read()
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    end = _dt.datetime.now(_dt.timezone.utc)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err[-2000:]}")
    return out, time.perf_counter() - t0, usage.ru_maxrss / 1e6, end, usage.ru_utime + usage.ru_stime


def _snr(scan_dir):
    """Median over lights of the merged SNR (dB) in the object's shadows and midtones, and the
    fraction of object pixels clipped (no finite variance), green channel."""
    mask = np.load(scan_dir / "truth.npz")["mask"].astype(bool)
    data = read_scan_manifest(scan_dir)
    shadow, mid, clipped = [], [], []
    for rec in data.hdr.lights:
        rad = read_exr(scan_dir / rec.file)[0][..., 1][mask]
        var = read_exr(scan_dir / rec.var_file)[0][..., 1][mask]
        ok = np.isfinite(var) & (var > 0) & (rad > 0)
        clipped.append(float(np.mean(~np.isfinite(var))))
        snr = 20 * np.log10(rad[ok] / np.sqrt(var[ok]))
        q = np.percentile(rad[ok], [2, 10, 45, 55])
        shadow.append(np.median(snr[(rad[ok] >= q[0]) & (rad[ok] < q[1])]))
        mid.append(np.median(snr[(rad[ok] >= q[2]) & (rad[ok] < q[3])]))
    return float(np.median(shadow)), float(np.median(mid)), float(np.max(clipped))


def height_errors(truth, height_mm, result_mask):
    """(global, per-object) height RMS error in mm of a height map against the truth.

    truth : dict with "height_mm" (H, W) and "mask" (H, W) bool (truth.npz); height_mm : (H, W)
    result heights in mm; result_mask : (H, W) bool, the pixels that have a result.
    Heights from normals are known up to a constant. "global" removes one constant over every
    compared pixel; "per-object" one per object (8-connected piece of the truth mask), which
    leaves out how well the step between an object and the table (the sphere's vertical rim)
    was integrated. NaN when no pixel is compared.
    """
    t = np.asarray(truth["height_mm"], np.float64)
    obj = np.asarray(truth["mask"], bool)
    h = np.asarray(height_mm, np.float64).reshape(t.shape)
    sel = obj & np.asarray(result_mask, bool) & np.isfinite(h)
    if not sel.any():
        return float("nan"), float("nan")
    d = h - t
    glob = float(np.sqrt(np.mean((d[sel] - d[sel].mean()) ** 2)))
    import scipy.ndimage
    labels, _ = scipy.ndimage.label(obj, structure=np.ones((3, 3)))
    lab = labels[sel]
    count = np.bincount(lab)
    offset = np.bincount(lab, weights=d[sel]) / np.maximum(count, 1)
    per = float(np.sqrt(np.mean((d[sel] - offset[lab]) ** 2)))
    return glob, per


def _scan_height_errors(scan_dir, results="results"):
    with np.load(scan_dir / "truth.npz") as z:
        truth = {"height_mm": z["height_mm"], "mask": z["mask"]}
    h = read_exr(scan_dir / results / "height.exr")[0][..., 0]
    mask = scan_dir / results / "mask.png"        # left out by --outputs normals,height
    return height_errors(truth, h, read_mask(mask) if mask.is_file() else np.isfinite(h))


def _results_written(results):
    """When the last file of a results folder was written (POSIX seconds)."""
    return max(p.stat().st_mtime for p in results.iterdir() if p.is_file())


def _last_captured(scan_dir):
    """The journal's last "captured" entry (the scan's last frame)."""
    last = None
    for line in (scan_dir / "journal.jsonl").read_text().splitlines():
        e = json.loads(line)
        if e.get("step") == "captured":
            last = e
    return last


def _journal_last_frame(scan_dir):
    return _dt.datetime.fromisoformat(_last_captured(scan_dir)["t"])


def cpu_after_last_frame(scan_dir, command_cpu_s):
    """CPU seconds the scan command used after its last frame (all threads): its whole CPU less the
    process's CPU the journal recorded at the last frame ("cpu_s"); NaN for a journal without it."""
    return command_cpu_s - _last_captured(scan_dir).get("cpu_s", float("nan"))


MAPS = ("normal.exr", "albedo.exr", "mask.png", "height.exr")    # the maps, before the report and model.glb


def _maps_written(results):
    """When the last of the maps (MAPS, those there) was written (POSIX seconds); NaN when none is."""
    times = [(results / name).stat().st_mtime for name in MAPS if (results / name).is_file()]
    return max(times) if times else float("nan")


def _ready_s(scan_dir):
    """Seconds from the scan's last frame to its last result file."""
    return _results_written(scan_dir / "results") - _journal_last_frame(scan_dir).timestamp()


def _maps_ready_s(scan_dir):
    """Seconds from the scan's last frame to the last of its maps (MAPS)."""
    return _maps_written(scan_dir / "results") - _journal_last_frame(scan_dir).timestamp()


def _size_args(size):
    return [] if size == "default" else ["--raw-size", size]


def rig_apart_run(size, work):
    """The scan command's peak memory (GB) and "ready after the last frame" (s) when the
    simulated rig is a process of its own, as a real rig is: `facette sim`, then `facette scan
    --device PORT --camera-dir DIR` with the simulator's profile (adaptive, every default stage)."""
    from facette._data import sim_profile_dir

    d = Path(tempfile.mkdtemp(prefix=f"e2e-rig-apart-{size}-", dir=work))
    with subprocess.Popen(FACETTE + ["sim", "--workdir", str(d / "rig")] + _size_args(size), stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True) as sim:
        try:
            port = sim.stdout.readline().split(": ", 1)[1].strip()
            camera = sim.stdout.readline().split(": ", 1)[1].strip()
            # its later lines are drained, so that a full pipe never stops the rig
            threading.Thread(target=sim.stdout.read, daemon=True).start()
            _, _, rss, _, _ = _run_rss(FACETTE + ["scan", "--device", port, "--camera-dir", camera,
                                                  "--profile", str(sim_profile_dir()), "--quiet",
                                                  str(d / "scan")])
        finally:
            sim.stdin.write("quit\n")
            sim.stdin.flush()
            sim.wait(timeout=120)
    return {"rig_apart_gb": rss, "rig_apart_ready_s": _ready_s(d / "scan")}


def one_run(size, work, exposures=None, rig_apart=True, memory=None, outputs=None, scan_only=False):
    """Figures of one scan at `size` ("WxH", or "default": the command's own) in a new folder
    under `work` (`memory`, `outputs`: the scan command's --memory and --outputs; `scan_only`:
    without the merge alone, the process alone and the rig apart)."""
    d = Path(tempfile.mkdtemp(prefix=f"e2e-{size}-", dir=work)) / "scan"
    cmd = FACETTE + ["scan", "--sim", "--press-button", "--quiet"] + _size_args(size) + [str(d)]
    if exposures:
        cmd[-1:-1] = ["--exposures", exposures]
    if memory:
        cmd[-1:-1] = ["--memory", memory]
    if outputs:
        cmd[-1:-1] = ["--outputs", outputs]
    out, wall, rss, end, cpu = _run_rss(cmd)
    data = read_scan_manifest(d)
    merge_s = sum(r.seconds() for r in data.hdr.lights) if data.hdr is not None else 0.0
    times = _times(out)
    global_, per_object = _scan_height_errors(d)
    with np.load(d / "truth.npz") as z:
        pitch, (h, w) = float(z["pixel_pitch_mm"]), z["mask"].shape
    # the RAW mosaic is twice the HDR grid
    label = f"{2 * w}x{2 * h} (default)" if size == "default" else size
    shadow, mid, clipped = _snr(d)
    row = {"size": label + (f" --memory {memory}" if memory else ""),
           "bracket": (data.bracketing or {}).get("name"),
           "frames": len(data.frames), "rig_s": data.rig_time_s, "wall_s": wall, "merge_s": merge_s,
           "recon_s": times.get("ps", np.nan) + times.get("integrate", np.nan),
           "fit_s": times.get("fit", np.nan), "maps_ready_s": _maps_ready_s(d), "ready_s": _ready_s(d),
           "scan_cpu_s": cpu, "cpu_after_s": cpu_after_last_frame(d, cpu),
           "exit_s": (end - _journal_last_frame(d)).total_seconds(), "peak_gb": rss,
           "shadow_db": shadow, "mid_db": mid, "clipped": clipped,
           "height_rms_mm": global_, "height_rms_px": global_ / pitch,
           "height_rms_object_mm": per_object, "pitch_mm": pitch, "after": timeline(d, out)}
    if scan_only:
        return {**row, **{k: np.nan for k in ("merge_alone_s", "merge_alone_cpu_s", "merge_alone_gb",
                                              "process_cpu_s", "process_s", "process_gb",
                                              "rig_apart_gb", "rig_apart_ready_s")}}
    # The merge alone, all lights, in a fresh process; then `facette process` alone.
    # with the `facette` command's allocator settings, as the merge runs inside the command
    code = ("from facette._memory import keep_freed_memory; keep_freed_memory(); "
            "import sys, time; from facette.scan import merge_scan; t = time.perf_counter(); "
            "merge_scan(sys.argv[1], force=True); print(f'merge {time.perf_counter() - t:.3f}')")
    m_out, _, m_rss, _, m_cpu = _run_rss([sys.executable, "-c", code, str(d)])
    p_out, p_wall, p_rss, _, p_cpu = _run_rss(FACETTE + ["process", str(d), "-o", str(d / "results2")])
    apart = rig_apart_run(size, work) if rig_apart and not exposures else \
        {"rig_apart_gb": np.nan, "rig_apart_ready_s": np.nan}
    return {**row, "merge_alone_s": float(m_out.split()[-1]), "merge_alone_cpu_s": m_cpu,
            "merge_alone_gb": m_rss, "process_cpu_s": p_cpu, "process_s": p_wall, "process_gb": p_rss,
            **apart}


COLUMNS = [("size", "size", "s"), ("bracket", "bracket", "s"), ("frames", "frames", "d"),
           ("rig_s", "rig s", ".1f"), ("wall_s", "wall s", ".1f"), ("merge_s", "merge s", ".2f"),
           ("merge_alone_s", "merge alone s", ".2f"), ("merge_alone_cpu_s", "(CPU s)", ".2f"),
           ("recon_s", "recon s", ".2f"),
           ("fit_s", "fit s", ".2f"), ("maps_ready_s", "maps ready after last frame s", ".2f"),
           ("ready_s", "ready after last frame s", ".2f"), ("scan_cpu_s", "scan command CPU s", ".1f"),
           ("cpu_after_s", "CPU s after last frame", ".2f"),
           ("exit_s", "command end s", ".2f"),
           ("process_s", "process alone s", ".2f"), ("process_cpu_s", "(CPU s)", ".2f"),
           ("peak_gb", "peak GB (scan+sim)", ".2f"), ("process_gb", "peak GB process", ".2f"),
           ("rig_apart_gb", "peak GB scan, rig apart", ".2f"),
           ("rig_apart_ready_s", "ready, rig apart s", ".2f"),
           ("shadow_db", "shadow dB", ".1f"), ("mid_db", "mid dB", ".1f"),
           ("clipped", "clipped", ".4f"), ("pitch_mm", "pitch mm", ".4f"),
           ("height_rms_mm", "height RMS mm", ".3f"), ("height_rms_px", "(pitches)", ".3f"),
           ("height_rms_object_mm", "(per object) mm", ".3f")]


def _median(rows):
    out = dict(rows[0])
    for k, _, f in COLUMNS:
        if f != "s":
            out[k] = float(np.median([r[k] for r in rows]))
    return out


def _print(rows):
    print("| " + " | ".join(h for _, h, _ in COLUMNS) + " |")
    print("|" + "---|" * len(COLUMNS))
    for r in rows:
        print("| " + " | ".join(format(int(r[k]) if f == "d" else r[k], f) for k, _, f in COLUMNS)
              + " |", flush=True)


def _on_kept_scan(args):
    """--stages / --viewer on a scan directory a run kept."""
    if args.stages:
        import facette.pipeline._relight_model_stage as stage
        from facette.bench._e2e_stages import print_stage_table, stage_table
        stage.MODEL_SIDE = args.model_side or stage.MODEL_SIDE
        print(f"`facette process` on {args.stages}" + (f" (its lights {args.held}, as the one-button scan hands them "
              "over)" if args.held else "") + ", every default output, the report's model at "
              f"{stage.MODEL_SIDE} px, stage by stage, one after the other (CPU: the process's over the stage; "
              "rest: no stage's)")
        print_stage_table(stage_table(args.stages, held=args.held))
    if args.viewer:
        from facette.bench._e2e_viewer import viewer_rows
        print(f"the report viewer on {args.viewer}: its relighting model fitted at each side")
        print("| model side | model stage s | (CPU s) | viewer PSNR dB (median over lights) | (min-max) |")
        print("|---|---|---|---|---|")
        for side, wall, cpu, med, (lo, hi) in viewer_rows(args.viewer, [int(s) for s in args.sides.split(",")]):
            print(f"| {side} | {wall:.2f} | {cpu:.2f} | {med:.2f} | {lo:.2f}-{hi:.2f} |", flush=True)
    return 0


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench e2e", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default=DEFAULT_SIZES, help=f"RAW sizes WxH (default {DEFAULT_SIZES})")
    p.add_argument("--full", action="store_true", help=f"also {FULL}, the thesis camera (minutes)")
    p.add_argument("--runs", type=int, default=1, help="runs per size; medians are printed")
    p.add_argument("--no-fixed", action="store_true", help="skip the thesis bracket comparison")
    p.add_argument("--keep", help="keep the scans in this folder (default: a temporary one)")
    p.add_argument("--no-rig-apart", action="store_true",
                   help="skip the second scan with the simulated rig in a process of its own")
    p.add_argument("--memory", help="the scan command's --memory (e.g. 2GB): bands, HDR not held")
    p.add_argument("--outputs", help="the scan command's --outputs (e.g. normals,height)")
    p.add_argument("--scan-only", action="store_true",
                   help="only the scan command: no merge alone, process alone or rig apart")
    p.add_argument("--stages", metavar="SCAN_DIR", help="each stage's time of `facette process` on a kept scan")
    p.add_argument("--held", choices=("held", "arriving"),
                   help="--stages: the lights held in memory as the one-button scan hands them to process; "
                        "arriving: also made into its inputs as they arrived (before the clock)")
    p.add_argument("--viewer", metavar="SCAN_DIR", help="the report viewer's PSNR per model side on a kept scan")
    p.add_argument("--sides", default="1100,550", help="--viewer: the report model's sides (default 1100,550)")
    p.add_argument("--model-side", type=int, help="--stages: the report model's side (default: "
                   "pipeline._relight_model_stage.MODEL_SIDE; 1100 fits it as before, at the viewer's)")
    args = p.parse_args(argv)
    if args.stages or args.viewer:
        return _on_kept_scan(args)
    sizes = [s.strip() for s in args.sizes.split(",") if s.strip()] + ([FULL] if args.full else [])
    for s in sizes:
        if not re.fullmatch(r"\d+x\d+", s) and s != "default":
            raise SystemExit(f"--sizes: {s!r} is neither WxH (e.g. 1024x768) nor 'default'")
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="facette-e2e-"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"one-button scan on the simulated rig, {args.runs} run(s) per size, medians; "
          f"{os.cpu_count()} cores; scans in {work}")
    rows = []
    jobs = [(s, None) for s in sizes] + ([] if args.no_fixed else [(sizes[0], "thesis")])
    for size, exposures in jobs:
        runs = []
        for k in range(max(1, args.runs)):
            runs.append(one_run(size, work, exposures, rig_apart=not args.no_rig_apart, memory=args.memory,
                                outputs=args.outputs, scan_only=args.scan_only))
            print(f"  {size} run {k + 1}: " + timeline_line(runs[-1]["after"]), flush=True)
            if args.runs > 1:
                print(f"  run {k + 1}:", flush=True)
                _print(runs[-1:])
        rows.append(_median(runs))
        _print(rows[-1:])
    print()
    _print(rows)
    print("  rig s: device timeline (metering included); merge s: decode + merge + EXR write summed "
          "over lights on the worker during the scan; merge alone: the same scan merged again in "
          "a fresh process; recon: photometric stereo + integration; maps ready: last frame captured -> "
          "the last of normal.exr, albedo.exr, mask.png, height.exr written; ready: -> the last result file written "
          "(report and model.glb included); scan command CPU s: simulator included; CPU s after last frame: the scan command's, every thread (the processing, and the last light's merge); command end: -> the scan command's exit; rig apart: the scan command (no simulator in its process) against `facette sim`; process alone: `facette process` on the finished scan (HDR up to date); "
          "CPU s: of that process (wall > CPU/cores means it waited for a core); SNR from the merge's variance on the object, green, median over lights; "
          "height RMS: result against the truth on the object up to one constant, also in pixel pitches, "
          "and up to one constant per object")
    if not args.keep:
        import shutil
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
