"""The scan directory: scan.json, raw/, hdr/, journal.jsonl (docs/scan-format.md).

`ScanDirectory` is the only reader and writer of scan.json and the journal; what scan.json
holds is the `Manifest` (scan/manifest.py, with its records `Light`, `Exposure`, `Frame`,
`HdrLight`, `Hdr`, re-exported here), set only through its methods and read through its
attributes.

The journal is appended (and fsync'ed) *before* each step, the manifest is
rewritten atomically *after* each captured frame, so that whatever stops the
scan (power cut, Ctrl-C, a device fault), the directory says what was taken and
a second run resumes where the first stopped.
"""
from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

from facette.errors import EXIT_STOPPED, BadInputError
from facette.io.atomic import move_file, write_text_atomic
from facette.io.checksum import sha256_file
from facette.scan.manifest import SCHEMA, Exposure, Frame, Hdr, HdrLight, Light, Manifest, _now

__all__ = ["ScanDirectory", "ScanDirectoryError", "ScanDirectoryBusy", "Manifest", "Light", "Exposure", "Frame",
           "HdrLight", "Hdr", "sha256_file", "frame_name", "read_scan_manifest", "SCHEMA", "LOCK_NAME"]
LOCK_NAME = ".facette.lock"   # flock'ed by the one process writing the directory


class ScanDirectoryError(BadInputError):
    """The directory holds something that is not this scan."""


class ScanDirectoryBusy(ScanDirectoryError):
    """Another process is writing the directory."""


def frame_name(light, exposure, suffix=".dng"):
    """raw/L00_E00.dng: light index (scan order) and exposure index."""
    return f"raw/L{light:02d}_E{exposure:02d}{suffix}"


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
        # what the processing that follows made of the held lights while they arrived (ScanOptions.on_held's,
        # e.g. facette.pipeline.ArrivingLights: `facette.process` takes it from here), or None
        self.prepared = None
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
            p = self.path / f.file
            if p.is_file() and f.sha256 and sha256_file(p) != f.sha256:
                dst = self.path / "raw" / "damaged" / p.name
                n = 1
                while dst.exists():
                    dst, n = dst.with_name(f"{p.stem}-{n}{p.suffix}"), n + 1
                dst.parent.mkdir(parents=True, exist_ok=True)
                rel = str(dst.relative_to(self.path))
                self.journal("damaged", file=f.file, kept=rel)
                move_file(p, dst)
                damaged.append(f.file)
                lines.append(f"{f.file}: sha256 differs from scan.json (the file changed after "
                             f"capture); kept as {rel} and taken again")
        if damaged:
            self.manifest.drop_frames(damaged)
            self.save()
        return lines

    def frames_done(self):
        """{(light, exposure): `Frame`} of frames whose file is present."""
        out = {}
        for f in (self.manifest.frames if self.manifest is not None else ()):
            if (self.path / f.file).is_file():
                out[(f.light, f.exposure)] = f
        return out

    def add_frame(self, record):
        """Record a captured frame (a `Frame`, or its JSON object; its file must already be at
        its ``file``) and save."""
        self.manifest.add_frame(record)
        self.save()

    def verify(self):
        """Check every frame file against its sha256: list of problems (empty when intact)."""
        problems = []
        for f in (self.manifest.frames if self.manifest is not None else ()):
            p = self.path / f.file
            if not p.is_file():
                problems.append(f"{f.file}: missing")
            elif sha256_file(p) != f.sha256:
                problems.append(f"{f.file}: sha256 differs from scan.json")
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
        held = self.take_held(light)
        return None if held is None else held.arrays()

    def take_held(self, light):
        """The `HeldLight` itself (its arrays, and `unchanged()`: whether its files are still as written),
        leaving the directory object; None when it was not held."""
        return self._held.pop(int(light), None)

    def held_lights(self):
        """The indices of the lights held in memory."""
        return sorted(self._held)

    def release_held_lights(self):
        """Drop every light held in memory that processing did not take, and what was prepared from them."""
        self._held.clear()
        prepared, self.prepared = self.prepared, None
        if prepared is not None:
            prepared.close()


def read_scan_manifest(scan_dir):
    """The `Manifest` of an existing scan (errors as `ScanDirectory.existing`)."""
    return ScanDirectory.existing(scan_dir).manifest


def _jsonable(obj):
    import numpy as np

    if hasattr(obj, "to_json"):          # a scan.json record (scan/manifest.py)
        return obj.to_json()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store {type(obj).__name__} in JSON")
