"""Taking a scan directory again: refuse one that holds another scan (`check_resumable`),
and resume one of the same plan (`resume`): finish the file moves the journal says were under
way, set damaged frames aside (taken again), and ignore the camera files that predate the scan."""
from __future__ import annotations

from pathlib import Path

from facette.errors import EXIT_STOPPED
from facette.io.atomic import move_file
from facette.scan.adaptive import METER_DIR
from facette.scan.directory import LOCK_NAME, ScanDirectoryError, sha256_file
from facette.scan.manifest import Frame

__all__ = ["check_resumable", "recover", "resume"]


def _is_meter_dir(path):
    return path.is_dir() and (path.name == METER_DIR or path.name.startswith(METER_DIR + "-"))


def check_resumable(sd, plan):
    """Refuse a directory that holds something else than this scan (nothing is touched)."""
    if sd.manifest is None:
        if (sd.path / "journal.jsonl").exists() or (sd.path.exists() and any(
                p.name not in (LOCK_NAME, ".DS_Store") and not _is_meter_dir(p) for p in sd.path.iterdir())):
            raise ScanDirectoryError(f"{sd.path} is not empty and holds no scan.json",
                                     hint="choose a new directory (a scan starts in an empty one)")
        return
    old = sd.manifest.plan or {}
    differ = [k for k in plan.key() if old.get(k) != plan.key()[k]]
    if differ:
        said = "; ".join(f"{k}: this directory has {old.get(k)}, the command asks for {plan.key()[k]}"
                         for k in differ)
        raise ScanDirectoryError(f"{sd.path} holds another scan ({said})",
                                 hint="resume it with the same settings, or choose a new directory")


def recover(sd):
    """Finish what the journal says was under way when the last run stopped: a frame's file
    moved (or not yet) but its record not saved."""
    entries = sd.read_journal()
    done = {e["file"] for e in entries if e.get("step") == "captured"}
    for e in entries:
        if e.get("step") != "capture":
            continue
        frame = Frame.from_json(e["record"], where=sd.path / "journal.jsonl")
        if frame.file in done:
            continue
        dst, src = sd.path / frame.file, Path(e["src"])
        if not dst.exists() and src.exists():
            move_file(src, dst, exit_code=EXIT_STOPPED)
        if dst.exists():
            frame = frame.replace(sha256=sha256_file(dst))
            sd.add_frame(frame)
            sd.journal("recovered", file=frame.file, sha256=frame.sha256)
            done.add(frame.file)


def resume(rig, sd):
    """A scan with a manifest taken again: journaled, its half-done moves finished, its damaged
    frames set aside (their lines added to ``sd.notes``), the camera told which files are not ours."""
    sd.journal("resume", rig=rig.identity)
    recover(sd)
    sd.notes += sd.set_aside_damaged()     # a frame whose sha256 fails is taken again
    begin = next((e for e in sd.read_journal() if e.get("step") == "begin"), {})
    if hasattr(rig.camera, "ignore"):   # files that predate the scan are not ours
        rig.camera.ignore(begin.get("camera_ignored", []))
