"""`facette bench size`: photometric stereo of large captures, untiled against tiled.

For each size a relief slab with known normals (bench/_large.py: 12 lights, the rig's
directions, 16-bit RGB PNGs, a DiLiGenT-style folder written band by band) is generated, then
each of these runs in a process of its own (peak memory = that child's max RSS, from wait4):

- untiled: `facette process SLAB -o OUT --outputs normals,height` as a user runs it (every
  photograph held as float32, photometric stereo of the whole image, then the integration);
- tiled: `pipeline.ps_tiled` with a memory budget (`--memory`, default 2GB), each band's normals
  written to a .npy as it comes (nothing kept at the image's size), the same method (a per-pixel
  one: li_alternating skips it, and its "tiled" error column is the `process --memory` run's);
- process --memory: `facette process SLAB -o OUT --outputs normals,height --memory 2GB` (the
  photographs read band by band, photometric stereo over bands, its maps kept in temporary
  files, the heights' divergence built band by band and solved as one float32 array): wall s,
  s/MP, peak, its bands, and its agreement with the untiled run (largest angle between the
  normals, pixels over 0.01 deg, largest height difference over the untiled heights' range on
  the mask; issue 26 asks 0.01 deg and 0.1 %).

With `--scan`, the slab is also written as a scan directory (hdr/light_XX.exr and _var.exr per
light, uncompressed as the HDR merge writes them, scan.json with the lights and their
intensities) and `facette process SCAN --outputs normals,height` (or `--scan-outputs`, which
must hold normals and height) runs untiled and with `--memory` on it: a second table (wall s,
s/MP, peak, agreement; with brdf, the largest relative difference of the fitted parameters; with
ptm and rti, whether relight.ptm / relight.rti are the same bytes: "=" or the bytes that differ).

With `--dask`, the scan's `process --memory` (with --scan; else the folder's) runs again with its
bands on a dask.distributed LocalCluster of 2 worker processes x 1 thread (`--scheduler`): wall s,
s/MP, the driver's and the workers' peaks, the agreement with the untiled run (above
--untiled-max-mp: with the `--memory` run here, the same run without a cluster); `--kill-worker S`
kills one worker S seconds into that run (`S%`: S % of the `--memory` run's wall seconds), the
first one that then holds tasks (waited for while none does: the driver's own passes): the
tasks it held are lost and the scheduler runs them again elsewhere (columns "kill s", "lost").

Printed per size: generation time and peak; for both runs wall seconds, seconds per megapixel
and peak memory (the untiled run also its load and ps stage times, the tiled one its staging
of the photographs and its bands' reading and photometric stereo); the normals' mean angular
error against the truth; the largest angle between the tiled and the untiled normals and the
number of pixels where they differ by more than 0.01 deg (rank_trimmed's window is a discrete
choice per pixel: a pixel whose values sit on its edge may flip between two answers with the
block layout of the arrays, untiled too: 1 pixel of 3.05 M at 3 MP).
The untiled run is skipped (`--no-untiled`, or above `--untiled-max-mp`, default 20 MP: at
100 MP it needs ~38 GB).

With `--no-flag`, `facette process SLAB --outputs normals,height` runs once more with no flag at
all (the default method, li_alternating, and the default memory budget of pipeline._budget, which
reads a capture band by band when it does not fit whole): wall and CPU s, s/MP, peak, the error to
the truth, the method that ran, the budget's note; `--only-no-flag`: that run alone (the scan's with --scan).

Usage: facette bench size [--sizes 12] [--memory 2GB] [--method rank_trimmed] [--no-flag] [--keep DIR]
Sizes in megapixels (3, 12, 50, 100: the thesis camera's half and whole, 50 MP, the GFX100)
or WxH.
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from facette.bench._large import npy_band_writer, slab_to_scan, write_relief_capture
from facette.bench._size_dask import dask_child, print_dask
from facette.bench._size_whole import against_whole
from facette.bench.e2e import _times   # the stage times `facette process` prints
from facette.io.exr import read_exr
from facette.methods import PS_DEFAULT, PS_METHODS
from facette.pipeline import TILED_METHODS, ps_tiled

SIZES = {"3": (2144, 1424), "12": (4288, 2848), "50": (8192, 6144), "100": (11648, 8736)}
DEFAULT_SIZES = "12"
FACETTE = [sys.executable, "-m", "facette.cli.main"]
SELF = [sys.executable, "-m", "facette.bench.size"]
UNTILED_MAX_MP = 20.0
AGREE_DEG = 0.01          # tiled and untiled normals agree within this (issue 26)
BAND_ROWS = 256           # rows compared at a time (tiled .npy and truth read through a memmap)


def _size(text):
    if text in SIZES:
        return SIZES[text]
    m = re.fullmatch(r"(\d+)x(\d+)", text)
    if not m:
        raise SystemExit(f"a size is one of {', '.join(SIZES)} (megapixels) or WxH, got {text!r}")
    return int(m.group(1)), int(m.group(2))


# The `facette` command's allocator settings (facette/_memory.py) through the environment, for
# the tiled child: the same as the untiled `facette process`, for a fair peak and time.
ALLOCATOR_ENV = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": "2147483647", "MALLOC_ARENA_MAX": "1",
                 "NUMPY_MADVISE_HUGEPAGE": "0", "MALLOC_TOP_PAD_": str(64 << 20)}


# the CPU seconds (user + system) of the last command `_run_rss` ran (its wait4), for the tables
LAST_CPU = [float("nan")]


def _run_rss(cmd, env=None):
    """(stdout, wall s, max RSS GB) of a command in a process of its own (wait4); its CPU seconds
    in LAST_CPU[0]."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=None if env is None else dict(os.environ, **env))
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    # the child's own max RSS comes from the --_rss wrapper (its wait4), printed on stderr
    if proc.returncode:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{err[-2000:]}")
    rss = re.search(r"^max_rss_kb (\d+)$", err, re.M)
    cpu = re.search(r"^cpu_s ([0-9.]+)$", err, re.M)
    LAST_CPU[0] = float(cpu.group(1)) if cpu else float("nan")
    return out, wall, int(rss.group(1)) / 1e6 if rss else float("nan")


def _measured(cmd):
    """The command run by this module's --_rss wrapper, which prints the child's max RSS."""
    return SELF + ["--_rss", "--"] + [str(c) for c in cmd]


def _rss_wrapper(cmd):
    proc = subprocess.Popen(cmd)
    _, status, usage = os.wait4(proc.pid, 0)
    print(f"max_rss_kb {usage.ru_maxrss}", file=sys.stderr)
    print(f"cpu_s {usage.ru_utime + usage.ru_stime:.2f}", file=sys.stderr)
    return os.waitstatus_to_exitcode(status)


def _angles_deg(a, b):
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def _tiled_child(folder, out_npy, memory, method):
    """Photometric stereo over tiles, each band's normals appended to `out_npy` as it comes."""
    t0 = time.perf_counter()
    h = w = None
    with open(Path(folder) / "normal_gt.npy", "rb") as f:
        np.lib.format.read_magic(f)
        h, w, _ = np.lib.format.read_array_header_1_0(f)[0]
    out = npy_band_writer(out_npy, (h, w, 3))
    written = [0]

    def on_band(r0, r1, part):
        if r0 > written[0]:          # bands the mask leaves out: zeros
            out.write(np.zeros((r0 - written[0], w, 3), "<f4").tobytes())
        out.write(part.normal.astype("<f4").tobytes())
        written[0] = r1

    res = ps_tiled(folder, method=method, memory=memory, keep=(), on_band=on_band,
                   work_dir=Path(out_npy).parent)
    if written[0] < h:
        out.write(np.zeros((h - written[0], w, 3), "<f4").tobytes())
    out.close()
    print(json.dumps({"seconds": time.perf_counter() - t0, **{k: res.info[k] for k in (
        "tiles", "rows_per_tile", "staging_s", "read_s", "ps_s")}}))


def _compare(folder, tiled_npy, untiled_exr):
    """Mean angle to the truth (tiled, untiled), the largest tiled-untiled angle (degrees) and
    the number of pixels where they differ by more than AGREE_DEG."""
    truth = np.load(Path(folder) / "normal_gt.npy", mmap_mode="r")
    tiled = np.load(tiled_npy, mmap_mode="r")
    untiled = read_exr(untiled_exr)[0] if untiled_exr else None
    sums, worst, count, over = [0.0, 0.0], 0.0, 0, 0
    for r0 in range(0, truth.shape[0], BAND_ROWS):
        sl = slice(r0, r0 + BAND_ROWS)
        t, n = np.asarray(truth[sl]), np.asarray(tiled[sl])
        ok = np.linalg.norm(n, axis=-1) > 0.5
        sums[0] += _angles_deg(n[ok], t[ok]).sum()
        count += int(ok.sum())
        if untiled is not None:
            u = untiled[sl][..., :3]
            sums[1] += _angles_deg(u[ok], t[ok]).sum()
            apart = _angles_deg(n[ok], u[ok])
            worst = max(worst, float(apart.max(initial=0.0)))
            over += int((apart > AGREE_DEG).sum())
    if untiled is None:
        return sums[0] / count, float("nan"), float("nan"), -1
    return sums[0] / count, sums[1] / count, worst, over


def _truth_error(folder, normal_exr):
    """Mean angle (deg) of the normals of `normal_exr` to the slab's truth, where they have one."""
    truth = np.load(Path(folder) / "normal_gt.npy", mmap_mode="r")
    n = read_exr(normal_exr, ("X", "Y", "Z"))[0]      # not the uncertainty: 4 B/px less held
    total, count = 0.0, 0
    for r0 in range(0, truth.shape[0], BAND_ROWS):
        sl = slice(r0, r0 + BAND_ROWS)
        t, u = np.asarray(truth[sl]), n[sl]
        ok = np.linalg.norm(u, axis=-1) > 0.5
        total += _angles_deg(u[ok], t[ok]).sum()
        count += int(ok.sum())
    return total / max(count, 1)


def _compare_process(untiled_dir, memory_dir):
    """(largest angle, deg; pixels over AGREE_DEG; largest height difference / the untiled
    heights' range) between `process --memory` and untiled `process`, where the untiled run has
    a normal."""
    worst, over = 0.0, 0
    xyz = ("X", "Y", "Z")     # the untiled file has the uncertainty too, the banded one not
    a, b = read_exr(Path(untiled_dir) / "normal.exr", xyz)[0], read_exr(Path(memory_dir) / "normal.exr", xyz)[0]
    mask = np.linalg.norm(a, axis=-1) > 0.5
    for r0 in range(0, mask.shape[0], BAND_ROWS):
        sl = slice(r0, r0 + BAND_ROWS)
        apart = _angles_deg(a[sl][mask[sl]], b[sl][mask[sl]])
        worst = max(worst, float(apart.max(initial=0.0)))
        over += int((apart > AGREE_DEG).sum())
    del a, b
    ha, hb = read_exr(Path(untiled_dir) / "height.exr")[0][..., 0], read_exr(Path(memory_dir) / "height.exr")[0][..., 0]
    span = float(np.ptp(ha[mask])) if mask.any() else 0.0
    return worst, over, float(np.abs(ha - hb)[mask].max(initial=0.0)) / span if span > 0 else float("nan")


def scan_size(size, work, memory, method, untiled, outputs="normals,height"):
    """The slab as a scan directory: untiled `process` against `process --memory`."""
    w, h = size
    folder = work / f"slab_{w}x{h}"
    scan = work / f"scan_{w}x{h}"
    row = dict(size=f"{w}x{h}", mp=w * h / 1e6)
    if not (scan / "scan.json").is_file():
        shutil.rmtree(scan, ignore_errors=True)
        _, row["gen_s"], row["gen_gb"] = _run_rss(_measured(SELF + ["--_scan", folder, scan]))
    else:
        row["gen_s"] = row["gen_gb"] = float("nan")
    # green in every run (--memory solves the default mean too): figures comparable with earlier rounds
    base = FACETTE + ["process", scan, "--outputs", outputs, "--method", method, "--channels", "green",
                      "--overwrite", "-o"]
    out_u, out_m = work / f"scan_untiled_{w}x{h}", work / f"scan_memory_{w}x{h}"
    if untiled:
        stdout, row["untiled_s"], row["untiled_gb"] = _run_rss(_measured(base + [out_u]))
    stdout, row["mem_s"], row["mem_gb"] = _run_rss(_measured(base + [out_m, "--memory", memory]))
    bands = re.search(r"over (\d+) bands? of (\d+) rows", stdout)
    row["mem_tiles"] = int(bands.group(1)) if bands else -1
    row["mem_deg"], row["mem_over"], row["mem_height"] = (
        _compare_process(out_u, out_m) if untiled else (float("nan"), -1, float("nan")))
    row["brdf_rel"] = float("nan")
    if untiled and (out_u / "brdf.json").is_file() and (out_m / "brdf.json").is_file():
        a, b = (json.loads((d / "brdf.json").read_text())["parameters"] for d in (out_u, out_m))
        row["brdf_rel"] = max(float(np.max(np.abs(np.asarray(b[k]) - np.asarray(a[k])) / np.abs(np.asarray(a[k]))))
                              for k in a)
    row["relight"] = _same_relight(out_u, out_m) if untiled else "-"
    return row


def _same_relight(out_u, out_m):
    """relight.ptm and relight.rti of both runs: "=" the same bytes, else the bytes that differ
    ("-": neither file)."""
    said = []
    for name in ("relight.ptm", "relight.rti"):
        if (out_u / name).is_file() and (out_m / name).is_file():
            a, b = (np.fromfile(d / name, np.uint8) for d in (out_u, out_m))
            said.append("=" if a.size == b.size and np.array_equal(a, b) else
                        str(int(np.count_nonzero(a != b)) if a.size == b.size else "size"))
    return "/".join(said) or "-"


def _kill_seconds(text, row):
    """--kill-worker's seconds: S, or S% of the `--memory` run's wall seconds (row["mem_s"])."""
    text = str(text).strip()
    return float(text[:-1]) / 100 * row["mem_s"] if text.endswith("%") else float(text)


def run_dask(row, size, work, memory, method, kill_worker, kind="scan"):
    """The `--memory` run of the scan (kind "scan") or the folder ("slab") again on a LocalCluster;
    compared with the untiled run when there is one, else with that `--memory` run."""
    w, h = size
    out = work / f"{'scan_' if kind == 'scan' else ''}dask_{w}x{h}"
    kill_after = _kill_seconds(kill_worker, row)
    stdout, wall, gb = _run_rss(_measured(SELF + ["--_dask", work / f"{kind}_{w}x{h}", out, memory, method,
                                                  str(kill_after)]))
    info = json.loads(stdout.strip().splitlines()[-1])
    row.update(dask_s=info["seconds"], dask_gb=gb, dask_workers_gb=max(info["workers_gb"]), dask_killed=info["killed"],
               dask_kill_s=float("nan") if info["kill_s"] is None else info["kill_s"], dask_lost=info["lost"],
               dask_lost_tasks=",".join(info["lost_tasks"]) or "-")
    prefix = "scan_" if kind == "scan" else ""
    untiled, memory_dir = work / f"{prefix}untiled_{w}x{h}", work / f"{prefix}memory_{w}x{h}"
    row["dask_ref"] = "untiled" if "untiled_s" in row else "--memory"
    row["dask_deg"], row["dask_over"], row["dask_height"] = _compare_process(
        untiled if "untiled_s" in row else memory_dir, out)
    return row


def _print_scan(rows, memory, outputs):
    print(f"scan directories (hdr/ EXR + _var.exr), process --outputs {outputs}; --memory {memory}")
    print(f"{'size':>12} {'MP':>6} | {'to scan s':>9} | {'untiled s':>9} {'s/MP':>5} {'GB':>5} | "
          f"{'--memory s':>10} {'s/MP':>5} {'GB':>5} {'bands':>5} | {'max°':>8} {'px > 0.01°':>10} {'height/range':>12} "
          f"{'brdf rel':>8} {'ptm/rti':>7}")
    for r in rows:
        u = r.get("untiled_s", float("nan"))
        print(f"{r['size']:>12} {r['mp']:6.1f} | {r['gen_s']:9.1f} | {u:9.1f} {u / r['mp']:5.2f} "
              f"{r.get('untiled_gb', float('nan')):5.2f} | {r['mem_s']:10.1f} {r['mem_s'] / r['mp']:5.2f} "
              f"{r['mem_gb']:5.2f} {r['mem_tiles']:5d} | {r['mem_deg']:8.5f} {r['mem_over']:10d} "
              f"{r['mem_height']:12.2e} {r['brdf_rel']:8.1e} {r.get('relight', '-'):>7}", flush=True)
    print_dask(rows, "same")


def one_size(size, work, memory, method, untiled):
    w, h = size
    mp = w * h / 1e6
    folder = work / f"slab_{w}x{h}"
    if (folder / "mask.png").is_file():       # written last, when every image is complete
        gen_s = gen_gb = float("nan")          # a slab kept from an earlier run (--keep): reused
    else:
        _, gen_s, gen_gb = _run_rss(_measured(SELF + ["--_generate", folder, str(w), str(h)]))
    row = dict(size=f"{w}x{h}", mp=mp, gen_s=gen_s, gen_gb=gen_gb)
    exr = None
    if untiled:
        out = work / f"untiled_{w}x{h}"
        stdout, wall, gb = _run_rss(_measured(FACETTE + ["process", folder, "-o", out, "--outputs",
                                                         "normals,height", "--method", method,
                                                         "--channels", "green", "--overwrite"]))
        times = _times(stdout)
        row.update(untiled_s=wall, untiled_gb=gb, untiled_load=times.get("load", float("nan")),
                   untiled_ps=times.get("ps", float("nan")))
        exr = out / "normal.exr"
    out_mem = work / f"memory_{w}x{h}"
    stdout, wall, gb = _run_rss(_measured(FACETTE + ["process", folder, "-o", out_mem, "--outputs", "normals,height",
                                                     "--method", method, "--channels", "green", "--memory", memory,
                                                     "--overwrite"]))
    bands = re.search(r"over (\d+) bands? of (\d+) rows", stdout)
    row.update(mem_s=wall, mem_cpu=LAST_CPU[0], mem_gb=gb, mem_tiles=int(bands.group(1)) if bands else -1,
               mem_ps=_times(stdout).get("ps", float("nan")))
    row["mem_deg"], row["mem_over"], row["mem_height"] = (
        _compare_process(exr.parent, out_mem) if exr is not None else (float("nan"), -1, float("nan")))
    nan = float("nan")
    if PS_METHODS.canonical(method) not in TILED_METHODS:     # ps_tiled solves each band on its own: no model
        row.update(tiled_s=nan, tiled_gb=nan, tiles=-1, rows=-1, tiled_stage=nan, tiled_ps=nan, over=-1,
                   err_tiled=_truth_error(folder, out_mem / "normal.exr"), tiled_vs_untiled=nan,
                   err_untiled=nan if exr is None else _truth_error(folder, exr))
        return row
    npy = work / f"tiled_{w}x{h}.npy"
    stdout, wall, gb = _run_rss(_measured(SELF + ["--_tiled", folder, npy, memory, method]), ALLOCATOR_ENV)
    info = json.loads(stdout.strip().splitlines()[-1])
    row.update(tiled_s=wall, tiled_gb=gb, tiles=info["tiles"], rows=info["rows_per_tile"],
               tiled_stage=info["staging_s"], tiled_ps=info["read_s"] + info["ps_s"])
    row["err_tiled"], row["err_untiled"], row["tiled_vs_untiled"], row["over"] = _compare(folder, npy, exr)
    return row


def _header(memory, method):
    print(f"method {method}, tiled budget {memory}; peak = the child process's max RSS; "
          "s/MP = wall seconds per megapixel")
    print(f"{'size':>12} {'MP':>6} | {'gen s':>6} {'GB':>5} | {'untiled s':>9} {'s/MP':>5} {'GB':>5} "
          f"{'(load':>6} {'ps)':>5} | {'tiled s':>7} {'s/MP':>5} {'GB':>5} {'tiles':>5} {'(stage':>6} {'ps)':>5} | "
          f"{'err° untiled':>12} {'tiled':>6} {'max° tiled-untiled':>18} {'px > 0.01°':>10} | "
          f"{'process --memory s':>18} {'CPU s':>6} {'s/MP':>5} {'GB':>5} {'bands':>5} {'(ps)':>5} {'max°':>8} "
          f"{'px > 0.01°':>10} {'height/range':>12}")


def _print(rows):
    for r in rows:
        u = r.get("untiled_s", float("nan"))
        print(f"{r['size']:>12} {r['mp']:6.1f} | {r['gen_s']:6.1f} {r['gen_gb']:5.2f} | {u:9.1f} "
              f"{u / r['mp']:5.2f} {r.get('untiled_gb', float('nan')):5.2f} "
              f"{r.get('untiled_load', float('nan')):6.1f} {r.get('untiled_ps', float('nan')):5.1f} | "
              f"{r['tiled_s']:7.1f} {r['tiled_s'] / r['mp']:5.2f} {r['tiled_gb']:5.2f} {r['tiles']:5d} "
              f"{r['tiled_stage']:6.1f} {r['tiled_ps']:5.1f} | "
              f"{r['err_untiled']:12.3f} {r['err_tiled']:6.3f} {r['tiled_vs_untiled']:18.5f} {r['over']:10d} | "
              f"{r['mem_s']:18.1f} {r.get('mem_cpu', float('nan')):6.1f} {r['mem_s'] / r['mp']:5.2f} {r['mem_gb']:5.2f} "
              f"{r['mem_tiles']:5d} "
              f"{r['mem_ps']:5.1f} {r['mem_deg']:8.5f} {r['mem_over']:10d} {r['mem_height']:12.2e}",
              flush=True)


def no_flag(size, work, kind="slab"):
    """`facette process SLAB -o OUT --outputs normals,height` with no flag at all, as a user runs it:
    the default method and the default memory budget (pipeline._budget); prints wall s, s/MP, peak,
    the method that ran and the budget's note. kind: "slab" (the folder) or "scan" (its scan directory)."""
    w, h = size
    out = work / f"noflag_{'' if kind == 'slab' else 'scan_'}{w}x{h}"
    stdout, wall, gb = _run_rss(_measured(FACETTE + ["process", work / f"{kind}_{w}x{h}", "-o", out, "--outputs",
                                                     "normals,height", "--overwrite"]))
    method = re.search(r"\((\w+)\)\s*$", stdout.splitlines()[0])
    err = _truth_error(work / f"slab_{w}x{h}", out / "normal.exr")      # the scan is the slab's too
    budget = next((line.strip()[len("note: "):] for line in stdout.splitlines() if "note: memory:" in line), "")
    print(f"no flag {'' if kind == 'slab' else 'scan '}{w}x{h}: {wall:.1f} s, {LAST_CPU[0]:.1f} CPU s, "
          f"{wall / (w * h / 1e6):.2f} s/MP ({LAST_CPU[0] / (w * h / 1e6):.2f} CPU s/MP), peak {gb:.2f} GB, "
          f"{err:.3f}° to the truth, {method.group(1) if method else '?'}; {budget}", flush=True)


def only_no_flag(size, work, scan, whole=False):
    """The no-flag run alone, of the folder or (scan) its scan directory, each written when missing;
    whole: then the same capture read whole, and the two compared (`_size_whole`)."""
    folder, scan_dir = (work / f"{kind}_{size[0]}x{size[1]}" for kind in ("slab", "scan"))
    if not (folder / "mask.png").is_file():
        _run_rss(_measured(SELF + ["--_generate", folder, *map(str, size)]))
    if scan and not (scan_dir / "scan.json").is_file():
        shutil.rmtree(scan_dir, ignore_errors=True)
        _run_rss(_measured(SELF + ["--_scan", folder, scan_dir]))
    no_flag(size, work, "scan" if scan else "slab")
    if whole:
        src, tag = (scan_dir, "scan_") if scan else (folder, "")
        against_whole(src, work / f"noflag_{tag}{size[0]}x{size[1]}", work / f"whole_{tag}{size[0]}x{size[1]}",
                      lambda cmd: (*_run_rss(_measured(cmd)), LAST_CPU[0]))


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--_rss"]:
        return _rss_wrapper(argv[2:])
    if argv[:1] == ["--_generate"]:
        write_relief_capture(argv[1], int(argv[2]), int(argv[3]))
        return 0
    if argv[:1] == ["--_scan"]:
        slab_to_scan(argv[1], argv[2])
        return 0
    if argv[:1] == ["--_dask"]:
        dask_child(argv[1], argv[2], argv[3], argv[4], float(argv[5]))
        return 0
    if argv[:1] == ["--_tiled"]:
        _tiled_child(*argv[1:5])
        return 0
    p = argparse.ArgumentParser(prog="facette bench size", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default=DEFAULT_SIZES,
                   help=f"megapixels ({', '.join(SIZES)}) or WxH, comma-separated (default {DEFAULT_SIZES})")
    p.add_argument("--memory", default="2GB", help="the tiled run's memory budget (default 2GB)")
    p.add_argument("--method", default=PS_DEFAULT, help=f"a per-pixel method (default {PS_DEFAULT})")
    p.add_argument("--no-untiled", action="store_true", help="skip the untiled `facette process`")
    p.add_argument("--untiled-max-mp", type=float, default=UNTILED_MAX_MP,
                   help=f"skip the untiled run above this size (default {UNTILED_MAX_MP:g} MP)")
    p.add_argument("--scan", action="store_true", help="also process the slab as a scan directory (EXR), "
                                                        "untiled and with --memory")
    p.add_argument("--only-scan", action="store_true", help="the scan directory's table alone")
    p.add_argument("--scan-outputs", default="normals,height",
                   help="the scan runs' --outputs (with normals and height; default normals,height)")
    p.add_argument("--dask", action="store_true", help="the scan's (with --scan; else the folder's) --memory run "
                                                        "again on a LocalCluster of 2 workers x 1 thread")
    p.add_argument("--kill-worker", default="0", metavar="S",
                   help="with --dask: kill one worker S seconds into the run (S%%: S %% of the --memory run's "
                        "wall seconds), the first then holding tasks (default: none)")
    p.add_argument("--no-flag", action="store_true", help="also `facette process SLAB` (and SCAN with "
                                                           "--scan) with no flag (the default method and budget)")
    p.add_argument("--only-no-flag", action="store_true", help="the no-flag run alone (with --scan: the scan "
                                                                "directory's), its capture written when missing")
    p.add_argument("--against-whole", action="store_true", help="with --only-no-flag: then the capture read whole "
                                                                 "(--memory its whole reading), the normals compared")
    p.add_argument("--keep", help="keep the captures and results in this folder (default: temporary); "
                                  "a slab already there is reused")
    args = p.parse_args(argv)
    sizes = [_size(s.strip()) for s in args.sizes.split(",") if s.strip()]
    rows, scan_rows = [], []
    if not (args.only_scan or args.only_no_flag):
        _header(args.memory, args.method)
    with tempfile.TemporaryDirectory(prefix="facette-bench-size-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for size in sizes:
            untiled = not args.no_untiled and size[0] * size[1] / 1e6 <= args.untiled_max_mp
            if args.only_no_flag:
                only_no_flag(size, work, args.scan, args.against_whole)
                continue
            if args.only_scan:
                if not (work / f"slab_{size[0]}x{size[1]}" / "mask.png").is_file():
                    _run_rss(_measured(SELF + ["--_generate", work / f"slab_{size[0]}x{size[1]}", *map(str, size)]))
            else:
                rows.append(one_size(size, work, args.memory, args.method, untiled))
                _print(rows[-1:])
                if args.no_flag:
                    no_flag(size, work)
                if args.dask and not (args.scan or args.only_scan):
                    run_dask(rows[-1], size, work, args.memory, args.method, args.kill_worker, "slab")
                    print_dask(rows[-1:], "folder's --memory run")
            if args.scan or args.only_scan:
                scan_rows.append(scan_size(size, work, args.memory, args.method, untiled, args.scan_outputs))
                if args.no_flag:
                    no_flag(size, work, "scan")
                if args.dask:
                    run_dask(scan_rows[-1], size, work, args.memory, args.method, args.kill_worker)
        if scan_rows:
            _print_scan(scan_rows, args.memory, args.scan_outputs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
