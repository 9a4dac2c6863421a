"""The scan directory (DESIGN §7, contract 3): scan.json, raw/, journal.jsonl.

The journal is appended (and fsync'ed) *before* each step, the manifest is
rewritten atomically *after* each captured frame, so that whatever stops the
scan (power cut, Ctrl-C, a device fault), the directory says what was taken and
a second run resumes where the first stopped.
"""
from __future__ import annotations

import datetime as _dt
import fcntl
import json
import os
from pathlib import Path

from facette.errors import BadInputError
from facette.io.checksum import sha256_file

__all__ = ["ScanDirectory", "ScanDirectoryError", "ScanDirectoryBusy", "sha256_file", "frame_name",
           "read_scan_manifest", "SCHEMA", "LOCK_NAME"]

SCHEMA = 1
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


class ScanDirectory:
    """One scan on disk.

    Attributes: ``path``, ``manifest`` (the scan.json dict, None before `create`).
    """

    def __init__(self, path):
        self.path = Path(path)
        self.manifest = None
        self.notes = []          # what the last scan run did that a user should know
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
        if not isinstance(data, dict) or not isinstance(data.get("frames"), list) \
                or not isinstance(data.get("lights"), list):
            raise ScanDirectoryError(f"{p} is damaged: it has no 'frames' and 'lights' lists", hint=hint)
        self.manifest = data

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
        """An existing scan: FileNotFoundError without scan.json, ValueError (ScanDirectoryError)
        when it is damaged or lacks the "lights" and "frames" lists of contract 3."""
        sd = cls(path)
        if sd.manifest is None:
            raise FileNotFoundError(f"{path} is not a scan directory: no scan.json in it")
        for key in ("lights", "frames"):
            if key not in sd.manifest:
                raise ScanDirectoryError(f"{sd.path / 'scan.json'} has no {key!r} list (contract 3); "
                                         "is it a facette scan?")
        return sd

    def __fspath__(self):
        return str(self.path)

    def __repr__(self):
        n = len((self.manifest or {}).get("frames", []))
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
        """A new manifest with no frames; refuses to overwrite a different scan."""
        self.path.mkdir(parents=True, exist_ok=True)
        (self.path / "raw").mkdir(exist_ok=True)
        self.manifest = {"schema": SCHEMA, "rig": rig, "profile": profile,
                         "pixel_pitch_mm": pixel_pitch_mm, "lights": lights, "exposures": exposures,
                         "frames": [], "rig_time_s": 0.0, "truth": None, "plan": plan,
                         "complete": False, "created": _now()}
        self.save()

    def save(self):
        tmp = self.path / ".scan.json.partial"
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(self.manifest, fh, indent=1, default=_jsonable)
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path / "scan.json")

    def update(self, **fields):
        """Set top-level fields of scan.json, re-read first so that what another writer saved
        meanwhile is kept (the HDR merge records itself this way)."""
        fresh = ScanDirectory.existing(self.path).manifest
        fresh.update(fields)
        self.manifest = fresh
        self.save()

    def set_aside_damaged(self):
        """Frames whose file no longer matches its sha256: each file is moved to raw/damaged/
        (kept, never deleted) and its record dropped, so that the scan takes it again.
        Returns one line per frame set aside."""
        lines = []
        keep = []
        for f in (self.manifest or {}).get("frames", []):
            p = self.path / f["file"]
            if p.is_file() and f.get("sha256") and sha256_file(p) != f["sha256"]:
                dst = self.path / "raw" / "damaged" / p.name
                n = 1
                while dst.exists():
                    dst, n = dst.with_name(f"{p.stem}-{n}{p.suffix}"), n + 1
                dst.parent.mkdir(parents=True, exist_ok=True)
                rel = str(dst.relative_to(self.path))
                self.journal("damaged", file=f["file"], kept=rel)
                os.replace(p, dst)
                lines.append(f"{f['file']}: sha256 differs from scan.json (the file changed after "
                             f"capture); kept as {rel} and taken again")
            else:
                keep.append(f)
        if lines:
            self.manifest["frames"] = keep
            self.manifest["complete"] = False
            self.save()
        return lines

    def frames_done(self):
        """{(light, exposure): frame record} of frames whose file is present."""
        out = {}
        for f in (self.manifest or {}).get("frames", []):
            if (self.path / f["file"]).is_file():
                out[(f["light"], f["exposure"])] = f
        return out

    def add_frame(self, record):
        """Record a captured frame (its file must already be at record["file"])."""
        frames = [f for f in self.manifest["frames"]
                  if (f["light"], f["exposure"]) != (record["light"], record["exposure"])]
        frames.append(record)
        frames.sort(key=lambda f: (f["light"], f["exposure"]))
        self.manifest["frames"] = frames
        self.save()

    def verify(self):
        """Check every frame file against its sha256: list of problems (empty when intact)."""
        problems = []
        for f in (self.manifest or {}).get("frames", []):
            p = self.path / f["file"]
            if not p.is_file():
                problems.append(f"{f['file']}: missing")
            elif sha256_file(p) != f["sha256"]:
                problems.append(f"{f['file']}: sha256 differs from scan.json")
        return problems


def read_scan_manifest(scan_dir):
    """scan.json of an existing scan as a dict (errors as `ScanDirectory.existing`)."""
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
