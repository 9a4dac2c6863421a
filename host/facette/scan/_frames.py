"""Camera files into the scan directory: each frame record's file moved to raw/L<l>_E<e>,
hashed and recorded (`FrameFiler.file`); a file no record accounts for kept in raw/unmatched/,
an earlier take of a frame taken again kept beside it. The journal says each move before it
is made (`facette.scan.acquire` describes the whole acquisition)."""
from __future__ import annotations

import time
from pathlib import Path

from facette.camera.raw import read_exposure_metadata
from facette.errors import EXIT_STOPPED
from facette.io.atomic import move_file
from facette.scan._errors import ScanError
from facette.scan.directory import frame_name, sha256_file
from facette.scan.manifest import Frame

__all__ = ["FrameFiler", "NO_EXPOSURE_NOTE"]

NO_EXPOSURE_NOTE = ("the camera's files carry no exposure time (no ExposureTime tag): the scan cannot check "
                    "the camera's shutter against its plan and uses the frame records' times")


class FrameFiler:
    """Files the camera's images of one scan directory `sd` (a `ScanDirectory`) as `plan` (a
    `ScanPlan`) names them; `frame_timeout_s`: how long to wait for a file after its record."""

    def __init__(self, sd, camera, plan, frame_timeout_s):
        self.sd, self.camera, self.plan = sd, camera, plan
        self.frame_timeout_s = frame_timeout_s
        self.unmatched_dir = sd.path / "raw" / "unmatched"

    def keep_unmatched(self, src, why):
        """Move a camera file no frame record accounts for to raw/unmatched/ (never over
        another); returns where it went."""
        self.unmatched_dir.mkdir(parents=True, exist_ok=True)
        dst = self.unmatched_dir / Path(src).name
        n = 1
        while dst.exists():
            dst, n = self.unmatched_dir / f"{Path(src).stem}-{n}{Path(src).suffix}", n + 1
        self.sd.journal("unmatched", src=str(src), dst=str(dst.relative_to(self.sd.path)), why=why)
        move_file(src, dst, exit_code=EXIT_STOPPED)
        self.camera.claimed(src)
        return dst

    def keep_superseded(self, dst):
        """An earlier take of a frame taken again (after a reset): kept in raw/unmatched/."""
        self.unmatched_dir.mkdir(parents=True, exist_ok=True)
        keep = self.unmatched_dir / f"{dst.stem}-superseded-{int(time.time() * 1e3)}{dst.suffix}"
        self.sd.journal("superseded", file=str(dst.relative_to(self.sd.path)),
                        kept=str(keep.relative_to(self.sd.path)))
        move_file(dst, keep)

    def wait_camera_quiet(self, quiet_s=0.3, limit_s=5.0):
        """After stopping a run, let the camera write out the image it was taking (a
        stray file arriving after the next run started would be taken for its first frame)."""
        deadline = time.monotonic() + limit_s
        last, since = len(self.camera.pending()), time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - since < quiet_s:
            time.sleep(0.01)      # watch the folder for new files
            n = len(self.camera.pending())
            if n != last:
                last, since = n, time.monotonic()

    def sweep_camera(self, why):
        """Keep every file waiting in the camera folder in raw/unmatched/."""
        for p in self.camera.pending():
            self.keep_unmatched(p, why)

    def check_exposure(self, src, light, exposure, t_us):
        """In camera-timed and bulb modes the file's own exposure time must be the record's: a
        mismatch means a frame without a record (or a camera set otherwise); never file it under
        the wrong name (ScanError, the file kept in raw/unmatched/)."""
        et, _, _ = read_exposure_metadata(src)
        if et is None and NO_EXPOSURE_NOTE not in self.sd.notes:
            self.sd.notes.append(NO_EXPOSURE_NOTE)
        if et is not None and abs(et * 1e6 - t_us) > max(0.05 * t_us, 1000):
            kept = self.keep_unmatched(src, f"exposure {et:g} s, the frame record says {t_us / 1e6:g} s "
                                            f"(light {light} exposure {exposure})")
            raise ScanError(
                f"the camera's image {src.name} was exposed {et:g} s but the rig took light {light} "
                f"exposure {exposure} at {t_us / 1e6:g} s (kept as {kept.relative_to(self.sd.path)}). In "
                "camera-timed mode the camera's shutter speed must match the scan's exposures: set it, "
                "or scan with --mode bulb or led; then run the same scan again to resume")

    def file(self, rec, light, exposure, run):
        """Move the camera's next file to raw/L<l>_E<e> and record it in scan.json; returns its
        `Frame` (docs/scan-format.md, "A frame record"). `rec`: the device's frame record."""
        t_us, _ = self.plan.exposures[exposure]
        src = self.camera.wait_for_file(self.frame_timeout_s)
        if self.plan.mode in ("camera", "bulb"):
            self.check_exposure(src, light, exposure, t_us)
        dst_rel = frame_name(light, exposure, src.suffix.lower())
        dst = self.sd.path / dst_rel
        frame = Frame(file=dst_rel, light=light, exposure=exposure, time_us=t_us,
                      current_set_mA=rec["current_set_mA"], current_meas_mA=rec["current_meas_mA"],
                      start_us=rec["start_us"], sync=rec["sync"], retry=rec["retry"], run=run, ring=rec["n"])
        # the journal's record is the frame's without its sha256 (not known before the move)
        record = {k: v for k, v in frame.to_json().items() if k != "sha256"}
        self.sd.journal("capture", src=str(src), record=record)
        if dst.exists():   # a frame taken again (after a reset): keep the earlier one too
            self.keep_superseded(dst)
        move_file(src, dst, exit_code=EXIT_STOPPED)
        self.camera.claimed(src)
        frame = frame.replace(sha256=sha256_file(dst))
        self.sd.add_frame(frame)
        # the process's CPU so far: what the processing after the last frame costs, on a shared machine (bench e2e)
        self.sd.journal("captured", file=dst_rel, sha256=frame.sha256, cpu_s=round(time.process_time(), 3))
        return frame
