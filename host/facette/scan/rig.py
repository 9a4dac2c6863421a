"""`Rig`: the instrument as a user scripts it (docs/conventions.md, "Scripting"): the
device's registers and a camera backend; `Rig.scan` acquires a scan directory. It sits in
the scan layer because it brings these together (the device layer below knows only the
Modbus client and the register map).

`Rig` is also the one boundary between acquisition and whatever rig it runs on: the
acquisition (`facette.scan.acquire`) never asks which kind of rig it has. What it may ask
beyond the device and the camera is four things, which a real rig answers as "unknown":
`sensor` (the camera's noise model), `pixel_pitch_mm`, `save_truth` (what the object really
is) and `press_button`/`can_press_button`; and the latched faults by name
(`latched_faults`). The calibration wizard asks two more: `show_target` and `restore_scene`
(a person places a real rig's targets), and the rig's `name`. The benchmarks and the command
line ask two more, again "unknown" on a real rig: `truth` (what `save_truth` writes, as
arrays: the benchmarks compare a calibration with it) and `simulated_events` (the shots a
simulator lost and the reboots it made on purpose). `SimRig`, the simulated rig
(``connect("sim")``), answers them from its simulator, the only way the simulator reaches
acquisition, the wizard, the benchmarks and the command line: outside `facette.sim` only
`SimRig` touches it (``host/tests/test_rig_door.py`` checks).

    rig = facette.connect("sim")              # or "/dev/ttyACM0", "socket://127.0.0.1:5020"
    rig.configure(exposures=[(1_000_000, 500)], lights=range(12))
    scan = rig.scan("out/plaque", profile=profile)
"""
from __future__ import annotations

import time

from facette.camera import FolderWatchCamera
from facette.device import registers as R
from facette.device.client import FW_ERRORS, DeviceClient, DeviceError, DeviceException
from facette.errors import BadInputError
from facette.hdr import TIMING_MODES
from facette.scan.acquire import run_scan
from facette.sim import SimulatedRig
from facette.sim.targets import restore_scene, show_target

__all__ = ["Rig", "SimRig", "connect", "decode_frame_record", "TIMING_MODES", "RigFault"]

TIMING_KEYS = ("prefocus_us", "mirror_up_us", "settle_us", "gap_us", "led_pre_us", "led_post_us",
               "sync_timeout_us")
RING_STRIDE = 8

class RigFault(DeviceError):
    """The device latched a fault (over-temperature, open LED, missed sync...)."""

    def __init__(self, message, faults):
        super().__init__(message)
        self.faults = faults

def decode_frame_record(words, n):
    """Decode one 8-word frame-ring record (see protocol/registers.toml, ring_*)."""
    return {"n": n, "frame": words[0], "light": words[1], "exposure": words[2],
            "current_set_mA": words[3], "current_meas_mA": words[4],
            "start_us": (words[5] << 16) | words[6], "sync": bool(words[7] & 1),
            "retry": bool(words[7] & 2), "valid": bool(words[7] & 4)}

class Rig:
    """A connected rig: device registers plus (optionally) a camera backend.

    Parameters
    ----------
    device : DeviceClient
    camera : a camera backend (facette.camera) or None
    """
    sim = None                  # the simulator behind a `SimRig` (for tests only: the package asks the Rig)
    can_press_button = False    # a person presses a real rig's button

    def __init__(self, device, camera=None):
        self.device = device
        self.camera = camera
        self.config = None

    # -- what a real rig does not know (a simulated one does: `SimRig`) --------------------
    @property
    def sensor(self):
        """The camera's noise model when the rig knows it (a SensorModel), else None: a real
        rig's comes from its calibration profile."""
        return None

    @property
    def pixel_pitch_mm(self):
        """mm per HDR pixel on the object when the rig knows it, else None (a real rig's comes
        from its calibration profile)."""
        return None

    def save_truth(self, directory, channels):
        """Write what the object really is beside a scan (normals, heights, ... for the LED
        `channels` in scan order); returns the file's name in `directory`, or None when the
        rig does not know it (a real rig never does)."""
        return None

    def truth(self):
        """What the object and the lights really are, as `save_truth` writes it (arrays at the HDR
        resolution: ``normals``, ``height_mm``, ``mask``, ``albedo``, ``light_dirs``,
        ``light_intensity``, ``light_positions_mm`` (NaN for far lights), one row per LED channel;
        docs/scan-format.md, "truth.npz"), or None when the rig does not know it (a real rig never
        does)."""
        return None

    def simulated_events(self):
        """What the rig's simulator did on purpose, {"shots", "frames", "missed" (shots lost),
        "boots", "virtual_us"}, or None (a real rig has no simulator)."""
        return None

    @property
    def name(self):
        """The rig's name for its calibration profile: rig-<serial number>."""
        return f"rig-{self.device.identity.get('serial_number', 0)}"

    def show_target(self, target, fault=None, **scene):
        """Put a calibration target under the camera: a person does that on a real rig (the
        wizard asks them), so nothing happens here; returns None."""
        return None

    def restore_scene(self):
        """Give the camera its object back after the calibration targets (a person's job)."""

    def press_button(self):
        """Press the rig's own button (only a rig with `can_press_button`)."""
        raise BadInputError("this rig's button is pressed by a person, not by the host",
                            hint="wait for the press instead (button='wait', --wait-button)")

    # -- identity and status -------------------------------------------------------
    @property
    def identity(self):
        """Firmware version, protocol, definition hash, serial, boot count, LED count..."""
        ident = dict(self.device.identity)
        v = ident.get("fw_version", 0)
        ident["fw_version"] = f"{v >> 8}.{v & 0xFF}"
        ident["definition_hash"] = f"{ident.get('definition_hash', 0):#010x}"
        return ident

    @property
    def n_lights(self):
        """LEDs fitted: 12 (the thesis rig; the firmware drives up to `max_leds` channels, not
        all of which need an LED)."""
        return min(self.device.identity.get("max_leds", 12) or 12, 12)

    def status(self):
        """State, faults, progress of the scan: a dict (times in µs)."""
        st = self.device.read_block(["state", "fault_bits", "current_light", "current_exposure",
                                     "frames_done", "frames_expected", "time_left_us", "ring_count",
                                     "retries_used", "fault_log_count", "last_error"])
        st["state"] = R.enum_name("state", st["state"])
        st["faults"] = _fault_names(st["fault_bits"])
        return st

    def progress(self):
        """(frames_done, frames_expected)."""
        st = self.device.read_block(["frames_done", "frames_expected"])
        return st["frames_done"], st["frames_expected"]

    def latched_faults(self):
        """Names of the faults the device has latched (empty when none)."""
        return _fault_names(self.device.read("fault_bits"))

    def faults(self):
        """Latched faults (names) and the fault log: {"latched": [...], "log": [{"code", "detail", "time_ms"}]}."""
        bits = self.device.read("fault_bits")
        count = self.device.read("fault_log_count")
        log = []
        for n in range(max(0, count - 8), count):
            i = n % 8
            e = self.device.read_block(["fault_log_code", "fault_log_detail", "fault_log_time_ms"], index=i)
            log.append({"code": R.enum_name("fault", e["fault_log_code"]),
                        "detail": e["fault_log_detail"], "time_ms": e["fault_log_time_ms"]})
        return {"latched": _fault_names(bits), "log": log}

    def measurements(self):
        m = self.device.read_block(["led_temp_cC", "led_current_mA", "supply_mV", "led_channel", "led_set_mA"])
        m["led_temp_C"] = m.pop("led_temp_cC") / 100.0
        return m

    def last_error(self):
        """The device's reason for the last request it refused, in words ("none" if none)."""
        code = self.device.read("last_error")
        return FW_ERRORS.get(code, f"error {code}")

    # -- configuration and commands ------------------------------------------------
    def limits(self):
        """The device's own limits that decide whether it arms a scan: max_current_mA, the
        hard limit, max_pulse_us (µs), settle_us (µs), and the per-channel current gains."""
        d = self.device
        hard = R.register("max_current_mA").maximum
        return {"max_current_mA": d.read("max_current_mA"), "hard_max_current_mA": hard,
                "max_pulse_us": d.read("max_pulse_us"), "hard_max_pulse_us": R.register("max_pulse_us").maximum,
                "settle_us": d.read("settle_us"), "gains": self.gains()}

    def check_config(self, exposures, lights, light_current_mA, mode="camera", timing=None):
        """Refuse (BadInputError naming the limit) what the device would refuse at ARM.

        Mirrors the firmware's seq_validate_config: every frame's current, after the
        channel's gain, within 1..max_current_mA; every LED pulse (the exposure, plus
        settle_us unless the LED times it) within max_pulse_us. Arguments as `configure`.
        """
        lim = self.limits()
        max_ma = min(lim["max_current_mA"], lim["hard_max_current_mA"])
        max_pulse = min(lim["max_pulse_us"], lim["hard_max_pulse_us"])
        settle = int((timing or {}).get("settle_us", lim["settle_us"]))
        lights = [int(c) for c in lights]
        currents = [int(light_current_mA)] * len(lights) if not hasattr(light_current_mA, "__len__") \
            else [int(c) for c in light_current_mA]
        exps = [(int(e), 0) if not hasattr(e, "__len__") else (int(e[0]), int(e[1])) for e in exposures]
        for i, ch in enumerate(lights):
            gain = lim["gains"][ch] if ch < len(lim["gains"]) else 1.0
            for e, (_, exp_ma) in enumerate(exps):
                set_ma = exp_ma or currents[i]
                ma = int((set_ma * round(gain * 1e4) + 5000) // 10000)
                if not 1 <= ma <= max_ma:
                    via = f" (× its calibration gain {gain:g} = {ma} mA)" if gain != 1.0 else ""
                    allowed = int(max_ma / gain)
                    raise BadInputError(
                        f"{set_ma} mA for light {i} (LED {ch}) exposure {e}{via} is above the device's "
                        f"limit max_current_mA = {max_ma} mA" if ma > max_ma else
                        f"{set_ma} mA for light {i} (LED {ch}) exposure {e} drives no current",
                        hint=f"use at most {allowed} mA (--current, or '@mA' in --exposures), or raise "
                             f"the device's limit: facette device --port {self.device.url} write max_current_mA N "
                             f"(hard limit {lim['hard_max_current_mA']} mA)")
        for e, (t_us, _) in enumerate(exps):
            pulse = t_us if mode == "led" else settle + t_us
            if pulse > max_pulse:
                with_settle = "" if mode == "led" else f" with settle_us {settle / 1e6:g} s"
                raise BadInputError(
                    f"exposure {e} ({t_us / 1e6:g} s) keeps the LED on {pulse / 1e6:g} s{with_settle}, "
                    f"above the device's limit max_pulse_us = {max_pulse / 1e6:g} s",
                    hint=f"shorten the exposure, or raise the limit: facette device --port {self.device.url} write "
                         f"max_pulse_us N (hard limit {lim['hard_max_pulse_us'] / 1e6:g} s)")

    def configure(self, exposures, lights=None, light_current_mA=500, mode="camera", retries=1,
                  **timing):
        """Write a scan configuration (lights × exposures) to the device.

        Parameters
        ----------
        exposures : sequence of (time_us, current_mA) or of time_us; current 0 means
            the light's current. 1..16 of them.
        lights : sequence of LED channels in scan order (default: every fitted LED, see n_lights)
        light_current_mA : int or sequence, drive current per light, mA (before calibration gain)
        mode : "camera" (the camera's shutter speed), "bulb", or "led" (LED pulse defines t)
        retries : repeats of a setting whose flash sync is missing
        timing : other µs registers: prefocus_us, mirror_up_us, settle_us, gap_us,
            led_pre_us, led_post_us, sync_timeout_us
        """
        if mode not in TIMING_MODES:
            raise ValueError(f"mode must be one of {TIMING_MODES}, got {mode!r}")
        n_leds = self.device.identity.get("max_leds", 12) or 12
        lights = list(range(self.n_lights)) if lights is None else [int(c) for c in lights]
        if not 1 <= len(lights) <= 16 or any(not 0 <= c < n_leds for c in lights):
            raise ValueError(f"lights must be 1..16 LED channels in [0, {n_leds}), got {lights}")
        exps = [(int(e), 0) if not hasattr(e, "__len__") else (int(e[0]), int(e[1])) for e in exposures]
        if not 1 <= len(exps) <= 16:
            raise ValueError(f"a scan has 1..16 exposures per light, got {len(exps)}")
        currents = [int(light_current_mA)] * len(lights) if not hasattr(light_current_mA, "__len__") \
            else [int(c) for c in light_current_mA]
        unknown = set(timing) - set(TIMING_KEYS)
        if unknown:
            raise ValueError(f"unknown timing settings {sorted(unknown)}")
        self.check_config(exps, lights, currents, mode, timing)
        d = self.device
        d.write("n_lights", len(lights))
        d.write("n_exposures", len(exps))
        d.write("timing_mode", R.enum_value("timing_mode", mode.upper()))
        d.write("retries", retries)
        d.write_array("light_order", lights)
        d.write_array("light_current_mA", currents)
        d.write_array("exposure_time_us", [t for t, _ in exps])
        d.write_array("exposure_current_mA", [c for _, c in exps])
        for k, v in timing.items():
            d.write(k, int(v))
        self.config = {"lights": lights, "exposures": exps, "light_current_mA": currents, "mode": mode,
                       "retries": retries, "timing": dict(timing)}
        return self.config

    def arm(self):
        self.device.command("ARM", accept_states={"ARMED"})

    def start(self):
        """Arm (if needed) and start the configured scan."""
        if self.device.state() != "ARMED":
            self.arm()
        self.device.command("START", accept_states={"RUNNING", "DONE"})

    def pause(self):
        self.device.command("PAUSE", accept_states={"PAUSED"})

    def resume(self):
        self.device.command("RESUME", accept_states={"RUNNING", "DONE"})

    def abort(self):
        self.device.command("ABORT", accept_states={"ABORTED", "IDLE"})

    def clear_faults(self):
        self.device.command("CLEAR_FAULTS", accept_states={"IDLE"})

    def reboot(self):
        self.device.command("REBOOT")

    # -- frame records -------------------------------------------------------------------
    def ring_count(self):
        return self.device.read("ring_count")

    def frame_records(self, since=0, count=None):
        """Frame-ring records ``since`` .. ring_count-1: (records, next index, records lost).

        The ring keeps the last `ring_len` records; older ones not read in time are
        counted as lost.

        A record says the device released the camera for (light, exposure) at
        start_us (µs since the scan started) with the set and measured current,
        and whether the camera's flash sync came back (a frame was really taken).
        """
        count = self.ring_count() if count is None else count
        ring_len = self.device.identity.get("ring_len", 16) or 16
        lost = max(0, count - since - ring_len)
        out = []
        base = R.register("ring_frame").address
        for n in range(since + lost, count):
            words = self.device.read_words("input", base + RING_STRIDE * (n % ring_len), RING_STRIDE)
            out.append(decode_frame_record(words, n))
        return out, count, lost

    # -- calibration gains ---------------------------------------------------------------
    def gains(self):
        """Per-LED current gains (1.0 = nominal), one per channel."""
        n = self.device.identity.get("max_leds", 12) or 12
        return [g / 1e4 for g in self.device.read_array("cal_gain")[:n]]

    def set_gains(self, gains, save=True, attempts=4):
        """Write per-LED gains (0.5..2.0) and, with `save`, store them in the device's flash.

        The unlock lasts 30 s of the device's clock; a simulated device running 2000×
        faster leaves 15 ms of real time, which a busy host can miss. So the store is
        unlocked right before each step, and a refusal for that reason is retried.
        """
        words = [int(round(g * 1e4)) for g in gains]
        key = R.UNLOCK_KEY
        for attempt in range(attempts):
            try:
                self.device.write("cal_unlock", key)
                self.device.write_array("cal_gain", words)
                if save:
                    self.device.write("cal_unlock", key)
                    self.device.command("SAVE")
                return
            except DeviceException as exc:
                if "locked" not in str(exc) or attempt == attempts - 1:
                    raise

    # -- buttons, scans ------------------------------------------------------------------
    def wait_state(self, states, timeout_s=30.0, poll_s=0.01):
        """Poll until the sequencer state is one of `states`; returns it."""
        deadline = time.monotonic() + timeout_s
        while True:
            s = self.device.state()
            if s in states:
                return s
            if time.monotonic() > deadline:
                raise DeviceError(f"the device stayed in {s} for {timeout_s} s (waiting for {sorted(states)})")
            time.sleep(poll_s)

    def scan(self, directory, profile=None, **kw):
        """Acquire a scan into `directory` (resumable); see facette.scan.run_scan."""
        return run_scan(self, directory, profile=profile, **kw)

    def close(self):
        """Close the port."""
        self.device.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self):
        return f"Rig({self.device.url!r}, boot {self.device.boot_count})"

def _fault_names(bits):
    return [f.name for f in R.Fault if bits >> f.value & 1]


class SimRig(Rig):
    """The simulated rig (`facette.sim.SimulatedRig`) as a `Rig`: the device is the firmware's
    posix build, the camera its folder, and the simulator answers what a real rig cannot
    (its sensor, pixel pitch and truth) and presses the button. Closing it stops the simulator.

    Parameters
    ----------
    device : DeviceClient on the simulated device's port
    sim : facette.sim.SimulatedRig
    camera : camera backend (default: a FolderWatchCamera on the simulator's camera folder)
    """
    can_press_button = True

    def __init__(self, device, sim, camera=None):
        super().__init__(device, camera=camera or FolderWatchCamera(sim.camera_dir))
        self.sim = sim

    @property
    def n_lights(self):
        """The simulator's LEDs."""
        return len(self.sim.leds)

    @property
    def sensor(self):
        return self.sim.sensor

    @property
    def pixel_pitch_mm(self):
        return self.sim.scene.pixel_pitch_mm

    def save_truth(self, directory, channels):
        return self.sim.save_truth(directory, channels=channels).name

    def truth(self):
        return self.sim.truth()

    def simulated_events(self):
        return self.sim.summary()

    def press_button(self):
        """Press the simulated button; returns once the device started (sent an event)."""
        self.sim.press_button()

    @property
    def name(self):
        return "sim-default"

    def show_target(self, target, fault=None, **scene):
        """Show a calibration target to the simulated camera (`facette.sim.targets.show_target`:
        `fault` "missing" or "overexposed" demonstrates a failed placement); returns its Scene."""
        return show_target(self.sim, target, fault=fault, **scene)

    def restore_scene(self):
        restore_scene(self.sim)

    def close(self):
        """Close the port and stop the simulator."""
        try:
            super().close()
        finally:
            if self.sim is not None:
                self.sim.close()
                self.sim = None


def connect(target="sim", camera=None, **kw):
    """Connect to a rig.

    Parameters
    ----------
    target : "sim" (start a simulated rig: device + rig simulator, stopped when the Rig
        closes), a serial port, a pty path, or a pyserial URL (``socket://host:port``)
    camera : camera backend for scans (facette.camera); the simulated rig brings its own
    kw : for "sim", options of facette.sim.SimulatedRig (scene, shape, faults, speed...);
        otherwise options of DeviceClient (timeout_s, retries, check_hash, baudrate)
    """
    if target == "sim":
        client_kw = {k: kw.pop(k) for k in ("timeout_s", "retries", "check_hash") if k in kw}
        sim = SimulatedRig(**kw)
        try:
            device = DeviceClient(sim.port, **client_kw)
        except Exception:
            sim.close()
            raise
        return SimRig(device, sim, camera=camera)
    return Rig(DeviceClient(target, **kw), camera=camera)
