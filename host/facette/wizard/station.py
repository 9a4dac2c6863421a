"""`RigStation`: the calibration wizard's captures on a rig (rig I/O only).

It places targets (asks the person, or shows them on the simulated rig), takes scans
through `facette.scan.run_scan`, merges them to HDR, and writes and checks the LED gains
in the device's calibration store (write, SAVE, reboot). The step sequence that uses it
is `facette.wizard.steps`.
"""
from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from facette.calib.checks import WizardError
from facette.camera.sensor import DEFAULT_SENSOR
from facette.device.client import DeviceError, DeviceException, DeviceReset
from facette.scan import MissingFrameWarning, load_hdr, merge_scan, read_scan_manifest, run_scan

__all__ = ["RigStation", "INSTRUCTIONS"]

INSTRUCTIONS = {
    "lens_cap": "Put the lens cap on (dark frames for the camera's noise).",
    "spectralon": "Lens cap off. Lay the Spectralon flat under the camera, filling the field "
                  "(nothing else in view).",
    "mirror_sphere": "Lens cap off. Place the chrome sphere on its black collar at the centre of the field, "
                     "on the grey card (nothing else in view).",
    "mirror_sphere_2": "Move the chrome sphere to {dx:+.0f} mm from the centre, sideways (keep it on the card, "
                       "fully in view).",
    "matte_sphere": "Lens cap off. Place the matte sphere at the centre of the field (nothing else in view).",
}




class RigStation:
    """Captures for the wizard through a `facette.scan.Rig`.

    rig : a connected Rig (``facette.connect("sim")`` or a real device with a camera)
    workdir : folder for the captures (one scan directory per capture)
    attended : ask the person to confirm each placement (Enter); False for --yes
    out : print-like callable; ask : input-like callable
    sim_faults : {target: "missing" | "overexposed"}: the simulated rig shows the
        empty table, or a target 300× too bright, instead of that target (demonstrations)
    """

    def __init__(self, rig, workdir, attended=True, out=print, ask=input, sim_faults=None,
                 n_leds=12, light_current_mA=500, button=False):
        self.rig = rig
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.attended = attended
        self.out = out
        self.ask = ask
        self.sim_faults = dict(sim_faults or {})
        self.n_leds = int(n_leds)
        self.current_mA = int(light_current_mA)
        self.n = 0
        self.button = bool(button)  # the person starts each capture with the rig's button
        self._wait_button = False
        self.sensor = None          # set by the noise step (a SensorModel)
        self.rig_name = rig.name
        # full scale of the nominal sensor until the noise step measures this camera's
        self.full_scale_dn = DEFAULT_SENSOR.white_level_dn - DEFAULT_SENSOR.black_level_dn

    # -- targets -------------------------------------------------------------------------
    def place(self, kind, instruction=None, **sim_kw):
        self.out(f"  → {instruction or INSTRUCTIONS.get(kind, kind)}")
        target = kind.split("#")[0]     # a real rig: a person places it; the simulated one shows it
        self.rig.show_target(target, fault=self.sim_faults.get(target), **sim_kw)
        if self.button:
            self._wait_button = True
            self.out("    then press the rig's button to take the pictures")
        elif self.attended:
            self.ask("    press Enter when it is in place (Ctrl-C stops; nothing is written) ")

    def restore(self):
        self.rig.restore_scene()

    # -- captures ------------------------------------------------------------------------
    def _scan(self, name, exposures, lights):
        self.n += 1
        d = self.workdir / f"{self.n:02d}-{name}"
        while d.exists():             # a capture folder is never reused: each is one scan
            self.n += 1
            d = self.workdir / f"{self.n:02d}-{name}"
        button = None
        if self._wait_button:
            # the simulated rig presses its own button; a person presses a real one
            button = "press" if self.rig.can_press_button else "wait"
            self._wait_button = False
        run_scan(self.rig, d, exposures=list(exposures), lights=list(lights),
                 light_current_mA=self.current_mA, mode="camera", progress=False, save_truth=False,
                 button=button)
        return d

    def capture(self, name, exposures, current="measured"):
        """HDR images (m, H, W, 3) in DN/(µs·mA) of every LED, merged with the station's
        sensor model; `current` "measured" (the LED's own efficiency) or "set" (what
        the host asked for: shows the effect of the calibration gains)."""
        d = self._scan(name, exposures, range(self.n_leds))
        with warnings.catch_warnings():
            # a calibration capture is merged only when complete
            warnings.simplefilter("error", MissingFrameWarning)
            try:
                merge_scan(d, sensor=self.sensor, current=current)
            except MissingFrameWarning as exc:
                raise WizardError(f"{name}: a frame is missing ({exc}): check the camera's card and "
                                  "tether, then run the step again") from None
        images, _, _ = load_hdr(d, sensor=self.sensor, merge_missing=False)
        return np.asarray(images, np.float32), d

    def capture_raw(self, name, exposures, light=0):
        """RAW files of one LED at each exposure, in order (paths)."""
        d = self._scan(name, exposures, [light])
        frames = sorted(read_scan_manifest(d).frames, key=lambda f: int(f.exposure))
        return [d / f.file for f in frames]

    # -- device calibration store --------------------------------------------------------
    def gains(self):
        return list(self.rig.gains())

    def set_gains(self, gains):
        """Write the gains and store them in flash (Rig.set_gains: unlock, write, SAVE)."""
        try:
            self.rig.set_gains(gains, save=True)
        except DeviceException as exc:
            raise WizardError(f"LED gains: the device refused them ({exc}); check "
                              "`facette device faults`, then run `facette calibrate --only "
                              "spectralon,gains`") from exc

    def reboot(self):
        """Reboot the device and wait until it answers again; returns the new boot count."""
        dev = self.rig.device
        before = dev.check_reset()
        try:
            self.rig.reboot()
        except (DeviceError, OSError):
            pass                      # the answer may be lost in the reboot
        deadline = time.monotonic() + 20.0
        while True:
            try:
                if dev.check_reset() != before:
                    return dev.boot_count
            except DeviceReset as exc:
                return exc.new_boot
            except (DeviceError, OSError):
                pass
            if time.monotonic() > deadline:
                raise WizardError("the device did not come back within 20 s after its reboot: check "
                                  "its power and cable, then run `facette calibrate --only gains`")
            time.sleep(0.02)
