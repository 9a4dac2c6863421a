"""Acquire a scan: configure the rig, run it, match RAW files to frame records.

``run_scan(rig, directory, profile=...)`` (also ``rig.scan(...)``, ``facette scan``):

1. plan: lights (LED channels in scan order) × exposures (time µs, current mA);
2. open the scan directory: new, or resume (same plan), completing any file move
   the journal says was under way and keeping stray camera files in raw/unmatched/;
3. for the (light, exposure) pairs still missing, grouped so that the device runs
   lights × exposures scans: configure, start (or wait for the button), and for
   every frame record whose flash sync was seen take the camera's next file,
   move it to raw/L<l>_E<e>.dng, hash it, add it to scan.json;
4. a device reset (boot count changed) is journaled, the frames of the interrupted
   run that arrived without a record are kept in raw/unmatched/, and the missing
   pairs are scanned again; a device fault stops the scan with the fault's name and
   an intact journal (run again to resume once the cause is fixed).
"""
from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path

from facette.calib import load as load_profile
from facette.calib import nominal_light_directions
from facette.camera.folder import CameraTimeout
from facette.camera.raw import read_exposure_metadata
from facette.device.client import DeviceException, DeviceReset, DeviceTimeout
from facette.errors import EXIT_STOPPED, BadInputError, StoppedError
from facette.hdr import THESIS_BRACKET_US
from facette.io.atomic import move_file
from facette.scan.adaptive import METER_DIR, meter_and_plan
from facette.scan.directory import LOCK_NAME, ScanDirectory, ScanDirectoryError, frame_name, sha256_file
from facette.scan.hdr import LightMerger, scan_sensor, store_light_records

__all__ = ["run_scan", "ScanOptions", "ScanPlan", "ScanError", "ScanAborted", "THESIS_BRACKET_US", "default_plan"]

# Faults that report a past event and do not make the next scan unsafe.
_BENIGN_FAULTS = frozenset({"HOST_SILENT", "CAL_INVALID", "WATCHDOG_RESET"})


NO_EXPOSURE_NOTE = ("the camera's files carry no exposure time (no ExposureTime tag): the scan cannot check "
                    "the camera's shutter against its plan and uses the frame records' times")


class ScanError(StoppedError):
    """The scan stopped; the directory holds everything captured so far."""


class ScanAborted(ScanError):
    """The scan was aborted (host call or second button press)."""


@dataclasses.dataclass
class ScanPlan:
    """What to acquire.

    lights : LED channels in scan order (light index i ↔ channel lights[i])
    exposures : [(time_us, current_mA)] (current 0: the light's current)
    light_current_mA : one current per light, mA
    mode : "camera" | "bulb" | "led"
    retries : repeats of a setting with a missing flash sync
    timing : other µs registers (settle_us, gap_us, ...)
    """
    lights: list
    exposures: list
    light_current_mA: list
    mode: str = "camera"
    retries: int = 1
    timing: dict = dataclasses.field(default_factory=dict)

    def key(self):
        return {"lights": list(self.lights), "exposures": [list(e) for e in self.exposures],
                "light_current_mA": list(self.light_current_mA), "mode": self.mode}

    def to_dict(self):
        return {**self.key(), "retries": self.retries, "timing": dict(self.timing)}


def default_plan(n_leds=12, exposures=None, lights=None, light_current_mA=500, mode="camera", retries=1,
                 timing=None):
    """A plan with the thesis bracket (camera-timed) on every LED unless told otherwise.
    `exposures` : times in µs or (time_us, current_mA) pairs."""
    lights = list(range(n_leds)) if lights is None else [int(c) for c in lights]
    exps = THESIS_BRACKET_US if exposures is None else exposures
    exps = [(int(e), 0) if not hasattr(e, "__len__") else (int(e[0]), int(e[1])) for e in exps]
    cur = [int(light_current_mA)] * len(lights) if not hasattr(light_current_mA, "__len__") \
        else [int(c) for c in light_current_mA]
    if len(cur) != len(lights):
        raise BadInputError(f"{len(cur)} light currents for {len(lights)} lights")
    if not 1 <= len(lights) <= 16 or not 1 <= len(exps) <= 16:
        raise BadInputError(f"a scan takes 1..16 lights and 1..16 exposures per light, got {len(lights)} "
                            f"lights and {len(exps)} exposures")
    twice = sorted({c for c in lights if lights.count(c) > 1})
    if twice:
        raise BadInputError(f"light {twice[0]} is listed twice in lights {lights}",
                            hint="give each LED channel once (a repeat would overwrite its images)")
    bad = [c for c in lights if c < 0] + [c for c in cur if c < 1] + [c for _, c in exps if c < 0]
    if bad:
        raise BadInputError(f"LED channels are >= 0 and currents >= 1 mA; got {bad[0]}")
    if any(t < 1 for t, _ in exps):
        raise BadInputError(f"exposure times are >= 1 µs; got {[t for t, _ in exps]}")
    return ScanPlan(lights, exps, cur, mode, int(retries), dict(timing or {}))


def _load_profile(profile):
    if profile is None or hasattr(profile, "lights"):
        return profile
    return load_profile(profile)


def _profile_section(profile):
    """scan.json's record of the profile: id and checksum, and where it was read from so that
    processing can apply its flat field (after checking the checksum again)."""
    if profile is None:
        return None
    path = getattr(profile, "path", None)
    size = profile.measured_size() if hasattr(profile, "measured_size") else None
    return {"id": profile.id, "sha256": profile.sha256,
            "path": None if path is None else str(Path(path).resolve()),
            # the size its pixel pitch and flat field were measured at (processing scales them)
            "image_size_px": None if size is None else list(size)}


def _lights_section(plan, profile):
    nominal = nominal_light_directions()
    out = []
    for i, ch in enumerate(plan.lights):
        if profile is not None:
            lt = profile.lights
            if ch >= len(lt):
                raise BadInputError(f"LED channel {ch} is not in profile {profile.id!r}: it calibrated "
                                    f"{len(lt)} lights (channels 0..{len(lt) - 1})",
                                    hint="choose lights among those, or calibrate that LED")
            d, inten = lt.directions[ch].tolist(), lt.intensities[ch].tolist()
            pos = None if lt.positions_mm is None else lt.positions_mm[ch].tolist()
        else:
            d, inten, pos = (nominal[ch].tolist() if ch < len(nominal) else None), [1.0, 1.0, 1.0], None
        out.append({"index": i, "channel": ch, "direction": d, "position_mm": pos, "intensity": inten})
    return out


def _exposures_section(plan):
    return [{"index": e, "time_us": t, "current_mA": c if c else plan.light_current_mA[0],
             "mode": plan.mode} for e, (t, c) in enumerate(plan.exposures)]


def _groups(pending, n_lights):
    """Split missing (light, exposure) pairs into device runs: lights sharing the same
    set of missing exposures form one lights × exposures scan."""
    by_light = {}
    for l, e in sorted(pending):
        by_light.setdefault(l, []).append(e)
    groups = {}
    for l, es in by_light.items():
        groups.setdefault(tuple(es), []).append(l)
    return [(ls, list(es)) for es, ls in sorted(groups.items(), key=lambda kv: kv[1][0])]


class _Acquisition:
    link_timeout_s = 20.0   # how long a silent link is tolerated while the device scans
    link_report_s = 5.0     # how often the wait for a silent link is reported

    def __init__(self, rig, sd, plan, options):
        self.rig, self.sd, self.plan = rig, sd, plan
        self.camera = rig.camera
        self.progress = None
        self.on_frame = options.on_frame
        self.frame_timeout_s = options.frame_timeout_s
        self.poll_s = options.poll_s
        self.link_timeout_s = float(options.link_timeout_s)
        self.unmatched_dir = sd.path / "raw" / "unmatched"
        self.merger = None   # a LightMerger when merging during acquisition

    # -- files ------------------------------------------------------------------------
    def keep_unmatched(self, src, why):
        self.unmatched_dir.mkdir(parents=True, exist_ok=True)
        dst = self.unmatched_dir / Path(src).name
        n = 1
        while dst.exists():
            dst, n = self.unmatched_dir / f"{Path(src).stem}-{n}{Path(src).suffix}", n + 1
        self.sd.journal("unmatched", src=str(src), dst=str(dst.relative_to(self.sd.path)), why=why)
        move_file(src, dst, exit_code=EXIT_STOPPED)
        self.camera.claimed(src)
        return dst

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
        for p in self.camera.pending():
            self.keep_unmatched(p, why)

    def take(self, rec, light, exposure, run):
        """Move the camera's next file to raw/L<l>_E<e> and record it."""
        t_us, c = self.plan.exposures[exposure]

        src = self.camera.wait_for_file(self.frame_timeout_s)
        if self.plan.mode in ("camera", "bulb"):
            # the file's own exposure time must be the record's: a mismatch means a frame
            # without a record (or a camera set otherwise); never file it under the wrong name
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
        dst_rel = frame_name(light, exposure, src.suffix.lower())
        dst = self.sd.path / dst_rel
        record = {"file": dst_rel, "light": light, "exposure": exposure, "time_us": t_us,
                  "current_set_mA": rec["current_set_mA"], "current_meas_mA": rec["current_meas_mA"],
                  "start_us": rec["start_us"], "sync": rec["sync"], "retry": rec["retry"], "run": run,
                  "ring": rec["n"]}
        self.sd.journal("capture", src=str(src), record=record)
        if dst.exists():   # a frame taken again (after a reset): keep the earlier one too
            self.keep_unmatched_existing(dst)
        move_file(src, dst, exit_code=EXIT_STOPPED)
        self.camera.claimed(src)
        record["sha256"] = sha256_file(dst)
        self.sd.add_frame(record)
        self.sd.journal("captured", file=dst_rel, sha256=record["sha256"])
        if self.merger is not None:
            self.merge_if_complete(light)
        if self.progress is not None:
            self.progress.update(1)
        if self.on_frame is not None:
            self.on_frame(record)
        return record

    # -- merge during acquisition ----------------------------------------------------
    def merge_if_complete(self, light):
        """Queue a light's HDR merge once all its exposures have landed (and been hashed);
        store the merges that finished meanwhile."""
        done = self.sd.frames_done()
        if all((light, e) in done for e in range(len(self.plan.exposures))):
            self.merger.submit(self.sd.manifest, light)
        self.store_merged()

    def store_merged(self, wait=False):
        """Record the finished merges in scan.json; a held light goes to the scan directory
        object, for the processing that follows in this process."""
        finished = self.merger.collect(wait=wait)
        records = []
        for light, rec, held in finished:
            if isinstance(rec, Exception):
                self.sd.journal("hdr_error", light=light, error=f"{type(rec).__name__}: {rec}"[:300])
            else:
                records.append(rec)
                self.sd.journal("hdr_light", light=light, time_s=rec["time_s"])
                if held is not None:
                    self.sd.hold_light(light, held)
        if records:
            m = self.sd.manifest
            _, source = scan_sensor(m, self.merger.sensor)
            m.set_hdr(store_light_records(m, records, self.merger.basis(m), source))
            self.sd.save()

    def keep_unmatched_existing(self, dst):
        self.unmatched_dir.mkdir(parents=True, exist_ok=True)
        keep = self.unmatched_dir / f"{dst.stem}-superseded-{int(time.time() * 1e3)}{dst.suffix}"
        self.sd.journal("superseded", file=str(dst.relative_to(self.sd.path)),
                        kept=str(keep.relative_to(self.sd.path)))
        move_file(dst, keep)

    def stop_device(self):
        """Best effort: abort the device's run when the host stops the scan itself."""
        try:
            if self.rig.device.state() in ("ARMED", "RUNNING", "PAUSED"):
                self.sd.journal("abort", why="the host stopped the scan")
                self.rig.abort()
            self.wait_camera_quiet()
            self.sweep_camera("arrived after the host stopped the scan: no frame record")
        except Exception:   # the scan is stopping anyway; the journal says why
            pass

    def add_rig_time(self, end_us):
        self.sd.manifest.add_rig_time(end_us * 1e-6)
        self.sd.save()

    # -- device runs ------------------------------------------------------------------
    def prepare_device(self):
        dev = self.rig.device
        state = dev.state()
        if state in ("ARMED", "RUNNING", "PAUSED"):
            self.sd.journal("abort_stale", state=state)
            self.rig.abort()
            self.rig.wait_state({"ABORTED", "IDLE"}, timeout_s=30)
            self.wait_camera_quiet()
        names = self.rig.latched_faults()
        if names:
            if set(names) <= _BENIGN_FAULTS:
                self.sd.journal("clear_faults", faults=names)
                self.rig.clear_faults()
            else:
                self.sd.journal("fault_latched", faults=names)
                raise ScanError(f"the device has latched faults {names}: fix the cause (see `facette device "
                                "faults`), clear them (`facette device clear`) and run the scan again to resume")

    def wait_button(self, states):
        """Wait for a person to press the rig's button: until the state is one of `states`,
        or the device refuses the press (its last_error changes: then say why, in words).
        The host first makes last_error a known value (a refused PAUSE in IDLE, "not allowed
        in this state") so that a refusal of the press, even for the same reason, shows."""
        dev = self.rig.device
        try:
            self.rig.pause()
        except DeviceException:
            pass
        marker = dev.read("last_error")
        while True:
            state = dev.state()
            if state in states:
                return state
            code = dev.read("last_error")
            if code != marker:
                self.sd.journal("button_refused", last_error=code)
                raise ScanError(f"the rig's button was pressed but the device refused to start the "
                                f"scan: {self.rig.last_error()} (last_error {code})",
                                hint="fix that, then run the same scan command again")
            time.sleep(0.02)   # a person's press lasts far longer

    def run_group(self, lights, exposures, run, button):
        rig, plan = self.rig, self.plan
        channels = [plan.lights[l] for l in lights]
        self.prepare_device()
        self.sweep_camera("in the camera folder before this device run: no frame record")
        self.sd.journal("configure", run=run, lights=lights, exposures=exposures)
        rig.configure([plan.exposures[e] for e in exposures], lights=channels,
                      light_current_mA=[plan.light_current_mA[l] for l in lights], mode=plan.mode,
                      retries=plan.retries, **plan.timing)
        boot = rig.device.check_reset()
        initial = rig.device.state()        # read before anyone can press the button
        self.sd.journal("start", run=run, lights=lights, exposures=exposures, boot=boot, button=button)
        if button in ("wait", "press"):
            # the button arms and starts a configured scan from IDLE/DONE/ABORTED (a press
            # while armed or running aborts), so the host leaves the device unarmed here
            if button == "press":
                rig.press_button()          # returns once the device started (sent an event)
            else:
                print("press the rig's button to start the scan", flush=True)
                # a finished state counts only if it is not the one left by an earlier scan
                self.wait_button({"RUNNING", "PAUSED", "FAULT"} | ({"DONE", "ABORTED"} - {initial}))
        else:
            rig.start()
        seen, end_us = 0, 0
        link_down_since, last_answer = None, time.monotonic()
        while True:
            try:
                rig.device.check_reset()
                st = rig.status()
                records, seen, lost = rig.frame_records(seen, st["ring_count"])
                link_down_since, last_answer = None, time.monotonic()
            except DeviceReset as exc:
                self.add_rig_time(end_us)
                self.sd.journal("device_reset", run=run, old_boot=exc.old_boot, new_boot=exc.new_boot)
                self.sweep_camera("arrived during a run interrupted by a device reset: no frame record")
                return 0, "reset"
            except DeviceTimeout as exc:
                # a noisy link: the device keeps scanning and its ring keeps the records;
                # keep asking until the link has been silent for link_timeout_s, saying so
                now = time.monotonic()
                if link_down_since is None:
                    link_down_since, reported = last_answer, last_answer - self.link_report_s
                self.sd.journal("link_error", error=str(exc)[:200])
                silent = now - link_down_since
                if silent > self.link_timeout_s:
                    done, total = len(self.sd.frames_done()), len(plan.lights) * len(plan.exposures)
                    raise ScanError(f"lost the link to the device at {rig.device.url}: no answer for "
                                    f"{silent:.0f} s ({done}/{total} frames kept in {self.sd.path})",
                                    hint="check the cable and the rig's power, then run the same scan "
                                         "command again to resume") from exc
                if now - reported >= self.link_report_s:
                    reported = now
                    print(f"no answer from the device at {rig.device.url} for {silent:.0f} s; retrying "
                          f"until {self.link_timeout_s:.0f} s (Ctrl-C stops; the scan resumes with the "
                          "same command)", file=sys.stderr, flush=True)
                continue
            if lost:
                self.sd.journal("ring_overflow", lost=lost)
            for rec in records:
                if not (0 <= rec["light"] < len(lights) and 0 <= rec["exposure"] < len(exposures)):
                    continue
                light, exposure = lights[rec["light"]], exposures[rec["exposure"]]
                end_us = max(end_us, rec["start_us"] + plan.exposures[exposure][0])
                if not rec["sync"]:
                    self.sd.journal("no_sync", light=light, exposure=exposure, ring=rec["n"])
                    continue
                try:
                    self.take(rec, light, exposure, run)
                except CameraTimeout as exc:
                    self.sd.journal("missing_file", light=light, exposure=exposure, ring=rec["n"], error=str(exc))
                    self.stop_device()
                    raise ScanError(f"the device took light {light} exposure {exposure} (flash sync seen) but "
                                    f"no image arrived: {exc}") from exc
                except ScanError:
                    self.stop_device()
                    raise
            state = st["state"]
            if state == "DONE" and seen >= st["ring_count"]:
                return end_us, "done"
            if state in ("FAULT", "ABORTED", "IDLE") and seen >= st["ring_count"]:
                self.add_rig_time(end_us)      # the time this stopped run took still counts
                faults = rig.faults()
                self.sd.journal("stopped", state=state, faults=faults, run=run)
                self.wait_camera_quiet()
                self.sweep_camera(f"arrived after the device stopped ({state})")
                done = len(self.sd.frames_done())
                total = len(plan.lights) * len(plan.exposures)
                if state == "ABORTED":
                    raise ScanAborted(f"scan aborted with {done}/{total} frames in {self.sd.path}",
                                      hint="run the same scan again to resume")
                if not faults["latched"]:     # nothing latched: the device refused to start
                    raise ScanError(f"the device did not run the scan ({state}): it refused with "
                                    f"\"{rig.last_error()}\" ({done}/{total} frames kept in {self.sd.path})",
                                    hint="fix that, then run the same scan again to resume")
                raise ScanError(f"the device stopped in {state} with faults {faults['latched']} "
                                f"({done}/{total} frames kept in {self.sd.path})",
                                hint="fix the cause (facette device --port PORT faults), clear the "
                                     "faults and run the same scan again to resume")
            time.sleep(self.poll_s)


def _recover(sd, camera):
    """Finish what the journal says was under way when the last run stopped."""
    entries = sd.read_journal()
    done = {e["file"] for e in entries if e.get("step") == "captured"}
    for e in entries:
        if e.get("step") != "capture":
            continue
        rec = dict(e["record"])
        if rec["file"] in done:
            continue
        dst, src = sd.path / rec["file"], Path(e["src"])
        if not dst.exists() and src.exists():
            move_file(src, dst, exit_code=EXIT_STOPPED)
        if dst.exists():
            rec["sha256"] = sha256_file(dst)
            sd.add_frame(rec)
            sd.journal("recovered", file=rec["file"], sha256=rec["sha256"])
            done.add(rec["file"])


def _is_meter_dir(path):
    return path.is_dir() and (path.name == METER_DIR or path.name.startswith(METER_DIR + "-"))


@dataclasses.dataclass
class ScanOptions:
    """How `run_scan` acquires: what to take, and how to run the rig.

    exposures : times in µs or (time_us, current_mA) pairs; "thesis" or None: the thesis
        bracket; "adaptive": meter each light once (into ``directory/meter``), plan the
        fewest exposures reaching 40 dB on the object without clipping it
        (`facette.scan.adaptive`), then scan them (a resume keeps the recorded plan)
    lights : LED channels in scan order (default every LED)
    light_current_mA : int or one per light
    mode : "camera" | "bulb" | "led"
    retries : repeats of a setting with a missing flash sync
    timing : other µs registers (settle_us, gap_us, ...)
    button : None (start now), "wait" (the rig's button starts it) or "press" (a rig that
        presses its own button, the simulated one: `Rig.can_press_button`)
    progress : show a tqdm progress bar
    on_frame : callable(record) after each frame is stored (tests use it to abort/pause)
    frame_timeout_s : how long to wait for the camera's file after its record
    poll_s : how often the device is polled while it scans
    max_runs : device runs allowed (resets re-run the missing frames)
    link_timeout_s : how long the device may stay silent before the scan stops (its wait
        is reported on standard error every few seconds)
    save_truth : write the rig's truth beside scan.json when it has one (`Rig.save_truth`:
        the simulated rig's; a real rig has none)
    merge_hdr : merge each light into hdr/ on a worker as soon as its frames have landed
        (`facette.scan.LightMerger`, with the scan's sensor model), so that after the last
        frame only that light's merge remains; recorded in scan.json "hdr" with what each
        image was made from. A resumed scan merges only the lights not merged yet (or whose
        frames changed); `merge_scan` and `facette process` then find nothing to do.
    hold_hdr : with merge_hdr, also keep each merged light in memory, in the returned
        `ScanDirectory` (`take_held_light`), for processing right after the scan
        (``facette.process(scan)``), which then does not read the HDR files back
        (4288x2848, 12 lights: ~2 CPU s less after the last frame, ~50 MB per light held
        until processing takes it or `release_held_lights` drops it).
    """
    exposures: object = None
    lights: object = None
    light_current_mA: object = 500
    mode: str = "camera"
    retries: int = 1
    timing: dict | None = None
    button: str | None = None
    progress: bool = True
    on_frame: object = None
    frame_timeout_s: float = 60.0
    poll_s: float = 0.003
    max_runs: int = 8
    link_timeout_s: float = 20.0
    save_truth: bool = True
    merge_hdr: bool = False
    hold_hdr: bool = False

    def check(self, rig):
        """Refuse what cannot be asked of this rig (ValueError / BadInputError), before anything
        is touched."""
        if rig.camera is None:
            raise ValueError("this rig has no camera backend: connect with camera=FolderWatchCamera(folder) "
                             "or GPhoto2Camera()")
        if isinstance(self.exposures, str) and self.exposures not in ("thesis", "adaptive"):
            raise ValueError(f"exposures must be 'adaptive', 'thesis' or a list of exposures, got "
                             f"{self.exposures!r}")
        if self.button not in (None, "wait", "press"):
            raise ValueError(f"button must be None, 'wait' or 'press', got {self.button!r}")
        if self.button == "press" and not rig.can_press_button:
            raise BadInputError("this rig's button is pressed by a person, not by the host",
                                hint="wait for the press instead (button='wait', --wait-button)")

    def plan(self, n_leds, exposures, light_current_mA=None):
        """The `ScanPlan` of these options with `exposures` (a list; None: the thesis bracket)
        and, once known, the light currents."""
        return default_plan(n_leds, exposures, self.lights,
                            self.light_current_mA if light_current_mA is None else light_current_mA,
                            self.mode, self.retries, self.timing)


def run_scan(rig, directory, profile=None, options=None, **settings):
    """Acquire (or resume) a scan into `directory`; returns the `ScanDirectory` (with the
    lights it merged held in memory when ``hold_hdr``: pass it to ``facette.process``).

    Parameters
    ----------
    rig : facette.scan.Rig with a camera backend (`rig.camera`)
    directory : path of the scan directory (created; an existing one with the same
        plan is resumed, one with another plan is refused)
    profile : facette.calib.Profile, its folder, or None (nominal light directions)
    options : `ScanOptions` (default: its defaults)
    settings : fields of `ScanOptions` to set (``exposures=..., lights=..., button="wait"``)

    The steps: check the options and plan against the rig (`_plan`: nothing touched when
    refused; an adaptive scan meters first), take the directory (`_open`: create it, or
    resume it), acquire the missing frames (`_acquire`), then record its completion
    (`_finish`).
    """
    options = dataclasses.replace(options or ScanOptions(), **settings)
    options.check(rig)
    profile = _load_profile(profile)
    sd = ScanDirectory(directory)
    try:
        plan, lights_section, bracketing, button = _plan(rig, sd, profile, options)
        sd.lock()                            # one writer; scan.json is read again under the lock
        _check_resumable(sd, plan)
        _open(rig, sd, plan, profile, lights_section, bracketing)
        _acquire(rig, sd, plan, options, button)
        _finish(rig, sd, plan, options)
        return sd
    finally:
        sd.unlock()


def _plan(rig, sd, profile, options):
    """(ScanPlan, its lights section, bracketing record, how the scan starts) once checked against the device's
    limits, the profile and the directory (a refused plan leaves nothing behind). An adaptive
    scan first takes the directory and meters each light (a resume keeps the recorded plan)."""
    n_leds = len(profile.lights) if profile is not None else rig.n_lights
    exposures, currents, button = options.exposures, None, options.button
    if exposures == "adaptive":
        # lights and currents before any metering; the metering writes <directory>/meter/:
        # the directory is ours before that (a second scan into a directory being written
        # touches nothing in it)
        pre = options.plan(n_leds, [(1000, 0)])
        _lights_section(pre, profile)
        rig.check_config(pre.exposures, pre.lights, pre.light_current_mA, pre.mode, pre.timing)
        sd.lock()
        exposures, currents, bracketing = _adaptive(rig, sd, profile, options)
        button = None   # the button started the metering
    else:
        bracketing = {"name": "thesis2016" if exposures in (None, "thesis") else "explicit"}
        exposures = None if exposures == "thesis" else exposures
    plan = options.plan(n_leds, exposures, currents)
    lights_section = _lights_section(plan, profile)
    rig.check_config(plan.exposures, plan.lights, plan.light_current_mA, plan.mode, plan.timing)
    _check_resumable(sd, plan)
    return plan, lights_section, bracketing, button


def _adaptive(rig, sd, profile, options):
    """(exposures, light currents, bracketing record) of an adaptive scan: the plan a started
    scan recorded (a resume never re-plans), else meter each light and plan."""
    m = sd.manifest
    if m is not None:
        old = m.plan or {}
        return ([tuple(e) for e in old.get("exposures", [])],
                old.get("light_current_mA", options.light_current_mA), m.bracketing or {"name": "adaptive"})
    meter = dataclasses.replace(options, progress=False, on_frame=None, save_truth=False, merge_hdr=False,
                                hold_hdr=False)

    def scan(path, exposures, btn):
        return run_scan(rig, path, profile, meter, exposures=exposures, button=btn)

    sensor = profile.sensor if profile is not None and profile.sensor else rig.sensor
    lights = options.lights
    n = len(lights) if lights is not None else (len(profile.lights) if profile is not None else rig.n_lights)
    current = options.light_current_mA
    currents = list(current) if hasattr(current, "__len__") else [current] * n
    plan, record = meter_and_plan(scan, sd.path, currents, options.mode, sensor, button=options.button)
    kw = plan.scan_kwargs()
    return kw["exposures"], kw.get("light_current_mA", current), record


def _check_resumable(sd, plan):
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


def _open(rig, sd, plan, profile, lights_section, bracketing):
    """A new scan: its manifest (the plan, the profile's calibration, the bracketing); a
    resumed one: finish what the journal says was under way, set damaged frames aside."""
    sd.notes = []
    if sd.manifest is not None:
        sd.journal("resume", rig=rig.identity)
        _recover(sd, rig.camera)
        sd.notes += sd.set_aside_damaged()     # a frame whose sha256 fails is taken again
        begin = next((e for e in sd.read_journal() if e.get("step") == "begin"), {})
        if hasattr(rig.camera, "ignore"):   # files that predate the scan are not ours
            rig.camera.ignore(begin.get("camera_ignored", []))
        return
    pitch = getattr(profile, "pixel_pitch_mm", None)
    if pitch is None:
        pitch = rig.pixel_pitch_mm          # a simulated rig knows its own; a real one says None
    ignored = rig.camera.ignore_existing()
    sd.journal("begin", plan=plan.to_dict(), rig=rig.identity, camera=repr(rig.camera),
               camera_ignored=ignored)
    sd.create(rig.identity, _profile_section(profile), pitch, lights_section,
              _exposures_section(plan), plan.to_dict())
    if profile is not None:
        sd.manifest.set_calibration(profile.sensor or None, profile.radiometric_scale)
        if not profile.sensor:
            sd.notes.append(f"profile {profile.id} has no sensor section: the HDR merge will use "
                            "a nominal noise model (calibrate the sensor to get the camera's own)")
    sd.manifest.set_bracketing(bracketing)   # the metering runs are rig time of this scan too
    sd.save()


def _acquire(rig, sd, plan, options, button):
    """Take every (light, exposure) still missing, in device runs (a reset runs the missing
    ones again), merging each complete light on a worker with ``merge_hdr``."""
    acq = _Acquisition(rig, sd, plan, options)
    all_pairs = {(l, e) for l in range(len(plan.lights)) for e in range(len(plan.exposures))}
    if options.merge_hdr:
        acq.merger = LightMerger(sd.path, hold=options.hold_hdr)
        done = sd.frames_done()
        for light in range(len(plan.lights)):   # a resumed scan: lights complete, not merged yet
            if all((light, e) in done for e in range(len(plan.exposures))) and \
                    acq.merger.stale(sd.manifest, light):
                acq.merger.submit(sd.manifest, light)
    if options.progress:
        from tqdm import tqdm

        acq.progress = tqdm(total=len(all_pairs), initial=len(sd.frames_done()), unit="frame", desc="scan",
                            leave=True, dynamic_ncols=True)
    try:
        for _ in range(options.max_runs):
            pending = all_pairs - set(sd.frames_done())
            if not pending:
                break
            for ls, es in _groups(pending, len(plan.lights)):
                run = sd.manifest.start_run()      # saved with the next manifest write
                end_us, how = acq.run_group(ls, es, run, button)
                button = None           # the button starts the first run only
                acq.add_rig_time(end_us)
                if how == "reset":
                    break
        pending = all_pairs - set(sd.frames_done())
        if pending:
            raise ScanError(f"{len(pending)} frames still missing after {options.max_runs} device runs "
                            f"in {sd.path}")
    except BaseException as exc:   # say in the journal why this run stopped (then re-raise)
        sd.journal("interrupted", error=f"{type(exc).__name__}: {exc}", frames=len(sd.manifest.frames))
        raise
    finally:
        if acq.progress is not None:
            acq.progress.close()
        if acq.merger is not None:
            acq.store_merged(wait=True)   # the last light's merge (an interrupted scan keeps the rest)
            acq.merger.close()


def _finish(rig, sd, plan, options):
    """The scan is complete: the rig's truth beside it (a simulated rig's), what went wrong on
    the way (from the journal), "complete" set."""
    if options.save_truth:
        sd.manifest.set_truth(rig.save_truth(sd.path, channels=plan.lights))
    sd.manifest.finish([e for e in sd.read_journal() if e.get("step") in
                        ("device_reset", "no_sync", "unmatched", "clear_faults")])
    sd.save()
    sd.journal("done", frames=len(sd.manifest.frames), rig_time_s=sd.manifest.rig_time_s)
