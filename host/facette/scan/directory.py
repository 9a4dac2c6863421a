"""The scan directory: scan.json (its `Manifest`), raw/, hdr/, journal.jsonl.

The format, every key with its unit and the version history, is `docs/scan-format.md`.
`ScanDirectory` is the only reader and writer of scan.json; `Manifest` owns its contents:
set only through its methods (the plan, the frames, the HDR merge, the completion), read
through its attributes. An older scan.json is migrated on read (`Manifest.from_dict`) and
written back in this version the next time the scan directory saves it.

Schema 2 (every key present)::

    {"schema": 2,
     "created": ISO-8601 str,                  # UTC, ms; when the scan directory was made
     "rig": {...},                             # the device's identity (`Rig.identity`)
     "profile": {"id", "sha256", "path",       # the calibration profile, or null
                 "image_size_px": [w, h] | null} | null,
     "pixel_pitch_mm": float | null,           # mm per HDR (half-size) pixel on the object
     "lights": [{"index": int, "channel": int, # scan order; LED channel
                 "direction": [x, y, z] | null,# unit, camera frame (docs/conventions.md)
                 "position_mm": [x, y, z] | null,
                 "intensity": [r, g, b]}],     # relative (the profile's)
     "exposures": [{"index": int, "time_us": int, "current_mA": int, "mode": str}],
     "plan": {"lights", "exposures", "light_current_mA", "mode", "retries", "timing"} | null,
     "bracketing": {"name": "thesis2016" | "explicit" | "adaptive", ...} | null,
     "sensor": {SENSOR_KEYS...} | null,        # the profile's noise model, for the HDR merge
     "radiometric_scale": [r, g, b] | null,    # HDR units per unit irradiance (Spectralon)
     "frames": [{"file", "light", "exposure", "time_us", "current_set_mA", "current_meas_mA",
                 "start_us", "sync", "retry", "run", "ring", "sha256"}],  # sorted (light, exposure)
     "runs": int,                              # device runs started
     "rig_time_s": float,                      # device time, metering included
     "hdr": {...} | null,                      # the HDR merge (`facette.scan.hdr.hdr_record`)
     "complete": bool,                         # every frame of the plan taken
     "truth": "truth.npz" | null,              # the simulator's truth, beside scan.json
     "faults_seen": [journal entries]}         # device resets, missed syncs, stray files...

Version 1 (facette until issue 27) wrote the same keys, but "sensor", "radiometric_scale",
"bracketing", "runs", "hdr" and "faults_seen" only once known, and scan.json files made by
tools lacked "plan", "complete", "created" and "truth"; version 2 writes every key.

The journal is appended (and fsync'ed) *before* each step, the manifest is
rewritten atomically *after* each captured frame, so that whatever stops the
scan (power cut, Ctrl-C, a device fault), the directory says what was taken and
a second run resumes where the first stopped.
"""
from __future__ import annotations

import copy
import dataclasses
import datetime as _dt
import fcntl
import json
import os
from pathlib import Path

from facette.errors import EXIT_STOPPED, BadInputError
from facette.io.atomic import move_file, write_text_atomic
from facette.io.checksum import sha256_file

__all__ = ["ScanDirectory", "ScanDirectoryError", "ScanDirectoryBusy", "Manifest", "sha256_file",
           "frame_name", "read_scan_manifest", "SCHEMA", "LOCK_NAME"]

SCHEMA = 2
LOCK_NAME = ".facette.lock"   # flock'ed by the one process writing the directory


class ScanDirectoryError(BadInputError):
    """The directory holds something that is not this scan."""


class ScanDirectoryBusy(ScanDirectoryError):
    """Another process is writing the directory."""


def frame_name(light, exposure, suffix=".dng"):
    """raw/L00_E00.dng: light index (scan order) and exposure index."""
    return f"raw/L{light:02d}_E{exposure:02d}{suffix}"


def _now():
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


@dataclasses.dataclass(frozen=True, eq=False)
class Manifest:
    """The contents of scan.json (schema in this module's docstring and docs/scan-format.md).

    Read through attributes (``m.frames``, ``m.complete``...); set only through the methods
    below, which `ScanDirectory` calls and then saves: the attributes refuse assignment
    (``dataclasses.FrozenInstanceError``). ``lights``, ``exposures`` and ``frames`` are
    tuples of dicts (the records the docstring lists); ``extra`` keeps the keys of a newer
    writer this version does not know, written back unchanged.
    """
    rig: dict
    profile: dict | None
    pixel_pitch_mm: float | None
    lights: tuple
    exposures: tuple
    plan: dict | None = None
    created: str | None = None
    bracketing: dict | None = None
    sensor: dict | None = None
    radiometric_scale: list | None = None
    frames: tuple = ()
    runs: int = 0
    rig_time_s: float = 0.0
    hdr: dict | None = None
    complete: bool = False
    truth: str | None = None
    faults_seen: tuple = ()
    extra: dict = dataclasses.field(default_factory=dict)

    # -- reading and writing -----------------------------------------------------------
    @classmethod
    def new(cls, rig, profile, pixel_pitch_mm, lights, exposures, plan):
        """A scan's manifest before its first frame."""
        return cls(rig=rig, profile=profile, pixel_pitch_mm=pixel_pitch_mm, lights=tuple(lights),
                   exposures=tuple(exposures), plan=plan, created=_now())

    @classmethod
    def from_dict(cls, data, where="scan.json"):
        """A manifest from scan.json's object, migrated from an older schema (1) when it is one.
        ValueError (naming `where`) when it lacks the "lights" and "frames" lists or comes from
        a newer facette."""
        if not isinstance(data, dict) or not isinstance(data.get("frames"), list) \
                or not isinstance(data.get("lights"), list):
            raise ValueError(f"{where} is damaged: it has no 'frames' and 'lights' lists")
        schema = data.get("schema", 1)
        if not isinstance(schema, int) or schema > SCHEMA:
            raise ValueError(f"{where} has schema {schema!r}; this facette reads schemas 1..{SCHEMA} "
                             "(update facette)")
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        fields = {k: v for k, v in data.items() if k in known}
        for key in ("lights", "exposures", "frames", "faults_seen"):
            fields[key] = tuple(fields.get(key) or ())
        fields.setdefault("rig", None)
        fields.setdefault("profile", None)
        fields.setdefault("pixel_pitch_mm", None)
        fields["complete"] = bool(fields.get("complete", False))
        fields["runs"] = int(fields.get("runs") or 0)
        fields["rig_time_s"] = float(fields.get("rig_time_s") or 0.0)
        extra = {k: v for k, v in data.items() if k not in known and k != "schema"}
        return cls(**fields, extra=extra)

    @classmethod
    def of(cls, data):
        """`data` itself when it is a Manifest, else `from_dict(data)` (a scan.json dict)."""
        return data if isinstance(data, Manifest) else cls.from_dict(data)

    def to_dict(self):
        """scan.json's object (schema `SCHEMA`, every key present, in the documented order)."""
        out = {"schema": SCHEMA}
        for f in dataclasses.fields(self):
            if f.name != "extra":
                v = getattr(self, f.name)
                out[f.name] = list(v) if isinstance(v, tuple) else v
        out.update(self.extra)
        return out

    def snapshot(self):
        """A deep copy (for a worker that reads it while the scan goes on writing this one)."""
        return copy.deepcopy(self)

    def _set(self, **fields):
        for k, v in fields.items():
            object.__setattr__(self, k, v)

    # -- what was planned -----------------------------------------------------------------
    def set_calibration(self, sensor, radiometric_scale):
        """The profile's noise model (for the HDR merge) and radiometric scale."""
        self._set(sensor=None if sensor is None else dict(sensor),
                  radiometric_scale=None if radiometric_scale is None else list(radiometric_scale))

    def set_bracketing(self, bracketing):
        """How the exposures were chosen; the metering's rig time counts as this scan's."""
        self._set(bracketing=dict(bracketing),
                  rig_time_s=round(float(bracketing.get("meter_rig_time_s", 0.0)), 6))

    @property
    def n_planned(self):
        """Frames the plan asks for: lights × exposures."""
        return len(self.lights) * len(self.exposures)

    # -- frames and device runs -------------------------------------------------------------
    def add_frame(self, record):
        """Record a captured frame (replacing an earlier one of the same light and exposure)."""
        key = (record["light"], record["exposure"])
        frames = [f for f in self.frames if (f["light"], f["exposure"]) != key] + [dict(record)]
        frames.sort(key=lambda f: (f["light"], f["exposure"]))
        self._set(frames=tuple(frames))

    def drop_frames(self, files):
        """Forget the frames of these files (to be taken again): the scan is then incomplete."""
        files = set(files)
        self._set(frames=tuple(f for f in self.frames if f["file"] not in files), complete=False)

    def start_run(self):
        """Count a device run; returns its index."""
        self._set(runs=self.runs + 1)
        return self.runs - 1

    def add_rig_time(self, seconds):
        self._set(rig_time_s=round(self.rig_time_s + float(seconds), 6))

    def light_frames(self, light):
        """Frame records of one light, by exposure index."""
        return sorted((f for f in self.frames if int(f["light"]) == int(light)),
                      key=lambda f: int(f["exposure"]))

    def frame_lights(self):
        """The light indices that have frames, sorted."""
        return sorted({int(f["light"]) for f in self.frames})

    # -- HDR and completion -----------------------------------------------------------------
    def set_hdr(self, record):
        """The HDR merge's record (`facette.scan.hdr.hdr_record`)."""
        self._set(hdr=record)

    def set_truth(self, name):
        """The simulator's truth file beside scan.json (None: no truth)."""
        self._set(truth=name)

    def finish(self, faults_seen):
        """Every frame of the plan is taken; `faults_seen`: the journal entries worth knowing."""
        self._set(complete=True, faults_seen=tuple(faults_seen))


class ScanDirectory:
    """One scan on disk.

    Attributes: ``path``, ``manifest`` (a `Manifest`, None before `create`), ``notes`` (what
    the last scan run did that a user should know) and the lights merged during the scan and
    kept in memory for the processing that follows (`hold_light`, `take_held_light`).
    """

    def __init__(self, path):
        self.path = Path(path)
        self.manifest = None
        self.notes = []
        self._held = {}
        self._lock_fh = None
        self.reload()

    def reload(self):
        """Read scan.json again (None when there is none); a damaged one is named."""
        p = self.path / "scan.json"
        self.manifest = None
        if not p.is_file():
            return
        hint = (f"nothing was changed; the journal {self.path / 'journal.jsonl'} and raw/ hold what "
                "was captured: restore scan.json from a backup, or scan into a new directory")
        try:
            data = json.loads(p.read_text())
        except ValueError as exc:
            raise ScanDirectoryError(f"{p} is damaged ({exc})", hint=hint) from exc
        try:
            self.manifest = Manifest.from_dict(data, where=p)
        except ValueError as exc:
            raise ScanDirectoryError(str(exc), hint=hint) from None

    # -- one writer at a time --------------------------------------------------------
    def lock(self):
        """Take the directory for this process (creating it): an flock on .facette.lock, which
        the kernel releases when the process ends, however it ends. Raises ScanDirectoryBusy
        when another process holds it. Re-reads scan.json (it may have changed meanwhile)."""
        if self._lock_fh is not None:
            return
        self.path.mkdir(parents=True, exist_ok=True)
        fh = open(self.path / LOCK_NAME, "a+", encoding="utf-8")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "?"
            fh.close()
            raise ScanDirectoryBusy(f"{self.path} is being written by another facette process ({holder})",
                                    hint="wait for it to finish (or stop it), then run this command "
                                         "again") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()}\n")
        fh.flush()
        self._lock_fh = fh
        self.reload()

    def writer(self):
        """Who writes the directory now ("pid N") when another process holds its lock, else None
        (the lock is not taken: a read-only folder can be asked too)."""
        p = self.path / LOCK_NAME
        try:
            fh = open(p, encoding="utf-8")
        except OSError:
            return None
        with fh:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = fh.read().strip() or "?"
                return None if self._lock_fh is not None or holder == f"pid {os.getpid()}" else holder
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        return None

    def unlock(self):
        if self._lock_fh is not None:
            fcntl.flock(self._lock_fh.fileno(), fcntl.LOCK_UN)
            self._lock_fh.close()
            self._lock_fh = None

    def __enter__(self):
        self.lock()
        return self

    def __exit__(self, *exc):
        self.unlock()

    @classmethod
    def existing(cls, path):
        """An existing scan: FileNotFoundError without scan.json, ScanDirectoryError (a
        ValueError) when it is damaged or lacks the "lights" and "frames" lists."""
        sd = cls(path)
        if sd.manifest is None:
            raise FileNotFoundError(f"{path} is not a scan directory: no scan.json in it")
        return sd

    def __fspath__(self):
        return str(self.path)

    def __repr__(self):
        n = len(self.manifest.frames) if self.manifest is not None else 0
        return f"ScanDirectory({str(self.path)!r}, {n} frames)"

    # -- journal --------------------------------------------------------------------
    def journal(self, step, **data):
        """Append one step to journal.jsonl and make it durable before returning."""
        self.path.mkdir(parents=True, exist_ok=True)
        line = json.dumps({"t": _now(), "step": step, **data}, sort_keys=True, default=_jsonable)
        with open(self.path / "journal.jsonl", "a", encoding="utf-8") as fh:
            fh.write(line + "\n")
            fh.flush()
            os.fsync(fh.fileno())

    def read_journal(self):
        """Journal entries (a truncated last line, from a crash mid-write, is skipped)."""
        p = self.path / "journal.jsonl"
        if not p.is_file():
            return []
        out = []
        for line in p.read_text(encoding="utf-8").splitlines():
            try:
                out.append(json.loads(line))
            except ValueError:
                continue
        return out

    # -- manifest -------------------------------------------------------------------
    def create(self, rig, profile, pixel_pitch_mm, lights, exposures, plan):
        """A new manifest with no frames (`Manifest.new`), saved; raw/ made."""
        self.path.mkdir(parents=True, exist_ok=True)
        (self.path / "raw").mkdir(exist_ok=True)
        self.manifest = Manifest.new(rig, profile, pixel_pitch_mm, lights, exposures, plan)
        self.save()

    def save(self):
        """Write the manifest to scan.json atomically (a temporary file, fsync'ed, renamed; a full
        disk is a DiskFullError that stops the scan: exit 1, it resumes)."""
        text = json.dumps(self.manifest.to_dict(), indent=1, default=_jsonable) + "\n"
        write_text_atomic(self.path / "scan.json", text, exit_code=EXIT_STOPPED)

    def record_hdr(self, record):
        """Store the HDR merge's record, scan.json re-read first so that what another writer
        saved meanwhile is kept."""
        self.manifest = ScanDirectory.existing(self.path).manifest
        self.manifest.set_hdr(record)
        self.save()

    def set_aside_damaged(self):
        """Frames whose file no longer matches its sha256: each file is moved to raw/damaged/
        (kept, never deleted) and its record dropped, so that the scan takes it again.
        Returns one line per frame set aside."""
        lines = []
        damaged = []
        for f in (self.manifest.frames if self.manifest is not None else ()):
            p = self.path / f["file"]
            if p.is_file() and f.get("sha256") and sha256_file(p) != f["sha256"]:
                dst = self.path / "raw" / "damaged" / p.name
                n = 1
                while dst.exists():
                    dst, n = dst.with_name(f"{p.stem}-{n}{p.suffix}"), n + 1
                dst.parent.mkdir(parents=True, exist_ok=True)
                rel = str(dst.relative_to(self.path))
                self.journal("damaged", file=f["file"], kept=rel)
                move_file(p, dst)
                damaged.append(f["file"])
                lines.append(f"{f['file']}: sha256 differs from scan.json (the file changed after "
                             f"capture); kept as {rel} and taken again")
        if damaged:
            self.manifest.drop_frames(damaged)
            self.save()
        return lines

    def frames_done(self):
        """{(light, exposure): frame record} of frames whose file is present."""
        out = {}
        for f in (self.manifest.frames if self.manifest is not None else ()):
            if (self.path / f["file"]).is_file():
                out[(f["light"], f["exposure"])] = f
        return out

    def add_frame(self, record):
        """Record a captured frame (its file must already be at record["file"]) and save."""
        self.manifest.add_frame(record)
        self.save()

    def verify(self):
        """Check every frame file against its sha256: list of problems (empty when intact)."""
        problems = []
        for f in (self.manifest.frames if self.manifest is not None else ()):
            p = self.path / f["file"]
            if not p.is_file():
                problems.append(f"{f['file']}: missing")
            elif sha256_file(p) != f["sha256"]:
                problems.append(f"{f['file']}: sha256 differs from scan.json")
        return problems

    # -- lights merged during the scan, kept in memory for the processing that follows ------
    def hold_light(self, light, held):
        """Keep a light merged in this process (`facette.scan.hdr.HeldLight`)."""
        self._held[int(light)] = held

    def take_held_light(self, light):
        """(radiance (H, W, 3) float32, green variance (H, W) float32, NaN where the variance
        is not finite in any channel) of a held light, exactly as in its two files; None when
        it was not held or either file changed since (then read the files). The arrays leave
        the directory object: a second call returns None."""
        held = self._held.pop(int(light), None)
        return None if held is None else held.arrays()

    def held_lights(self):
        """The indices of the lights held in memory."""
        return sorted(self._held)

    def release_held_lights(self):
        """Drop every light held in memory that processing did not take."""
        self._held.clear()


def read_scan_manifest(scan_dir):
    """The `Manifest` of an existing scan (errors as `ScanDirectory.existing`)."""
    return ScanDirectory.existing(scan_dir).manifest


def _jsonable(obj):
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in JSON")
