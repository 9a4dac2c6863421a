"""The simulated device (posix build of the firmware) as the hardware-in-the-loop tests start it.

A plain module, not conftest.py: test files import it by name, and a `from conftest import`
would pick up whichever conftest.py (host/tests has its own) pytest loaded first.
"""
from __future__ import annotations

import os
import socket
import subprocess
from dataclasses import dataclass
from pathlib import Path


def stop_process(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:  # pragma: no cover - kill is not ignorable
        pass


REPO = Path(__file__).resolve().parent.parent
POSIX_DEVICE = REPO / "build" / "posix" / "facette-device"


@dataclass
class PosixDevice:
    """A running simulated device: ``port`` (pty path), ``side`` (Unix socket path), ``state`` dir."""

    port: str
    side: str
    state: Path
    process: subprocess.Popen

    def side_connect(self) -> socket.socket:
        """Connect to the side channel (the device then runs in lockstep with this client)."""
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.connect(self.side)
        return s


def _posix_binary() -> Path:
    if not POSIX_DEVICE.is_file():
        r = subprocess.run(["make", "-s", "-C", os.fspath(REPO / "firmware"), "posix",
                            f"BUILD={REPO / 'build'}"], capture_output=True, text=True)
        if r.returncode != 0 or not POSIX_DEVICE.is_file():
            raise FileNotFoundError(f"{POSIX_DEVICE} is missing and building it failed; run "
                                    f"`make firmware-posix`:\n{r.stdout}{r.stderr}")
    return POSIX_DEVICE


def start_posix_device(tmp: Path, speed: float = 100.0, state: Path | None = None) -> PosixDevice:
    """Start facette-device in tmp; returns once its pty path has been printed."""
    state = state or tmp / "state"
    side = tmp / "side.sock"
    proc = subprocess.Popen([os.fspath(_posix_binary()), "--speed", str(speed), "--side",
                             os.fspath(side), "--state", os.fspath(state)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline().strip()
    if not line.startswith("port: "):
        stop_process(proc)
        raise RuntimeError(f"facette-device printed {line!r} instead of 'port: <path>'")
    return PosixDevice(line.split(": ", 1)[1], os.fspath(side), state, proc)


def stop_posix_device(dev: PosixDevice) -> None:
    dev.process.terminate()
    try:
        dev.process.wait(timeout=5)
    except subprocess.TimeoutExpired:
        stop_process(dev.process)
    dev.process.stdout.close()
