"""Scan-directory HDR: raw/*.dng listed in scan.json -> hdr/light_XX.exr (+ _var.exr).

The merge itself is `facette.hdr.merge` on arrays; this module reads and writes the scan
directory around it, through `ScanDirectory` (the one reader and writer of scan.json).

Contract 3 (DESIGN §7): ``hdr/light_XX.exr`` holds R, G, B linear radiance per unit
exposure, per µs·mA (black-subtracted DN / (exposure time µs × LED current mA)),
float32, at RAW half-size; ``hdr/light_XX_var.exr`` the variances (DN / (µs·mA))².
The merge is recorded in scan.json under ``"hdr"``.
"""
from __future__ import annotations

import datetime as _dt
import time
import warnings
from pathlib import Path

import numpy as np

from facette.camera.raw import read_raw
from facette.hdr import as_sensor, merge
from facette.io.checksum import sha256_file
from facette.io.exr import read_exr, write_exr
from facette.scan.directory import ScanDirectory, read_scan_manifest

__all__ = ["merge_scan", "load_hdr", "read_scan_manifest", "frame_exposure", "MissingFrameWarning",
           "HDR_UNIT"]

HDR_UNIT = "DN/(us*mA)"


class MissingFrameWarning(UserWarning):
    """A frame listed in scan.json (or an exposure of the plan) is not on disk."""


def frame_exposure(frame, current="measured"):
    """Exposure of a scan.json frame record in µs·mA, and the current used (mA).

    `current`: "measured" uses current_meas_mA when it is a positive number (falls
    back to current_set_mA), "set" always uses current_set_mA.
    """
    t_us = float(frame["time_us"])
    meas, setc = frame.get("current_meas_mA"), frame.get("current_set_mA")
    if current == "measured" and meas is not None and float(meas) > 0:
        i_ma = float(meas)
    elif setc is not None and float(setc) > 0:
        i_ma = float(setc)
    else:
        raise ValueError(f"frame {frame.get('file')} records no positive LED current "
                         f"(current_set_mA={setc}, current_meas_mA={meas}); cannot express its "
                         "exposure per µs·mA")
    if not t_us > 0:
        raise ValueError(f"frame {frame.get('file')} has exposure time {t_us} µs; must be > 0")
    return t_us * i_ma, i_ma


def merge_scan(scan_dir, sensor=None, method="inverse_variance", current="measured",
               verify_sha256=True, lights=None, per="us*mA"):
    """Merge every light of a scan directory into hdr/light_XX.exr and hdr/light_XX_var.exr.

    Parameters
    ----------
    scan_dir : path with scan.json and raw/ (contract 3)
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
        Unit of exposure: µs·mA (contract 3, default) or µs alone (the LED current
        ignored, e.g. for a constant-current rig whose currents are not recorded).

    Returns
    -------
    dict: the ``"hdr"`` record also written into scan.json.

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
    source = "given"
    if sensor is None and isinstance(data.get("sensor"), dict):
        sensor, source = data["sensor"], "scan.json sensor"
    elif sensor is None:
        source = "nominal (no profile given)"
    sens = as_sensor(sensor)
    by_light = {}
    for fr in data["frames"]:
        by_light.setdefault(int(fr["light"]), []).append(fr)
    wanted = sorted(by_light) if lights is None else sorted(int(i) for i in lights)
    n_exposures = len(data.get("exposures") or [])
    (scan_dir / "hdr").mkdir(exist_ok=True)
    sd.journal("hdr_begin", method=method, lights=wanted)
    unit = HDR_UNIT if per == "us*mA" else "DN/us"
    t0 = time.perf_counter()
    records = []
    for li in wanted:
        frames, missing = [], []
        recorded = {int(f["exposure"]) for f in by_light.get(li, [])}
        missing += [{"exposure": e, "file": None, "reason": "not captured"}
                    for e in range(n_exposures) if e not in recorded]
        for fr in sorted(by_light.get(li, []), key=lambda f: int(f["exposure"])):
            path = scan_dir / fr["file"]
            if fr.get("sync") is False:  # the camera's flash sync never came: not a real frame
                missing.append({"exposure": int(fr["exposure"]), "file": fr["file"],
                                "reason": "no flash sync"})
                continue
            if not path.is_file():
                missing.append({"exposure": int(fr["exposure"]), "file": fr["file"],
                                "reason": "file missing"})
                continue
            if verify_sha256 and fr.get("sha256") and sha256_file(path) != fr["sha256"]:
                raise ValueError(f"{path} does not match the sha256 recorded in scan.json: the "
                                 "file changed after capture; re-shoot that frame or restore it")
            frames.append((fr, read_raw(path)))
        if missing:
            warnings.warn(f"light {li}: merging without {len(missing)} exposure(s) "
                          f"{[m['exposure'] for m in missing]} ({missing[0]['reason']})",
                          MissingFrameWarning, stacklevel=2)
        if not frames:
            raise FileNotFoundError(f"light {li} has no RAW frame on disk in {scan_dir / 'raw'}; "
                                    "re-run the scan for that light")
        exposures = [frame_exposure(fr, current)[0] if per == "us*mA" else float(fr["time_us"])
                     for fr, _ in frames]
        times_s = [float(fr["time_us"]) * 1e-6 for fr, _ in frames]
        try:
            res = merge([rf for _, rf in frames], exposures, sens, method=method, times_s=times_s)
        except ValueError as exc:
            raise ValueError(f"light {li} of {scan_dir}: {exc} (files "
                             f"{[fr['file'] for fr, _ in frames]})") from exc
        name = f"light_{li:02d}"
        hdr_attrs = {"facette_unit": unit, "facette_method": method,
                     "facette_light": str(li)}
        write_exr(scan_dir / "hdr" / f"{name}.exr", res.radiance, ("R", "G", "B"), hdr_attrs)
        write_exr(scan_dir / "hdr" / f"{name}_var.exr", res.variance, ("R", "G", "B"),
                  dict(hdr_attrs, facette_unit=f"({unit})^2"))
        records.append({"index": li, "file": f"hdr/{name}.exr", "var_file": f"hdr/{name}_var.exr",
                        "frames": [fr["file"] for fr, _ in frames], "missing": missing,
                        "saturated_fraction": float(res.saturated.mean()),
                        "no_sample_fraction": float(np.mean(res.n_used == 0))})
    record = {"method": method, "unit": unit, "current": current if per == "us*mA" else None,
              "resolution": "half-size", "sensor": sens.to_profile_dict(),
              "sensor_source": source,
              "lights": records, "merge_time_s": round(time.perf_counter() - t0, 3),
              "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    sd.update(hdr=record)
    sd.journal("hdr_done", lights=wanted, merge_time_s=record["merge_time_s"])
    return record


def load_hdr(scan_dir, sensor=None, merge_missing=True, method="inverse_variance"):
    """Load a scan's HDR images for the pipeline.

    Returns
    -------
    images : ndarray (m, H, W, 3) float32, radiance per µs·mA
    variances : ndarray (m, H, W, 3) float32
    lights : list of m dicts from scan.json's "lights" (index, direction, position_mm,
        intensity), in the order of `images`.

    If hdr/ is absent (or lacks a light) and `merge_missing`, `merge_scan` runs first
    with `sensor` and `method`.
    """
    scan_dir = Path(scan_dir)
    data = read_scan_manifest(scan_dir)
    lights = sorted(data["lights"], key=lambda l: int(l["index"]))
    light_ids = sorted({int(f["light"]) for f in data["frames"]})
    paths = {li: (scan_dir / "hdr" / f"light_{li:02d}.exr",
                  scan_dir / "hdr" / f"light_{li:02d}_var.exr") for li in light_ids}
    absent = [li for li, (p, v) in paths.items() if not (p.is_file() and v.is_file())]
    if absent:
        if not merge_missing:
            raise FileNotFoundError(f"{scan_dir / 'hdr'} lacks lights {absent}; run "
                                    "facette.scan.merge_scan(scan_dir) first")
        merge_scan(scan_dir, sensor=sensor, method=method, lights=absent)
    by_index = {int(l["index"]): l for l in lights}
    unknown = [li for li in light_ids if li not in by_index]
    if unknown:
        raise ValueError(f"scan.json has frames for lights {unknown} that its 'lights' list "
                         "does not describe")
    images = np.stack([read_exr(paths[li][0], ("R", "G", "B"))[0] for li in light_ids])
    variances = np.stack([read_exr(paths[li][1], ("R", "G", "B"))[0] for li in light_ids])
    return images, variances, [by_index[li] for li in light_ids]
