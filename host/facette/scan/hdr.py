"""Scan-directory HDR: raw/*.dng listed in scan.json -> hdr/light_XX.exr (+ _var.exr).

The merge itself is `facette.hdr.merge` on arrays; this module reads and writes the scan
directory around it, through `ScanDirectory` (the one reader and writer of scan.json).

The files (docs/scan-format.md, "hdr/"): ``hdr/light_XX.exr`` holds R, G, B linear radiance per unit
exposure, per µs·mA (black-subtracted DN / (exposure time µs × LED current mA)),
float32, at RAW half-size; ``hdr/light_XX_var.exr`` the variances (DN / (µs·mA))².
The merge is recorded in scan.json under ``"hdr"``.
"""
from __future__ import annotations

import datetime as _dt
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from facette.camera.raw import read_raw
from facette.hdr import as_sensor, merge, n_workers
from facette.io.checksum import sha256_file
from facette.io.exr import read_exr, write_exr
from facette.scan.directory import ScanDirectory, read_scan_manifest
from facette.scan.manifest import Hdr, HdrLight, Manifest

__all__ = ["merge_scan", "merge_light", "LightMerger", "HeldLight", "store_light_records", "hdr_up_to_date", "stale_lights", "hdr_record", "scan_sensor", "light_frames",
           "load_hdr", "read_scan_manifest", "frame_exposure", "MissingFrameWarning",
           "HDR_UNIT"]

HDR_UNIT = "DN/(us*mA)"



class HeldLight:
    """A light merged in this process, kept in memory for the processing that follows the scan
    (`ScanDirectory.hold_light`): the radiance as stored (float32) and the green variance, NaN
    where any channel's variance is not finite, with the `_stat` of the two files written.
    At 4288x2848, reading the 12 lights' EXR pairs back costs ~2 CPU s after the last frame."""

    def __init__(self, img_path, var_path, radiance, variance, written):
        var = np.asarray(variance, np.float32)
        green = np.array(var[..., 1])
        green[~(np.isfinite(var[..., 0]) & np.isfinite(var[..., 1]) & np.isfinite(var[..., 2]))] = np.nan
        self.paths = (Path(img_path), Path(var_path))
        self.written = tuple(written)
        self.radiance, self.green = np.asarray(radiance, np.float32), green

    def arrays(self):
        """(radiance, green variance) when both files are unchanged since they were written (as
        `hdr_up_to_date` judges them: size and mtime), else None (then read the files)."""
        return (self.radiance, self.green) if self.unchanged() else None

    def unchanged(self):
        """Both files are as they were written (size and mtime)."""
        try:
            return tuple(_stat(p) for p in self.paths) == self.written
        except OSError:
            return False

    def release(self):
        """Drop the arrays (once copied); `unchanged` still answers."""
        self.radiance = self.green = None


class MissingFrameWarning(UserWarning):
    """A frame listed in scan.json (or an exposure of the plan) is not on disk."""


def frame_exposure(frame, current="measured"):
    """Exposure of a scan.json frame record (a `Frame` or its JSON object) in µs·mA, and the
    current used (mA).

    `current`: "measured" uses current_meas_mA when it is a positive number (falls
    back to current_set_mA), "set" always uses current_set_mA.
    """
    get = frame.get if isinstance(frame, dict) else lambda key: getattr(frame, key)
    t_us = float(get("time_us"))
    meas, setc = get("current_meas_mA"), get("current_set_mA")
    if current == "measured" and meas is not None and float(meas) > 0:
        i_ma = float(meas)
    elif setc is not None and float(setc) > 0:
        i_ma = float(setc)
    else:
        raise ValueError(f"frame {get('file')} records no positive LED current "
                         f"(current_set_mA={setc}, current_meas_mA={meas}); cannot express its "
                         "exposure per µs·mA")
    if not t_us > 0:
        raise ValueError(f"frame {get('file')} has exposure time {t_us} µs; must be > 0")
    return t_us * i_ma, i_ma


def _basis(method, current, per, sens):
    """What, besides the frames, an HDR image depends on: redo it when any of these changes."""
    return {"method": method, "current": current if per == "us*mA" else None,
            "unit": HDR_UNIT if per == "us*mA" else "DN/us", "sensor": sens.to_profile_dict()}


def _stat(path):
    st = path.stat()
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def light_frames(data, light):
    """`Frame`s of one light, by exposure index (`data`: a Manifest or scan.json dict)."""
    return Manifest.of(data).light_frames(light)


def hdr_up_to_date(scan_dir, data, record, basis=None):
    """True when the HDR files of a light record exist and were made from the frames
    scan.json lists now (same files, same sha256, unchanged on disk) and, if given, with
    the same `basis` (method, unit, current, sensor). `record`: an `HdrLight` (or its JSON object)."""
    scan_dir = Path(scan_dir)
    data = Manifest.of(data)
    record = HdrLight.from_json(record)
    if basis is not None and record.basis != basis:
        return False
    if not all((scan_dir / (f or "")).is_file() for f in (record.file, record.var_file)):
        return False
    inputs = record.inputs
    if not inputs:
        return False
    if {i["file"]: i["sha256"] for i in inputs} != _synced_sha256(data, record.index):
        return False   # a frame was re-shot, added or lost since the merge
    for i in inputs:   # a file touched after the merge: let the sha256 check decide
        p = scan_dir / i["file"]
        if not p.is_file() or _stat(p) != {"size": i["size"], "mtime_ns": i["mtime_ns"]}:
            return False
    # the HDR files themselves, edited or damaged since the merge wrote them
    return all(_stat(scan_dir / rel) == st for rel, st in (record.outputs or {}).items())


def _synced_sha256(data, light):
    """{file: sha256} of a light's frames taken with their flash sync."""
    return {f.file: f.sha256 for f in light_frames(data, light) if f.synced}


def stale_lights(scan_dir, data):
    """Why each light's HDR files cannot be used as they are: {light: reason}, only for lights
    whose files exist (a missing one is simply merged) and can be merged again from raw/."""
    scan_dir = Path(scan_dir)
    data = Manifest.of(data)
    records = data.hdr_lights()
    out = {}
    for li in data.frame_lights():
        rec, name = records.get(li), f"hdr/light_{li:02d}.exr"
        if not (scan_dir / name).is_file() or not _stale(scan_dir, data, li, rec, None):
            continue
        now = _synced_sha256(data, li)
        if rec is None or not rec.inputs:
            out[li] = f"{name} has no record of the frames it was merged from: merged again"
        elif {i["file"]: i["sha256"] for i in rec.inputs} != now:
            out[li] = (f"{name} was merged from other frames ({len(rec.inputs)} then, {len(now)} "
                       "now): merged again")
        elif any(_stat(scan_dir / r) != st for r, st in (rec.outputs or {}).items()
                 if (scan_dir / r).is_file()):
            out[li] = f"{name} changed since it was merged: merged again from raw/"
    return out


def _stale(scan_dir, data, light, record, basis):
    """Does this light need a merge? Yes unless its HDR is up to date, or its HDR files are
    all there is (no RAW frame of it on disk: a scan copied without raw/)."""
    if record is not None and hdr_up_to_date(scan_dir, data, record, basis):
        return False
    has_raw = any((scan_dir / f.file).is_file() for f in light_frames(data, light))
    name = scan_dir / "hdr" / f"light_{int(light):02d}"
    has_hdr = Path(f"{name}.exr").is_file() and Path(f"{name}_var.exr").is_file()
    return has_raw or not has_hdr


def _read_frame(scan_dir, fr, verify_sha256):
    """Decode one frame (and check its sha256 on the same thread): (`Frame`, RawFrame, input)."""
    path = scan_dir / fr.file
    digest = sha256_file(path)
    if verify_sha256 and fr.sha256 and digest != fr.sha256:
        raise ValueError(f"{path} does not match the sha256 recorded in scan.json: the "
                         "file changed after capture; re-shoot that frame or restore it")
    return fr, read_raw(path), {"file": fr.file, "sha256": digest, **_stat(path)}


def merge_light(scan_dir, data, light, sensor=None, method="inverse_variance", current="measured",
                verify_sha256=True, per="us*mA", workers=None):
    """Merge one light of a scan into hdr/light_XX.exr and _var.exr; returns its record.

    `data` is the scan's `Manifest` (or its scan.json dict), read by the caller, who also
    stores the record: this function writes only the two EXR files. The record lists the inputs (file, sha256,
    size, mtime) and the `basis` (method, unit, current, sensor), so that
    `hdr_up_to_date` can tell whether the files still describe the frames.
    Frames are decoded and hashed on `workers` threads (None: one per core, at most 4).
    """
    return _merge_light(scan_dir, data, light, sensor, method, current, verify_sha256, per, workers)[0]


def _merge_light(scan_dir, data, light, sensor, method, current, verify_sha256, per, workers,
                 hold=False):
    """`merge_light`: (record, `HeldLight` of what was written, or None without `hold`)."""
    scan_dir = Path(scan_dir)
    data = Manifest.of(data)
    sens = as_sensor(sensor)
    li = int(light)
    n_exposures = len(data.exposures)
    frames_rec = light_frames(data, li)
    recorded = {int(f.exposure) for f in frames_rec}
    missing = [{"exposure": e, "file": None, "reason": "not captured"}
               for e in range(n_exposures) if e not in recorded]
    todo = []
    for fr in frames_rec:
        if not fr.synced:  # the camera's flash sync never came: not a real frame
            missing.append({"exposure": int(fr.exposure), "file": fr.file, "reason": "no flash sync"})
        elif not (scan_dir / fr.file).is_file():
            missing.append({"exposure": int(fr.exposure), "file": fr.file, "reason": "file missing"})
        else:
            todo.append(fr)
    if missing:
        warnings.warn(f"light {li}: merging without {len(missing)} exposure(s) "
                      f"{[m['exposure'] for m in missing]} ({missing[0]['reason']})",
                      MissingFrameWarning, stacklevel=3)
    if not todo:
        raise FileNotFoundError(f"light {li} has no RAW frame on disk in {scan_dir / 'raw'}; "
                                "re-run the scan for that light")
    t0 = time.perf_counter()
    n_threads = n_workers(workers, len(todo))
    with ThreadPoolExecutor(n_threads) as pool:
        frames = list(pool.map(lambda fr: _read_frame(scan_dir, fr, verify_sha256), todo))
    t_read = time.perf_counter() - t0
    exposures = [frame_exposure(fr, current)[0] if per == "us*mA" else float(fr.time_us)
                 for fr, _, _ in frames]
    times_s = [float(fr.time_us) * 1e-6 for fr, _, _ in frames]
    try:
        res = merge([rf for _, rf, _ in frames], exposures, sens, method=method, times_s=times_s,
                    workers=workers)
    except ValueError as exc:
        raise ValueError(f"light {li} of {scan_dir}: {exc} (files "
                         f"{[fr.file for fr, _, _ in frames]})") from exc
    inputs = [inp for _, _, inp in frames]
    del frames[:]    # the RawFrames (7 × 2 × 36 MB at 12 MP) are no longer needed
    t_merge = time.perf_counter() - t0 - t_read
    basis = _basis(method, current, per, sens)
    name = f"light_{li:02d}"
    attrs = {"facette_unit": basis["unit"], "facette_method": method, "facette_light": str(li)}
    (scan_dir / "hdr").mkdir(exist_ok=True)
    # Uncompressed: ZIP saves 1 % on noisy float radiance and takes 13× longer.
    write_exr(scan_dir / "hdr" / f"{name}.exr", res.radiance, ("R", "G", "B"), attrs,
              compression="none")
    write_exr(scan_dir / "hdr" / f"{name}_var.exr", res.variance, ("R", "G", "B"),
              dict(attrs, facette_unit=f"({basis['unit']})^2"), compression="none")
    outputs = {rel: _stat(scan_dir / rel) for rel in (f"hdr/{name}.exr", f"hdr/{name}_var.exr")}
    held = HeldLight(scan_dir / "hdr" / f"{name}.exr", scan_dir / "hdr" / f"{name}_var.exr",
                     res.radiance, res.variance, outputs.values()) if hold else None
    return HdrLight(index=li, file=f"hdr/{name}.exr", var_file=f"hdr/{name}_var.exr",
                    frames=tuple(fr.file for fr in todo), inputs=tuple(inputs), outputs=outputs,
                    missing=tuple(missing), basis=basis, saturated_fraction=float(res.saturated.mean()),
                    no_sample_fraction=float(np.mean(res.n_used == 0)),
                    time_s={"read": round(t_read, 3), "merge": round(t_merge, 3),
                            "write": round(time.perf_counter() - t0 - t_read - t_merge, 3)}), held


def hdr_record(records, basis, source, merge_time_s):
    """scan.json's "hdr" section (an `Hdr`) from per-light `HdrLight` records (sorted by light)."""
    return Hdr(method=basis["method"], unit=basis["unit"], current=basis["current"],
               resolution="half-size", sensor=basis["sensor"], sensor_source=source,
               lights=tuple(sorted((HdrLight.from_json(r) for r in records), key=lambda r: r.index)),
               merge_time_s=round(merge_time_s, 3),
               created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))


def scan_sensor(data, sensor=None):
    """(noise model, where it came from): `sensor`, else scan.json's, else the nominal one."""
    data = Manifest.of(data)
    if sensor is not None:
        return as_sensor(sensor), "given"
    if isinstance(data.sensor, dict):
        return as_sensor(data.sensor), "scan.json sensor"
    if isinstance(data.profile, dict):
        return as_sensor(None), (f"nominal: profile {data.profile.get('id')} has no sensor section "
                                 "(its noise model was never calibrated)")
    return as_sensor(None), "nominal (no profile given)"


class LightMerger:
    """Merge lights on a worker thread while a scan goes on (merge during acquisition).

    `submit(data, light)` queues a light whose frames have all landed (`data`: the scan's
    `Manifest` at that moment, frames hashed); `collect()` returns the finished lights' records
    (or the exception a merge raised) for the caller to store in scan.json: the worker
    writes only hdr/light_XX*.exr, never scan.json, so the scan directory keeps one writer.
    With `hold`, each finished light also comes with its `HeldLight` (the arrays it wrote).
    """

    def __init__(self, scan_dir, sensor=None, method="inverse_variance", current="measured",
                 workers=None, hold=False):
        self.scan_dir = Path(scan_dir)
        self.sensor, self.method, self.current, self.workers = sensor, method, current, workers
        self.hold = hold
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="hdr-merge")
        self._futures = {}
        self.submitted = []

    def basis(self, data):
        """The basis (method, unit, current, sensor) a merge of this scan gets."""
        sens, _ = scan_sensor(data, self.sensor)
        return _basis(self.method, self.current, "us*mA", sens)

    def stale(self, data, light):
        """True when `light` has no HDR that describes its frames now (see `hdr_up_to_date`)."""
        data = Manifest.of(data)
        return _stale(self.scan_dir, data, light, data.hdr_lights().get(int(light)), self.basis(data))

    def submit(self, data, light):
        light = int(light)
        if light in self._futures:
            return
        data = Manifest.of(data).snapshot()   # the scan goes on writing its own
        sens, _ = scan_sensor(data, self.sensor)

        def work():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", MissingFrameWarning)   # recorded in "missing"
                return _merge_light(self.scan_dir, data, light, sens, self.method, self.current,
                                    True, "us*mA", self.workers, hold=self.hold)

        self._futures[light] = self._pool.submit(work)
        self.submitted.append(light)

    def collect(self, wait=False):
        """[(light, record or Exception, HeldLight or None)] of the merges finished (all of
        them with `wait`)."""
        out = []
        for light, fut in list(self._futures.items()):
            if wait or fut.done():
                try:
                    out.append((light, *fut.result()))
                except Exception as exc:   # the scan goes on; `facette process` merges it again
                    out.append((light, exc, None))
                del self._futures[light]
        return out

    def close(self):
        self._pool.shutdown(wait=True, cancel_futures=True)


def store_light_records(data, records, basis, source):
    """scan.json's "hdr" with `records` (per-light, from `merge_light`) added or replaced;
    records of another basis are dropped (they no longer describe a merge of this kind)."""
    old = {i: r for i, r in Manifest.of(data).hdr_lights().items() if r.basis == basis}
    old.update({r.index: r for r in (HdrLight.from_json(x) for x in records)})
    total = sum(r.seconds() for r in old.values())
    return hdr_record(list(old.values()), basis, source, total)


def merge_scan(scan_dir, sensor=None, method="inverse_variance", current="measured",
               verify_sha256=True, lights=None, per="us*mA", force=False, workers=None):
    """Merge every light of a scan directory into hdr/light_XX.exr and hdr/light_XX_var.exr.

    Parameters
    ----------
    scan_dir : path with scan.json and raw/ (docs/scan-format.md)
    sensor : SensorModel, profile sensor dict, facette.calib Profile, or None
        Noise model; None uses scan.json's "sensor" dict when the scan recorded
        one, else the nominal simulated sensor (recorded as such).
    method : str
        A `facette.hdr.MERGE_METHODS` name.
    current : {"measured", "set"}
        Which LED current defines the exposure (see `frame_exposure`).
    verify_sha256 : bool
        Refuse a frame whose file no longer matches the sha256 recorded at capture.
    lights : iterable of int or None
        Only these light indices (default all lights with frames).
    per : {"us*mA", "us"}
        Unit of exposure: µs·mA (docs/scan-format.md, default) or µs alone (the LED current
        ignored, e.g. for a constant-current rig whose currents are not recorded).
    force : bool
        Merge again even the lights whose HDR files are up to date (made from the same
        frames, unchanged on disk, with the same method, unit and sensor); by default
        those are kept, so a scan merged during acquisition is not merged twice.
    workers : int or None
        Threads for decoding and merging (None: one per core, at most 4).

    Returns
    -------
    Hdr: the ``"hdr"`` record also written into scan.json; each light's `HdrLight` says
    what it was made from (``inputs``, ``basis``).

    A frame listed in scan.json whose file is missing, or recorded with
    ``"sync": false``, is skipped with a `MissingFrameWarning` and recorded under
    ``missing``; a light with no usable frame at all raises FileNotFoundError;
    frames of different sizes raise ValueError naming the light and files.
    """
    if per not in ("us*mA", "us"):
        raise ValueError(f"per must be 'us*mA' or 'us', got {per!r}")
    scan_dir = Path(scan_dir)
    sd = ScanDirectory.existing(scan_dir)
    data = sd.manifest
    sens, source = scan_sensor(data, sensor)
    basis = _basis(method, current, per, sens)
    ids = data.frame_lights()
    wanted = ids if lights is None else sorted(int(i) for i in lights)
    old = data.hdr_lights()
    todo = [li for li in wanted if force or _stale(scan_dir, data, li, old.get(li), basis)]
    if not todo:
        return data.hdr or hdr_record(list(old.values()), basis, source, 0.0)
    sd.journal("hdr_begin", method=method, lights=todo)
    t0 = time.perf_counter()
    records = [merge_light(scan_dir, data, li, sens, method, current, verify_sha256, per, workers)
               for li in todo]
    record = store_light_records(data, records, basis, source)
    record = record.replace(merge_time_s=round(time.perf_counter() - t0, 3))
    sd.record_hdr(record)
    sd.journal("hdr_done", lights=todo, merge_time_s=record.merge_time_s)
    return record


def load_hdr(scan_dir, sensor=None, merge_missing=True, method="inverse_variance"):
    """Load a scan's HDR images for the pipeline.

    Returns
    -------
    images : ndarray (m, H, W, 3) float32, radiance per µs·mA
    variances : ndarray (m, H, W, 3) float32
    lights : list of m `Light` records of the manifest (index, direction, position_mm,
        intensity), in the order of `images`.

    With `merge_missing`, `merge_scan` runs first with `sensor` and `method`: it merges
    the lights whose HDR files are absent or no longer describe their RAW frames, and
    nothing when all are up to date.
    """
    scan_dir = Path(scan_dir)
    data = read_scan_manifest(scan_dir)
    lights = sorted(data.lights, key=lambda l: int(l.index))
    light_ids = data.frame_lights()
    paths = {li: (scan_dir / "hdr" / f"light_{li:02d}.exr",
                  scan_dir / "hdr" / f"light_{li:02d}_var.exr") for li in light_ids}
    if merge_missing:
        merge_scan(scan_dir, sensor=sensor, method=method)
    absent = [li for li, (p, v) in paths.items() if not (p.is_file() and v.is_file())]
    if absent:
        raise FileNotFoundError(f"{scan_dir / 'hdr'} lacks lights {absent}; run "
                                "facette.scan.merge_scan(scan_dir) first")
    by_index = {int(l.index): l for l in lights}
    unknown = [li for li in light_ids if li not in by_index]
    if unknown:
        raise ValueError(f"scan.json has frames for lights {unknown} that its 'lights' list "
                         "does not describe")
    images = np.stack([read_exr(paths[li][0], ("R", "G", "B"))[0] for li in light_ids])
    variances = np.stack([read_exr(paths[li][1], ("R", "G", "B"))[0] for li in light_ids])
    return images, variances, [by_index[li] for li in light_ids]
