"""Where the seconds after the last frame go: `process` on a finished scan, stage by stage.

`stage_table(scan_dir)` runs `facette.pipeline.process` with every default output on a scan
directory (its HDR read from disk: the one-button scan hands over the lights it held, so its
"load" is shorter) and wraps each stage's function to record its wall time and the process's
CPU seconds over it (every thread: numba's parallel kernels and the worker pools included).
For that the stages `process` runs two at a time run one after the other here (its thread
pools replaced by `_Inline`), so the wall times add up to more than a real run's; the CPU
seconds are each stage's own. The modules a scan preloads during its acquisition
(`pipeline.preload`) are loaded before the clock starts. "rest" is what no wrapper saw (the
record, the checks against truth, between stages). Rows "of which: ..." (`PARTS`) are parts of the
stage named after them (the shadow step's heights, li_alternating's coarse rounds, its full-size round),
counted in that stage's row too. `facette bench e2e --stages SCAN_DIR [--held held|arriving]` prints the table; `--held` gives `process` the
lights held in memory as the one-button scan does (`held_scan`), "arriving" also made into its inputs as they
arrived (pipeline._arriving): the load after the last frame of a scan, not of `facette process`.
"""
import tempfile
import threading
import time
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path

__all__ = ["stage_table", "print_stage_table"]

# (name in the table, module, function): the functions `process` calls through module globals
# (pipeline._whole: the load of the images held whole; pipeline._tiled_process: the band loop, its one band)
WRAPPED = [
    ("load", "facette.pipeline._whole", "load_input"),
    # the solve's 4-channel stack: per light with the default channels, so a candidate for the acquisition
    ("solve's channel (with_solve_channel)", "facette.pipeline._tiled_process", "with_solve_channel"),
    ("light gains", "facette.pipeline._whole", "light_gains_of_bands"),
    ("photometric stereo (shadow step)", "facette.pipeline._tiled_process", "hidden_over_bands"),
    ("photometric stereo (li_alternating's model)", "facette.pipeline._tiled_process", "band_model"),
    ("photometric stereo (solve)", "facette.pipeline._tiled_process", "photometric_stereo"),
    ("object mask", "facette.pipeline._whole", "object_of"),
    ("uncertainty", "facette.pipeline._process", "uncertainty_of"),
    # after the maps, inside the ptm / rti stage (pipeline._relight_later): counted in its row
    ("relighting files' set-up (their exposure)", "facette.pipeline._process", "relight_after_maps"),
    ("integrate", "facette.pipeline._process", "integrate"),
    ("mesh", "facette.pipeline._process", "mesh_from_height"),
    ("report's relighting model", "facette.pipeline._process", "relight_model_stage"),
    ("samples", "facette.pipeline._process", "_samples_stage"),
    ("brdf fit", "facette.pipeline._process", "_fit_stage"),
    ("report: fit section", "facette.pipeline._process", "report_fit_section"),
    ("hsh / ptm fits + writes", "facette.pipeline._process", "relight_stage"),
    ("glTF maps + write", "facette.pipeline._process", "write_glb"),
    ("glTF material (the model's maps)", "facette.pipeline._process", "gltf_material"),
    ("glTF inputs", "facette.pipeline._process", "gltf_inputs"),
    ("checks against truth", "facette.pipeline._process", "truth_errors"),
    ("relighting files' exposure", "facette.pipeline._process", "record_exposure"),
    ("report's pictures", "facette.pipeline._process", "report_pictures"),
    ("report.html", "facette.pipeline._process", "write_report"),
    ("map writes (exr/png/ply/npz/json)", "facette.pipeline._process", "write_exr"),
    ("map writes (exr/png/ply/npz/json)", "facette.pipeline._process", "write_mask"),
    ("map writes (exr/png/ply/npz/json)", "facette.pipeline._process", "write_ply"),
    ("map writes (exr/png/ply/npz/json)", "facette.pipeline._process", "write_text_atomic"),
]
# parts of the stages above, recorded inside the stage they run in too (rows `WITHIN` + name + " (stage)", not
# in "rest"): where the photometric stereo's seconds go
WITHIN = "  of which: "
PARTS = [
    (WITHIN + "shadow step's heights (heights_in_pixels)", "facette.recon._shadows", "heights_in_pixels"),
    (WITHIN + "model's coarse rounds (model choice, alternation)", "facette.fit._ps_li", "_rounds"),
    (WITHIN + "solve's full-size round (fine_round)", "facette.fit._ps_li_coarse", "fine_round"),
]


class _Inline:
    """A ThreadPoolExecutor that runs each task as it is submitted, on the caller's thread."""

    def __init__(self, *args, **kwargs):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, fn, *args, **kwargs):
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as e:      # re-raised by result(), as a pool's
            future.set_exception(e)
        return future


@contextmanager
def _wrapped(table, t_start):
    """Each WRAPPED function replaced by one that adds (wall, process CPU, first start, last end)
    to table[name], process's pools by `_Inline`; the originals back on exit. A wrapped call
    inside another counts in the outer one only."""
    import importlib

    local = threading.local()
    proc = importlib.import_module("facette.pipeline._process")
    saved = [(proc, "ThreadPoolExecutor", proc.ThreadPoolExecutor)]
    proc.ThreadPoolExecutor = _Inline
    for name, mod_name, fn_name in WRAPPED + PARTS:
        mod = importlib.import_module(mod_name)
        fn = getattr(mod, fn_name)
        saved.append((mod, fn_name, fn))

        def wrapper(*a, _fn=fn, _name=name, **k):
            outer = getattr(local, "inside", None)
            if _name.startswith(WITHIN):          # a part: its row named with the stage it runs in
                key = f"{_name} ({outer or 'no stage'})"
            elif outer:
                return _fn(*a, **k)
            else:
                key = _name
            local.inside = outer or _name
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                return _fn(*a, **k)
            finally:
                local.inside = outer
                row = table.setdefault(key, [0.0, 0.0, float("inf"), 0.0])
                row[0] += time.perf_counter() - t0
                row[1] += time.process_time() - c0
                row[2] = min(row[2], t0 - t_start)
                row[3] = max(row[3], time.perf_counter() - t_start)
        setattr(mod, fn_name, wrapper)
    try:
        yield
    finally:
        for mod, fn_name, fn in saved:
            setattr(mod, fn_name, fn)


def held_scan(scan_dir, arriving=True):
    """The scan directory object of `scan_dir` as the one-button scan hands it to `process`: each light's
    HDR pair read and held (`ScanDirectory.hold_light`), and, with `arriving`, made into process's inputs as
    it arrives (`pipeline.ArrivingLights`, waited for): what the scan does before its last frame."""
    from facette.io.exr import read_exr
    from facette.pipeline import ArrivingLights
    from facette.scan import ScanDirectory
    from facette.scan.hdr import HeldLight, _stat

    sd = ScanDirectory(scan_dir)
    on_held = ArrivingLights() if arriving else None
    for rec in sd.manifest.hdr.lights:
        img, var = Path(scan_dir) / rec.file, Path(scan_dir) / rec.var_file
        sd.hold_light(rec.index, HeldLight(img, var, read_exr(img)[0], read_exr(var)[0], (_stat(img), _stat(var))))
        if on_held is not None:
            on_held(sd, rec.index)
    if on_held is not None:
        on_held.wait()
    return sd


def stage_table(scan_dir, outputs=None, held=None, **options):
    """{stage: (wall s, CPU s, start s, end s)} of one `process` of `scan_dir` (every default output
    unless `outputs`; **options: ProcessOptions fields), with "total" (wall, process CPU) and
    "rest" (the total CPU no stage recorded). Results go to a temporary folder. held: None, the scan
    read from its files; "held", its lights held in memory as the one-button scan hands them over;
    "arriving", also made into the inputs as they arrived (`held_scan`: before the clock starts)."""
    from facette.pipeline import preload, process

    preload()                 # as a scan does during its acquisition
    source = Path(scan_dir) if held is None else held_scan(scan_dir, arriving=held == "arriving")
    table = {}
    with tempfile.TemporaryDirectory(prefix="facette-stages-") as tmp:
        t0, c0 = time.perf_counter(), time.process_time()
        with _wrapped(table, t0):
            try:
                process(source, outputs=outputs, out_dir=Path(tmp) / "results", **options)
            finally:
                if held is not None:
                    source.release_held_lights()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    table = {k: tuple(v) for k, v in table.items()}
    table["rest"] = (float("nan"), cpu - sum(v[1] for k, v in table.items() if not k.startswith(WITHIN)),
                     float("nan"), float("nan"))
    table["total"] = (wall, cpu, 0.0, wall)
    return table


def print_stage_table(table):
    print("| stage | wall s | CPU s | started s | ended s |")
    print("|---|---|---|---|---|")
    rows = sorted(((k, v) for k, v in table.items() if k not in ("rest", "total")), key=lambda kv: kv[1][2])
    for k, (wall, cpu, start, end) in rows + [("rest", table["rest"]), ("total", table["total"])]:
        print(f"| {k} | {wall:.2f} | {cpu:.2f} | {start:.2f} | {end:.2f} |", flush=True)
