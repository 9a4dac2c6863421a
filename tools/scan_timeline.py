#!/usr/bin/env python3
"""Scan timeline of the simulated device, in virtual time.

Starts build/posix/facette-device with a side-channel client that plays an ideal
camera (answers each shutter opening with a flash-sync edge, acks every event),
configures a scan over Modbus (pymodbus), runs it, and prints every LED pulse and
shutter window with its duration, the configured one and the deviation, then the
worst deviation per timing mode.

    .venv/bin/python tools/scan_timeline.py [--mode camera|bulb|led|all] [--lights N]
                                            [--speed X] [--quiet]

What "configured" means per mode (exp = exposure_time_us[e]):
  camera  exposure lit = LED off - shutter open = exp; LED pulse = settle_us + exp
  bulb    shutter window = exp; LED pulse = settle_us + exp
  led     LED pulse = exp; shutter window = led_pre_us + exp + led_post_us
"""
from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEVICE = ROOT / "build" / "posix" / "facette-device"
sys.path.insert(0, str(ROOT / "host"))

from pymodbus.client import ModbusSerialClient  # noqa: E402

from facette.device import registers as R  # noqa: E402

BRACKET_US = [15_000_000, 10_000_000, 2_000_000, 1_000_000, 200_000, 66_667, 33_333]


class IdealCamera(threading.Thread):
    """Side-channel client: records events, answers shutter openings with a sync edge."""

    def __init__(self, path: str):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        for _ in range(200):
            try:
                self.sock.connect(path)
                break
            except OSError:
                time.sleep(0.01)  # the device creates its socket right after printing the port
        else:
            raise RuntimeError(f"cannot connect to the side channel {path}")
        self.events: list[tuple[int, str, list[str]]] = []
        self.stop = False

    def run(self):
        buf = b""
        f = self.sock
        while not self.stop:
            try:
                chunk = f.recv(4096)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                parts = line.decode().split()
                t, kind, args = int(parts[0]), parts[1], parts[2:]
                self.events.append((t, kind, args))
                if kind == "shutter" and args[0] == "1":
                    f.sendall(f"sync {t}\nack\n".encode())
                elif kind in ("shutter", "led"):
                    f.sendall(b"ack\n")


def write(c, name, value, i=0):
    reg = R.REGISTERS[name]
    a = R.address_of(name, i)
    r = (c.write_registers(a, [value >> 16, value & 0xFFFF], device_id=R.UNIT_ID) if reg.words == 2
         else c.write_register(a, value & 0xFFFF, device_id=R.UNIT_ID))
    if r.isError():
        raise RuntimeError(f"writing {name}[{i}] = {value}: {r}")


def read(c, name, i=0):
    reg = R.REGISTERS[name]
    fn = c.read_input_registers if reg.space == "input" else c.read_holding_registers
    r = fn(R.address_of(name, i), count=reg.words, device_id=R.UNIT_ID)
    if r.isError():
        raise RuntimeError(f"reading {name}: {r}")
    return r.registers[0] << 16 | r.registers[1] if reg.words == 2 else r.registers[0]


def run_mode(mode: str, lights: int, speed: float, quiet: bool) -> tuple[int, int, float]:
    """Run one scan; returns (pulses+windows checked, worst |deviation| us, real seconds)."""
    with tempfile.TemporaryDirectory() as tmp:
        side = os.path.join(tmp, "side")
        proc = subprocess.Popen([str(DEVICE), "--speed", str(speed), "--side", side],
                                stdout=subprocess.PIPE, text=True)
        try:
            port = proc.stdout.readline().split(": ", 1)[1].strip()
            cam = IdealCamera(side)
            cam.start()
            c = ModbusSerialClient(port=port, baudrate=R.BAUD, timeout=2, retries=1)
            c.connect()
            write(c, "timing_mode", int(R.TimingMode[mode.upper()]))
            write(c, "n_lights", lights)
            write(c, "n_exposures", len(BRACKET_US))
            for e, t in enumerate(BRACKET_US):
                write(c, "exposure_time_us", t, e)
            write(c, "prefocus_us", 50_000)
            cfg = {n: read(c, n) for n in ("settle_us", "led_pre_us", "led_post_us", "gap_us")}
            t0 = time.monotonic()
            write(c, "command", int(R.Command.ARM))
            write(c, "command", int(R.Command.START))
            while read(c, "state") in (R.State.ARMED, R.State.RUNNING):
                pass  # each poll is a real request/answer on the pty
            elapsed = time.monotonic() - t0
            state = R.State(read(c, "state"))
            done = read(c, "frames_done")
            c.close()
        finally:
            proc.terminate()
            proc.wait(timeout=5)
            proc.stdout.close()
        cam.stop = True
        ev = cam.events

    if state != R.State.DONE:
        raise RuntimeError(f"{mode}: scan ended in state {state.name} after {done} frames")
    worst, checked = 0, 0
    led_on = None
    opened = None
    rows = []
    for t, kind, args in ev:
        if kind == "led":
            ch, mA = int(args[0]), int(args[1])
            if ch >= 0:
                led_on = (t, ch, mA)
            elif led_on is not None:
                frame = opened[1] if opened else {}
                exp = int(frame.get("exp_us", 0))
                conf = exp if mode == "led" else cfg["settle_us"] + exp
                dur = t - led_on[0]
                rows.append((led_on[0], f"LED ch {led_on[1]:2d} {led_on[2]:4d} mA  on {dur:9d} us"
                             f"  configured {conf:9d}  deviation {dur - conf:+d}"))
                worst = max(worst, abs(dur - conf))
                checked += 1
                if mode == "camera" and opened:
                    lit = t - opened[0]
                    rows.append((opened[0], f"exposure lit from shutter open {lit:9d} us"
                                 f"  configured {exp:9d}  deviation {lit - exp:+d}"))
                    worst = max(worst, abs(lit - exp))
                    checked += 1
                led_on = None
        elif kind == "shutter":
            fields = dict(a.split("=") for a in args[1:])
            if args[0] == "1":
                opened = (t, fields)
            elif opened is not None and mode != "camera":
                exp = int(fields["exp_us"])
                conf = exp if mode == "bulb" else cfg["led_pre_us"] + exp + cfg["led_post_us"]
                dur = t - opened[0]
                rows.append((opened[0], f"shutter frame {fields['frame']:>3} (L{fields['light']} "
                             f"E{fields['exp']})  open {dur:9d} us  configured {conf:9d}  "
                             f"deviation {dur - conf:+d}"))
                worst = max(worst, abs(dur - conf))
                checked += 1
    if not quiet:
        for t, text in sorted(rows, key=lambda r: r[0]):
            print(f"{mode:6s} t={t:12d} us  {text}")
    expected = lights * len(BRACKET_US)
    lit = [t for t, kind, _ in ev if kind in ("led", "shutter", "focus")]
    span = lit[-1] - lit[0]
    print(f"{mode}: {done}/{expected} frames, {checked} pulses and windows, worst deviation "
          f"{worst} us; virtual scan {span} us, real {elapsed:.2f} s at --speed {speed:g}")
    return checked, worst, elapsed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", default="all", choices=["camera", "bulb", "led", "all"])
    ap.add_argument("--lights", type=int, default=12)
    ap.add_argument("--speed", type=float, default=2000.0)
    ap.add_argument("--quiet", action="store_true", help="only the summary lines")
    args = ap.parse_args(argv)
    if not DEVICE.is_file():
        print(f"{DEVICE} is missing: run `make firmware-posix`", file=sys.stderr)
        return 2
    modes = ["camera", "bulb", "led"] if args.mode == "all" else [args.mode]
    worst = 0
    for m in modes:
        _, w, _ = run_mode(m, args.lights, args.speed, args.quiet)
        worst = max(worst, w)
    print(f"worst deviation over all modes: {worst} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
