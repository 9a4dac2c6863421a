"""The rig simulator: the camera and the optics on the simulated device's side channel.

It connects to the Unix socket of ``build/posix/facette-device --side SOCKET``
(its protocol: the header comment of firmware/ports/posix/hal_posix.c), follows the LED
and shutter lines in the device's virtual time,
and for every shutter window integrates LED current × time, renders the frame
(sensor model of thesis eq 2.12–2.13), and writes it as a DNG into its camera
folder, as a tethered camera would. It answers each shutter opening with a
flash-sync edge (``sync <t>``) and every ``shutter``/``led`` event with ``ack``
(lockstep: the device's clock waits for it, so the result does not depend on
the speed of the machine).

Faults (``Faults``) are injected through the same channel: bit errors on the
serial link, a device reset at a given shot, a power cut (the device process
restarts; with `SimulatedRig`), a missed flash sync (the camera does not fire:
no sync, no file), an open LED, and over-temperature.
"""
from __future__ import annotations

import dataclasses
import json
import os
import select
import socket
import threading
import time
from pathlib import Path

import numpy as np

from facette.camera.sensor import DEFAULT_SENSOR, bayer_mosaic_rggb
from facette.sim.bands import RadianceOnDisk, band_rows_for
from facette.sim.dng import write_dng

__all__ = ["RigSimulator", "SimCamera", "Faults", "SideChannelError"]


class SideChannelError(RuntimeError):
    """The device's side channel could not be reached or broke."""


@dataclasses.dataclass
class Faults:
    """Faults to inject, by shot number (0-based count of shutter openings the
    simulator has seen since it connected).

    biterr : float, probability per UART byte of a flipped bit (both directions), from the start
    reset_at_shot : int or None, hard-reset the device when this shutter opens (the shot is lost)
    power_cut_at_shot : int or None, cut the device's power when this shutter opens: the
        process stops and starts again (flash kept, a new pseudo-terminal behind the same
        link name, as a USB device re-enumerates); needs a SimulatedRig
    miss_sync_shots : tuple of int, the camera does not fire at these shots (no sync, no file)
    open_led : int or None, this LED channel is open-circuit from the start (no light, no current)
    overtemp_at_shot : int or None, the LED heat sink reads `overtemp_c` from this shot on
    overtemp_c : float, °C
    """
    biterr: float = 0.0
    reset_at_shot: int | None = None
    power_cut_at_shot: int | None = None
    miss_sync_shots: tuple = ()
    open_led: int | None = None
    overtemp_at_shot: int | None = None
    overtemp_c: float = 95.0

    @classmethod
    def parse(cls, spec):
        """From a command-line string like ``"biterr=1e-3,reset_at_shot=5,miss_sync_shots=3:7"``."""
        out = cls()
        if not spec:
            return out
        for item in spec.split(","):
            key, _, val = item.partition("=")
            key = key.strip()
            if key not in cls.__dataclass_fields__:
                raise ValueError(f"unknown fault {key!r}; known: {sorted(cls.__dataclass_fields__)}")
            if key == "miss_sync_shots":
                setattr(out, key, tuple(int(v) for v in val.split(":") if v))
            elif key in ("biterr", "overtemp_c"):
                setattr(out, key, float(val))
            else:
                setattr(out, key, int(val))
        return out


class SimCamera:
    """A Bayer RGGB 14-bit camera that writes DNG files into `folder`.

    Its optics are the per-LED electron maps of `facette.sim.render.radiance_per_led`
    (m, H, W, 3) e- per mA·µs (an array, or a `RadianceOnDisk`: then each frame is made a band of
    rows at a time, the same frame); a frame exposed to charges Q_i (mA·µs) of each LED
    collects Σ_i Q_i · radiance[i] electrons (plus dark current over the window).
    """

    def __init__(self, folder, radiance, sensor=None, iso=400, seed=0, prefix="DSC_"):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.radiance = radiance if isinstance(radiance, RadianceOnDisk) else np.asarray(radiance, dtype=np.float64)
        self.sensor = sensor if sensor is not None else DEFAULT_SENSOR.at_iso(iso)
        self.iso = int(iso)
        self.rng = np.random.default_rng(seed)
        self.prefix = prefix
        existing = sorted(self.folder.glob(f"{prefix}*.dng"))
        self.count = len(existing)
        self._written = []

    def unclaimed(self):
        """Number of frames still in the camera folder (nobody moved them away yet)."""
        self._written = [p for p in self._written if os.path.exists(p)]
        return len(self._written)

    def expose(self, charges_mA_us, t_s, extra=None):
        """Take one frame; `charges_mA_us` : (m,) LED current × time inside the window.
        Returns the path written."""
        q = np.asarray(charges_mA_us, dtype=np.float64)
        if isinstance(self.radiance, RadianceOnDisk):   # a band of rows at a time, the same frame
            _, hh, ww, _ = self.radiance.shape
            mosaic = self.sensor.expose_charge_rows(
                lambda r0, r1: bayer_mosaic_rggb(self.radiance.electrons(q, r0 // 2, r1 // 2)),
                (2 * hh, 2 * ww), max(t_s, 1e-6), self.rng, band_rows=2 * band_rows_for(ww))
        else:
            electrons = np.tensordot(q, self.radiance, axes=(0, 0))          # (H, W, 3)
            mosaic = self.sensor.expose_charge(bayer_mosaic_rggb(electrons), max(t_s, 1e-6), self.rng)
        self.count += 1
        path = self.folder / f"{self.prefix}{self.count:04d}.dng"
        write_dng(path, mosaic, self.sensor.black_level_dn, self.sensor.white_level_dn,
                  max(t_s, 1e-6), self.iso, model="sim", extra=extra)
        self._written.append(path)
        return path


class RigSimulator:
    """Side-channel client: follows the device, drives the camera, injects faults.

    Parameters
    ----------
    side_socket : path of the device's side-channel Unix socket
    camera : SimCamera
    faults : Faults or None
    open_led_dark : bool, an open LED emits no light (True: it is open)
    shutter_lag_us : int, delay from the shutter line to the flash-sync edge (µs)
    max_unclaimed : int or None; when set, a shutter opening is not acknowledged
        (the device's virtual clock stays frozen) while the camera folder holds this
        many files nobody took yet. With a host in the loop this keeps a fast virtual
        clock from outrunning the host (the device's frame ring holds 16 records);
        leave it None when nobody collects the files.

    Attributes (read them from another thread): ``shots`` (shutter openings seen),
    ``frames`` (list of dicts for the frames written), ``boots`` (boot counts seen),
    ``log`` (the last event lines), ``virtual_us`` (last device time seen).
    """

    def __init__(self, side_socket, camera, faults=None, shutter_lag_us=40, connect_timeout_s=10.0,
                 max_unclaimed=None, continues=None, on_power_cut=None):
        self.camera = camera
        self.max_unclaimed = max_unclaimed
        self.on_power_cut = on_power_cut
        self.faults = faults or Faults()
        self.shutter_lag_us = int(shutter_lag_us)
        self.m = camera.radiance.shape[0]
        self.shots = 0
        self.frames = []
        self.missed = []
        self.boots = []
        self.events = 0
        self.virtual_us = 0
        self.error = None
        self._led = (-1, 0.0)
        self._last_t = None
        self._window = None
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._reset_done = False
        self._power_cut_done = False
        self._overtemp = False
        if continues is not None:   # the same rig after a power cycle: keep its history
            self.shots, self.frames, self.missed = continues.shots, continues.frames, continues.missed
            self.boots, self.events = continues.boots, continues.events
            self._reset_done, self._power_cut_done = continues._reset_done, continues._power_cut_done
            self._overtemp = continues._overtemp
        deadline = time.monotonic() + connect_timeout_s
        while True:
            try:
                self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                self.sock.connect(str(side_socket))
                break
            except OSError as exc:
                self.sock.close()
                if time.monotonic() > deadline:
                    raise SideChannelError(f"cannot connect to the device's side channel {side_socket}: "
                                           f"{exc}; is build/posix/facette-device running with --side?") from exc
                time.sleep(0.01)
        self._rbuf = b""
        self._thread = threading.Thread(target=self._run, name="rig-simulator", daemon=True)
        self._initial_faults()
        self._thread.start()

    # -- inputs to the device ------------------------------------------------
    def send(self, line):
        """Send one input line to the device (firmware/ports/posix/hal_posix.c)."""
        with self._send_lock:
            try:
                self.sock.sendall((line.strip() + "\n").encode("ascii"))
            except OSError as exc:
                if not self._stop.is_set():
                    raise SideChannelError(f"side channel closed while sending {line!r}: {exc}") from exc

    def button(self, pressed):
        self.send(f"button {1 if pressed else 0}")

    def set_ntc(self, celsius):
        self.send(f"ntc {int(round(celsius * 100))}")

    def led_fault(self, ch, kind):
        self.send(f"led_fault {int(ch)} {kind}")

    def set_biterr(self, p):
        self.send(f"biterr {float(p):.6g}")

    def reset_device(self):
        self.send("reset")

    def _initial_faults(self):
        if self.faults.biterr:
            self.set_biterr(self.faults.biterr)
        if self.faults.open_led is not None:
            self.led_fault(self.faults.open_led, "open")

    # -- event loop ------------------------------------------------------------
    def _lines(self):
        while True:
            while b"\n" not in self._rbuf:
                chunk = self.sock.recv(65536)
                if not chunk:
                    return
                self._rbuf += chunk
            line, self._rbuf = self._rbuf.split(b"\n", 1)
            yield line.decode("ascii", "replace")

    def _more_pending(self):
        """Whether the device sent more lines than the one being handled."""
        if b"\n" in self._rbuf:
            return True
        ready, _, _ = select.select([self.sock], [], [], 0)
        return bool(ready)

    def _run(self):
        try:
            for line in self._lines():
                if self._stop.is_set():
                    break
                line = line.strip()
                if line:
                    self._handle(line)
        except (OSError, ValueError) as exc:
            if not self._stop.is_set():
                self.error = exc
        except Exception as exc:  # keep the cause for the host; the device would hang in lockstep
            self.error = exc
            raise

    def _integrate_to(self, t):
        w = self._window
        if w is not None and self._last_t is not None:
            ch, ma = self._led
            lo = max(self._last_t, w["t_open"])
            hi = t if w["t_end"] is None else min(t, w["t_end"])
            if hi > lo and ch >= 0 and ma > 0 and ch < self.m and ch != self.faults.open_led:
                w["charge"][ch] += ma * (hi - lo)
        self._last_t = t

    def _finish(self, t_close):
        w, self._window = self._window, None
        if w is None or not w["fire"]:
            return
        t_us = (w["t_end"] if w["t_end"] is not None else t_close) - w["t_open"]
        extra = {k: w["params"].get(k) for k in ("frame", "light", "exp", "exp_us", "mode")}
        extra.update(start_us=w["t_open"], shot=w["shot"])
        path = self.camera.expose(w["charge"], t_us * 1e-6, extra=extra)
        with self._lock:
            self.frames.append({**extra, "file": str(path), "charge_mA_us": w["charge"].tolist(),
                                "window_us": t_us})

    def _handle(self, line):
        parts = line.split()
        try:
            t = int(parts[0])
            kind = parts[1]
        except (IndexError, ValueError):
            return  # not an event line
        self.events += 1
        self.virtual_us = t
        if kind == "boot":
            # a (re)boot: the camera loses any exposure in progress
            self._window, self._led, self._last_t = None, (-1, 0.0), t
            with self._lock:
                self.boots.append(int(parts[2]) if len(parts) > 2 else None)
            return
        self._integrate_to(t)
        w = self._window
        if w is not None and w["t_end"] is not None and t >= w["t_end"] and w["closed"]:
            self._finish(t)
        if kind == "led":
            ch, ma = int(parts[2]), float(parts[3])
            self._led = (ch, ma) if ch >= 0 and ma > 0 else (-1, 0.0)
            if self._window is not None and self._window["closed"] and self._led[0] < 0:
                self._finish(t)   # camera-timed: light off after the shutter line dropped
            self.send("ack")
        elif kind == "shutter":
            level = int(parts[2])
            params = {k: (int(v) if v.lstrip("-").isdigit() else v)
                      for k, v in (p.split("=", 1) for p in parts[3:] if "=" in p)}
            if level == 1:
                self._backpressure()
                what = self._open(t, params)
                if what == "reset":
                    self.send("ack")        # release the lockstep first, then pull the plug
                    self.reset_device()
                    return
                if what == "power_cut":     # the rig restarts the process from another thread
                    threading.Thread(target=self.on_power_cut, name="power-cut", daemon=True).start()
                    self._stop.set()
                    return
            else:
                w = self._window
                if w is not None:
                    w["closed"] = True
                    # camera-timed: with the light already off nothing more can reach the
                    # sensor, so the camera writes its file now (also after an abort)
                    if w["t_end"] is None or t >= w["t_end"] or self._led[0] < 0:
                        self._finish(t)
            self.send("ack")

    def _open(self, t, params):
        if self._window is not None:        # a new opening ends any previous exposure
            self._finish(t)
        shot = self.shots
        self.shots += 1
        f = self.faults
        if f.overtemp_at_shot is not None and shot >= f.overtemp_at_shot and not self._overtemp:
            self._overtemp = True
            self.set_ntc(f.overtemp_c)
        if f.power_cut_at_shot is not None and shot == f.power_cut_at_shot and not self._power_cut_done \
                and self.on_power_cut is not None:
            self._power_cut_done = True
            with self._lock:
                self.missed.append({"shot": shot, "why": "power cut", **params})
            self._window = None
            return "power_cut"
        if f.reset_at_shot is not None and shot == f.reset_at_shot and not self._reset_done:
            self._reset_done = True
            with self._lock:
                self.missed.append({"shot": shot, "why": "device reset", **params})
            self._window = None
            return "reset"
        fire = shot not in f.miss_sync_shots
        mode = params.get("mode", "camera")
        exp_us = int(params.get("exp_us", 0) or 0)
        t_end = t + exp_us if mode == "camera" else None
        self._window = {"t_open": t, "t_end": t_end, "params": params, "charge": np.zeros(self.m),
                        "closed": False, "fire": fire, "shot": shot}
        if fire:
            self.send(f"sync {t + self.shutter_lag_us}")
        else:
            with self._lock:
                self.missed.append({"shot": shot, "why": "missed flash sync", **params})

    def _backpressure(self):
        if not self.max_unclaimed:
            return
        # a frozen device sends nothing more; if it did (an abort, a fault), stop waiting
        while not self._stop.is_set() and self.camera.unclaimed() >= self.max_unclaimed \
                and not self._more_pending():
            time.sleep(0.001)

    def close(self):
        """Stop following the device and close the socket."""
        self._stop.set()
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        self.sock.close()

    def summary(self):
        with self._lock:
            return {"shots": self.shots, "frames": len(self.frames), "missed": list(self.missed),
                    "boots": list(self.boots), "virtual_us": self.virtual_us}

    def __repr__(self):
        return f"RigSimulator({json.dumps(self.summary())})"
