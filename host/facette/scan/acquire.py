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

The pieces, each in a module of its own: the plan and the scan.json sections it decides
(`scan._plan`), taking a directory again (`scan._resume`), one device run (`scan._device_run`),
the camera's files into raw/ (`scan._frames`), the HDR merge during acquisition
(`scan._merge`); this module puts them in order (`run_scan`) and holds its `ScanOptions`.
"""
from __future__ import annotations

import dataclasses

from facette.errors import BadInputError
from facette.hdr import THESIS_BRACKET_US
from facette.scan._device_run import DeviceRuns
from facette.scan._errors import ScanAborted, ScanError
from facette.scan._merge import MergeDuringScan
from facette.scan._plan import (ScanPlan, default_plan, device_run_groups, exposures_section, lights_section,
                                load_scan_profile, profile_section)
from facette.scan._resume import check_resumable, resume
from facette.scan.adaptive import meter_and_plan
from facette.scan.directory import ScanDirectory

__all__ = ["run_scan", "ScanOptions", "ScanPlan", "ScanError", "ScanAborted", "THESIS_BRACKET_US", "default_plan"]


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
    on_frame : callable(`Frame`) after each frame is stored (tests use it to abort/pause)
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
    on_held : with hold_hdr, callable(sd, light) called on the scan's thread as each merged light is
        held: the processing that follows starts its per-light work there, before the last frame
        (`facette.pipeline.ArrivingLights`: it takes the light, `ScanDirectory.take_held`, and leaves
        what it made in `sd.prepared` for ``facette.process``).
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
    on_held: object = None

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
    profile = load_scan_profile(profile)
    sd = ScanDirectory(directory)
    try:
        plan, lights, bracketing, button = _plan(rig, sd, profile, options)
        sd.lock()                            # one writer; scan.json is read again under the lock
        check_resumable(sd, plan)
        _open(rig, sd, plan, profile, lights, bracketing)
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
        lights_section(pre, profile)
        rig.check_config(pre.exposures, pre.lights, pre.light_current_mA, pre.mode, pre.timing)
        sd.lock()
        exposures, currents, bracketing = _adaptive(rig, sd, profile, options)
        button = None   # the button started the metering
    else:
        bracketing = {"name": "thesis2016" if exposures in (None, "thesis") else "explicit"}
        exposures = None if exposures == "thesis" else exposures
    plan = options.plan(n_leds, exposures, currents)
    lights = lights_section(plan, profile)
    rig.check_config(plan.exposures, plan.lights, plan.light_current_mA, plan.mode, plan.timing)
    check_resumable(sd, plan)
    return plan, lights, bracketing, button


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


def _open(rig, sd, plan, profile, lights, bracketing):
    """A new scan: its manifest (the plan, the profile's calibration, the bracketing); a
    resumed one: finish what the journal says was under way, set damaged frames aside."""
    sd.notes = []
    if sd.manifest is not None:
        resume(rig, sd)
        return
    pitch = getattr(profile, "pixel_pitch_mm", None)
    if pitch is None:
        pitch = rig.pixel_pitch_mm          # a simulated rig knows its own; a real one says None
    ignored = rig.camera.ignore_existing()
    sd.journal("begin", plan=plan.to_dict(), rig=rig.identity, camera=repr(rig.camera),
               camera_ignored=ignored)
    sd.create(rig.identity, profile_section(profile), pitch, lights,
              exposures_section(plan), plan.to_dict())
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
    all_pairs = plan.all_pairs()
    merge = MergeDuringScan(sd, len(plan.exposures), hold=options.hold_hdr,
                            on_held=options.on_held if options.hold_hdr else None) if options.merge_hdr else None
    if merge is not None:
        merge.submit_stale(len(plan.lights))   # a resumed scan: lights complete, not merged yet
    progress = None
    if options.progress:
        from tqdm import tqdm

        progress = tqdm(total=len(all_pairs), initial=len(sd.frames_done()), unit="frame", desc="scan",
                        leave=True, dynamic_ncols=True)
    runs = DeviceRuns(rig, sd, plan, options, merge=merge, progress=progress)
    try:
        for _ in range(options.max_runs):
            pending = all_pairs - set(sd.frames_done())
            if not pending:
                break
            for ls, es in device_run_groups(pending):
                run = sd.manifest.start_run()      # saved with the next manifest write
                end_us, how = runs.run_group(ls, es, run, button)
                button = None           # the button starts the first run only
                runs.add_rig_time(end_us)
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
        if progress is not None:
            progress.close()
        if merge is not None:
            merge.close()   # the last light's merge (an interrupted scan keeps the rest)


def _finish(rig, sd, plan, options):
    """The scan is complete: the rig's truth beside it (a simulated rig's), what went wrong on
    the way (from the journal), "complete" set."""
    if options.save_truth:
        sd.manifest.set_truth(rig.save_truth(sd.path, channels=plan.lights))
    sd.manifest.finish([e for e in sd.read_journal() if e.get("step") in
                        ("device_reset", "no_sync", "unmatched", "clear_faults")])
    sd.save()
    sd.journal("done", frames=len(sd.manifest.frames), rig_time_s=sd.manifest.rig_time_s)
