"""`SimulatedRig`: the firmware's posix build plus the rig simulator, as one object."""
from __future__ import annotations

import json
import shutil
import tempfile
import threading
import time
import zipfile
from pathlib import Path

import numpy as np

from facette.sim.bands import TRUTH_ARRAYS, render_to_disk
from facette.sim.device_process import SimulatedDevice
from facette.sim.lights import thesis_leds
from facette.sim.render import radiance_per_led
from facette.sim.rig import Faults, RigSimulator, SimCamera
from facette.sim.scene import scene_spec
from facette.camera.sensor import DEFAULT_SENSOR

__all__ = ["SimulatedRig", "DEFAULT_RAW_SHAPE"]

DEFAULT_RAW_SHAPE = (96, 128)   # (rows, columns) of the RAW mosaic; HDR/truth are half that
RADIANCE_IN_MEMORY_BYTES = 2**30
"""The largest radiance (m × H × W × 3 float64) rendered whole and held in memory; above it the
rig renders a band of rows at a time to disk (about 3 MP of half-size pixels, 12 LEDs)."""


class SimulatedRig:
    """Start a simulated device and a rig simulator following it.

    Parameters
    ----------
    scene : str, a name of facette.sim.scene.SCENES (default "plaque_sphere")
    raw_shape : (rows, cols) of the RAW images, even (default 96×128; HDR is half)
    pixel_pitch_mm : mm per half-size pixel on the object (default: scene 120 mm wide)
    brdf : {"model", "params"}, a preset name ("mask", "bust", "lambert"), or None ("mask":
        Cook–Torrance σ = 0.05, n_i = 1.2, see facette.sim.scene.BRDF_PRESETS)
    near : bool, point LEDs at 1.5 m with per-pixel directions and 1/r²
    direction_error_deg, intensity_error : LED errors (see facette.sim.lights.thesis_leds)
    sensor : facette.camera.sensor.SensorModel or None (the default D300-like sensor at ISO 400)
    electrons_per_mA_s : exposure scale (see facette.sim.render.radiance_per_led)
    faults : Faults, or a string for Faults.parse ("biterr=1e-3,reset_at_shot=5")
    speed : virtual clock rate of the device (× real time)
    workdir : folder for the camera folder, the side socket and the flash (default: temporary)
    seed : int
    max_unclaimed : int or None, see RigSimulator (default 1: the next shot waits until the
        host took the previous file, which makes runs deterministic; a host collects the files;
        None for a simulator nobody takes files from)
    render_rows : int or None, render the scene and the LEDs `render_rows` rows at a time
        into WORKDIR/radiance (`facette.sim.bands`: the same frames, in bounded memory; the
        folder holds m × H × W × 24 bytes, 7.3 GB at 11648×8736 RAW); None: whole in memory
        when the radiance takes at most RADIANCE_IN_MEMORY_BYTES, else in bands
    """

    def __init__(self, scene="plaque_sphere", raw_shape=DEFAULT_RAW_SHAPE, pixel_pitch_mm=None, brdf=None,
                 near=False, direction_error_deg=0.5, intensity_error=0.05, sensor=None,
                 electrons_per_mA_s=20.0, faults=None, speed=2000.0, workdir=None, seed=0, shadows=True,
                 max_unclaimed=1, render_rows=None):
        rows, cols = (int(v) for v in raw_shape)
        if rows % 2 or cols % 2 or rows < 22 or cols < 22:
            raise ValueError(f"raw_shape must be even and at least 22×22 (a DNG limit), got {raw_shape}")
        self._tmp = None
        if workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="facette-rig-")
            workdir = self._tmp.name
        self.workdir = Path(workdir)
        self.camera_dir = self.workdir / "camera"
        self.faults = Faults.parse(faults) if isinstance(faults, str) or faults is None else faults
        spec = scene_spec(scene, (rows // 2, cols // 2), pixel_pitch_mm, seed=seed, brdf=brdf)
        self.leds = thesis_leds(direction_error_deg, intensity_error, near=near, seed=seed + 1)
        self.sensor = sensor or DEFAULT_SENSOR
        whole_bytes = len(self.leds) * spec.shape[0] * spec.shape[1] * 3 * 8
        self.banded = render_rows is not None or whole_bytes > RADIANCE_IN_MEMORY_BYTES
        if self.banded:   # the scene made and rendered a band of rows at a time, kept on disk
            self.scene = spec
            self.radiance = render_to_disk(self.workdir / "radiance", spec, self.leds, electrons_per_mA_s,
                                           shadows=shadows, band_rows=render_rows)
        else:
            self.scene = spec.rows(0, spec.shape[0])
            self.radiance = radiance_per_led(self.scene, self.leds, electrons_per_mA_s, shadows=shadows)
        self.device = SimulatedDevice(speed=speed, side=True, workdir=self.workdir / "device", link=True)
        self.max_unclaimed = max_unclaimed
        self.power_cycles = 0
        self._closed = threading.Event()
        try:
            self.camera = SimCamera(self.camera_dir, self.radiance, self.sensor, iso=self.sensor.iso,
                                    seed=seed + 2)
            self.simulator = RigSimulator(self.device.side_socket, self.camera, self.faults,
                                         max_unclaimed=max_unclaimed, on_power_cut=self.power_cycle)
        except Exception:
            self.device.close()
            raise
        self.port = self.device.port

    def power_cycle(self):
        """Cut the device's power and restore it: the process restarts with its flash
        (boot count + 1), a new pseudo-terminal appears behind the same `port` link, and
        the rig simulator reconnects, keeping its history (shots, frames)."""
        old = self.simulator
        old.close()
        self.device.restart()
        self.simulator = RigSimulator(self.device.side_socket, self.camera, self.faults,
                                      max_unclaimed=self.max_unclaimed, continues=old,
                                      on_power_cut=self.power_cycle)
        self.power_cycles += 1
        if threading.current_thread() is not threading.main_thread():
            # the device dies with the thread that started it (PR_SET_PDEATHSIG):
            # keep this thread until the rig closes
            self._closed.wait()

    # -- controls ---------------------------------------------------------------------
    def press_button(self, wait_for=None, timeout_s=10.0):
        """Press and release the rig's button. The button is held until `wait_for()`
        is true (default: the device sent an event, i.e. the scan started), bounded by
        `timeout_s`, so that the firmware's debounce (in virtual time) always sees it."""
        if wait_for is None:
            before = self.simulator.events
            wait_for = lambda: self.simulator.events > before  # noqa: E731
        self.simulator.button(True)
        deadline = time.monotonic() + timeout_s
        while wait_for is not None and not wait_for() and time.monotonic() < deadline:
            time.sleep(0.002)
        self.simulator.button(False)

    def set_temperature(self, celsius):
        self.simulator.set_ntc(celsius)

    def summary(self):
        return self.simulator.summary()

    # -- truth ---------------------------------------------------------------------------
    def truth(self):
        """The simulator's truth at the HDR (half-size) resolution (truth.npz in docs/scan-format.md)."""
        return {**self._truth_maps(), **self._truth_lights()}

    def _truth_maps(self):
        if self.banded:
            return {name: np.load(self.radiance.folder / f"truth_{name}.npy") for name in TRUTH_ARRAYS}
        s = self.scene
        return {"normals": s.normals.astype(np.float32), "height_mm": s.height_mm.astype(np.float32),
                "mask": s.mask, "albedo": s.albedo.astype(np.float32)}

    def _truth_lights(self):
        s = self.scene
        return {"light_dirs": self.leds.directions.astype(np.float64),
                "light_intensity": self.leds.intensities.astype(np.float64),
                "light_positions_mm": (self.leds.positions_mm if self.leds.positions_mm is not None
                                       else np.full((len(self.leds), 3), np.nan)),
                "pixel_pitch_mm": np.float64(s.pixel_pitch_mm),
                "brdf": np.str_(s.brdf_json()),
                "sensor": np.str_(json.dumps(self.sensor.to_profile_dict(), sort_keys=True))}

    def save_truth(self, directory, channels=None):
        """Write truth.npz into `directory`. `channels` : LED channel of each scan light
        (light_dirs/light_intensity then follow the scan's light order). A rig rendered in
        bands copies its truth files into the archive, never holding them."""
        t = self._truth_lights()
        if channels is not None:
            idx = np.asarray(list(channels), int)
            for k in ("light_dirs", "light_intensity", "light_positions_mm"):
                t[k] = t[k][idx]
        path = Path(directory) / "truth.npz"
        tmp = path.with_name(".truth.npz.partial")
        if not self.banded:
            with open(tmp, "wb") as fh:
                np.savez(fh, **self._truth_maps(), **t)
        else:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
                for name in TRUTH_ARRAYS:
                    with open(self.radiance.folder / f"truth_{name}.npy", "rb") as src, \
                            zf.open(f"{name}.npy", "w", force_zip64=True) as dst:
                        shutil.copyfileobj(src, dst, 16 * 2**20)
                for name, value in t.items():
                    with zf.open(f"{name}.npy", "w", force_zip64=True) as dst:
                        np.lib.format.write_array(dst, np.asanyarray(value), allow_pickle=False)
        tmp.replace(path)
        return path

    def close(self):
        self._closed.set()
        try:
            self.simulator.close()
        finally:
            self.device.close()
            if self._tmp is not None:
                self._tmp.cleanup()
                self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
