"""One device run of a scan: the device made ready (a stale run aborted, harmless latched
faults cleared), configured for a group of lights × exposures, started (or its button waited
for), then polled: each frame record whose flash sync was seen gets the camera's next file
(`FrameFiler`), until the device is done, resets, stops or stays silent too long."""
from __future__ import annotations

import sys
import time

from facette.camera.folder import CameraTimeout
from facette.device.client import DeviceException, DeviceReset, DeviceTimeout
from facette.scan._errors import ScanAborted, ScanError
from facette.scan._frames import FrameFiler

__all__ = ["DeviceRuns"]

# Faults that report a past event and do not make the next scan unsafe.
_BENIGN_FAULTS = frozenset({"HOST_SILENT", "CAL_INVALID", "WATCHDOG_RESET"})


class _LinkWatch:
    """How long the device has not answered; says so on standard error every `report_s`."""

    def __init__(self, timeout_s, report_s):
        self.timeout_s, self.report_s = timeout_s, report_s
        self.down_since, self.last_answer, self.reported = None, time.monotonic(), None

    def answered(self):
        self.down_since, self.last_answer = None, time.monotonic()

    def silent_s(self):
        """Seconds without an answer (the silence starts at the last answer)."""
        now = time.monotonic()
        if self.down_since is None:
            self.down_since, self.reported = self.last_answer, self.last_answer - self.report_s
        return now - self.down_since

    def due(self):
        """True once every `report_s` of silence (then it is reported)."""
        now = time.monotonic()
        if now - self.reported >= self.report_s:
            self.reported = now
            return True
        return False


class DeviceRuns:
    """The device runs of one scan: `run_group` takes one group of lights × exposures.

    rig : `facette.scan.Rig`; sd : its `ScanDirectory`; plan : the `ScanPlan`
    options : `ScanOptions` (on_frame, frame_timeout_s, poll_s, link_timeout_s)
    merge : a `MergeDuringScan` told of each frame, or None; progress : a tqdm bar, or None
    """
    link_timeout_s = 20.0   # how long a silent link is tolerated while the device scans
    link_report_s = 5.0     # how often the wait for a silent link is reported

    def __init__(self, rig, sd, plan, options, merge=None, progress=None):
        self.rig, self.sd, self.plan = rig, sd, plan
        self.files = FrameFiler(sd, rig.camera, plan, options.frame_timeout_s)
        self.on_frame = options.on_frame
        self.poll_s = options.poll_s
        self.link_timeout_s = float(options.link_timeout_s)
        self.merge, self.progress = merge, progress

    # -- before a run ------------------------------------------------------------------------
    def prepare_device(self):
        """Abort a run left over from an earlier scan; clear harmless latched faults, stop
        (ScanError) on any other."""
        state = self.rig.device.state()
        if state in ("ARMED", "RUNNING", "PAUSED"):
            self.sd.journal("abort_stale", state=state)
            self.rig.abort()
            self.rig.wait_state({"ABORTED", "IDLE"}, timeout_s=30)
            self.files.wait_camera_quiet()
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

    def start_run(self, lights, exposures, run, button):
        """Configure the device for lights × exposures (indices into the plan) and start it: now,
        by pressing its button, or by waiting for a person to press it."""
        rig, plan = self.rig, self.plan
        self.prepare_device()
        self.files.sweep_camera("in the camera folder before this device run: no frame record")
        self.sd.journal("configure", run=run, lights=lights, exposures=exposures)
        rig.configure([plan.exposures[e] for e in exposures], lights=[plan.lights[l] for l in lights],
                      light_current_mA=[plan.light_current_mA[l] for l in lights], mode=plan.mode,
                      retries=plan.retries, **plan.timing)
        boot = rig.device.check_reset()
        initial = rig.device.state()        # read before anyone can press the button
        self.sd.journal("start", run=run, lights=lights, exposures=exposures, boot=boot, button=button)
        if button == "press":
            # the button arms and starts a configured scan from IDLE/DONE/ABORTED (a press
            # while armed or running aborts), so the host leaves the device unarmed here
            rig.press_button()          # returns once the device started (sent an event)
        elif button == "wait":
            print("press the rig's button to start the scan", flush=True)
            # a finished state counts only if it is not the one left by an earlier scan
            self.wait_button({"RUNNING", "PAUSED", "FAULT"} | ({"DONE", "ABORTED"} - {initial}))
        else:
            rig.start()

    # -- during a run --------------------------------------------------------------------
    def run_group(self, lights, exposures, run, button):
        """One device run of lights × exposures: (device time µs it took, "done" | "reset")."""
        self.start_run(lights, exposures, run, button)
        seen, end_us = 0, 0
        link = _LinkWatch(self.link_timeout_s, self.link_report_s)
        while True:
            try:
                self.rig.device.check_reset()
                st = self.rig.status()
                records, seen, lost = self.rig.frame_records(seen, st["ring_count"])
                link.answered()
            except DeviceReset as exc:
                self.add_rig_time(end_us)
                self.sd.journal("device_reset", run=run, old_boot=exc.old_boot, new_boot=exc.new_boot)
                self.files.sweep_camera("arrived during a run interrupted by a device reset: no frame record")
                return 0, "reset"
            except DeviceTimeout as exc:
                # a noisy link: the device keeps scanning and its ring keeps the records;
                # keep asking until the link has been silent for link_timeout_s, saying so
                self.link_silent(link, exc)
                continue
            if lost:
                self.sd.journal("ring_overflow", lost=lost)
            end_us = max(end_us, self.take_records(records, lights, exposures, run))
            state = st["state"]
            if state == "DONE" and seen >= st["ring_count"]:
                return end_us, "done"
            if state in ("FAULT", "ABORTED", "IDLE") and seen >= st["ring_count"]:
                self.add_rig_time(end_us)      # the time this stopped run took still counts
                self.stopped(state, run)
            time.sleep(self.poll_s)

    def link_silent(self, link, exc):
        """The device did not answer: journal it, report the wait every few seconds, and stop the
        scan (ScanError) once it has been silent for `link_timeout_s`."""
        silent = link.silent_s()
        self.sd.journal("link_error", error=str(exc)[:200])
        url = self.rig.device.url
        if silent > link.timeout_s:
            raise ScanError(f"lost the link to the device at {url}: no answer for "
                            f"{silent:.0f} s ({self._count()} frames kept in {self.sd.path})",
                            hint="check the cable and the rig's power, then run the same scan "
                                 "command again to resume") from exc
        if link.due():
            print(f"no answer from the device at {url} for {silent:.0f} s; retrying "
                  f"until {link.timeout_s:.0f} s (Ctrl-C stops; the scan resumes with the "
                  "same command)", file=sys.stderr, flush=True)

    def take_records(self, records, lights, exposures, run):
        """File the camera's image of each synced frame record of this run (its light and
        exposure indices are the run's); returns the device time (µs) the records reach."""
        end_us = 0
        for rec in records:
            if not (0 <= rec["light"] < len(lights) and 0 <= rec["exposure"] < len(exposures)):
                continue
            light, exposure = lights[rec["light"]], exposures[rec["exposure"]]
            end_us = max(end_us, rec["start_us"] + self.plan.exposures[exposure][0])
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
        return end_us

    def take(self, rec, light, exposure, run):
        """File one frame (`FrameFiler.file`), then tell the merge, the progress bar and
        `on_frame`; returns its record."""
        record = self.files.file(rec, light, exposure, run)
        if self.merge is not None:
            self.merge.frame_landed(light)
        if self.progress is not None:
            self.progress.update(1)
        if self.on_frame is not None:
            self.on_frame(record)
        return record

    # -- after a run -----------------------------------------------------------------------
    def _count(self):
        """"done/total" frames of the plan on disk."""
        return f"{len(self.sd.frames_done())}/{len(self.plan.lights) * len(self.plan.exposures)}"

    def stopped(self, state, run):
        """The device stopped before the run's end (FAULT, ABORTED, IDLE): keep the stray files
        and stop the scan, saying why (ScanAborted, or ScanError with the faults or the refusal)."""
        faults = self.rig.faults()
        self.sd.journal("stopped", state=state, faults=faults, run=run)
        self.files.wait_camera_quiet()
        self.files.sweep_camera(f"arrived after the device stopped ({state})")
        count = self._count()
        if state == "ABORTED":
            raise ScanAborted(f"scan aborted with {count} frames in {self.sd.path}",
                              hint="run the same scan again to resume")
        if not faults["latched"]:     # nothing latched: the device refused to start
            raise ScanError(f"the device did not run the scan ({state}): it refused with "
                            f"\"{self.rig.last_error()}\" ({count} frames kept in {self.sd.path})",
                            hint="fix that, then run the same scan again to resume")
        raise ScanError(f"the device stopped in {state} with faults {faults['latched']} "
                        f"({count} frames kept in {self.sd.path})",
                        hint="fix the cause (facette device --port PORT faults), clear the "
                             "faults and run the same scan again to resume")

    def stop_device(self):
        """Best effort: abort the device's run when the host stops the scan itself."""
        try:
            if self.rig.device.state() in ("ARMED", "RUNNING", "PAUSED"):
                self.sd.journal("abort", why="the host stopped the scan")
                self.rig.abort()
            self.files.wait_camera_quiet()
            self.files.sweep_camera("arrived after the host stopped the scan: no frame record")
        except Exception:   # the scan is stopping anyway; the journal says why
            pass

    def add_rig_time(self, end_us):
        self.sd.manifest.add_rig_time(end_us * 1e-6)
        self.sd.save()
