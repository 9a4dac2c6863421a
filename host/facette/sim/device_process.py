"""Start and stop the simulated device (the firmware's posix build, contract 1)."""
from __future__ import annotations

import os
import selectors
import subprocess
import tempfile
import time
from pathlib import Path

__all__ = ["SimulatedDevice", "device_binary", "DeviceBinaryMissing", "REPO_ROOT"]

REPO_ROOT = Path(__file__).resolve().parents[3]


def _die_with_parent():
    """Linux: the device gets SIGTERM when the Python process that started it dies
    (a killed test run leaves no simulated device behind)."""
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


class DeviceBinaryMissing(FileNotFoundError):
    """build/posix/facette-device is not there and could not be built."""


def device_binary(build=True):
    """Path of the simulated device, building it with `make firmware-posix` when missing.

    ``FACETTE_DEVICE`` in the environment overrides the path.
    """
    env = os.environ.get("FACETTE_DEVICE")
    path = Path(env) if env else REPO_ROOT / "build" / "posix" / "facette-device"
    if path.is_file():
        return path
    if build and not env and (REPO_ROOT / "Makefile").is_file():
        proc = subprocess.run(["make", "-s", "-C", str(REPO_ROOT), "firmware-posix"],
                              capture_output=True, text=True)
        if proc.returncode == 0 and path.is_file():
            return path
        detail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
        raise DeviceBinaryMissing(f"{path} is missing and `make firmware-posix` failed:\n  "
                                  + "\n  ".join(detail) + "\nbuild it by hand with `make firmware-posix`")
    raise DeviceBinaryMissing(f"{path} is missing: build the simulated device with "
                              "`make firmware-posix` (or set FACETTE_DEVICE to its path)")


class SimulatedDevice:
    """A running ``facette-device`` process.

    Parameters
    ----------
    speed : float > 0, virtual clock rate as a multiple of real time
    side : bool, open the side channel (a Unix socket in `workdir`) for a rig simulator
    state_dir : path or None, where the simulated flash lives (kept across restarts);
        default a folder in `workdir`
    workdir : path or None, default a fresh temporary folder (removed on close)
    startup_timeout_s : float, how long to wait for the ``port:`` line

    Attributes: ``port`` (the pty path to give the Modbus client), ``side_socket``,
    ``state_dir``, ``proc``.
    """

    def __init__(self, speed=50.0, side=True, state_dir=None, workdir=None, startup_timeout_s=20.0,
                 extra_args=()):
        if not speed > 0:
            raise ValueError(f"speed must be > 0 (a multiple of real time), got {speed}")
        self._tmp = None
        if workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="facette-sim-")
            workdir = self._tmp.name
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.state_dir = Path(state_dir) if state_dir else self.workdir / "flash"
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.side_socket = self.workdir / "side.sock" if side else None
        self.speed = float(speed)
        args = [str(device_binary()), "--speed", f"{speed:g}", "--state", str(self.state_dir)]
        if side:
            args += ["--side", str(self.side_socket)]
        args += list(extra_args)
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     stdin=subprocess.DEVNULL, text=True, bufsize=1,
                                     preexec_fn=_die_with_parent)
        self.port = self._read_port(startup_timeout_s)
        if side:
            deadline = time.monotonic() + startup_timeout_s
            while not self.side_socket.exists():
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    self.close()
                    raise RuntimeError(f"the simulated device did not open its side channel "
                                       f"{self.side_socket}")
                time.sleep(0.005)

    def _read_port(self, timeout_s):
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + timeout_s
        try:
            while time.monotonic() < deadline:
                if sel.select(timeout=0.1):
                    line = self.proc.stdout.readline()
                    if line.startswith("port:"):
                        return line.split(":", 1)[1].strip()
                    if not line and self.proc.poll() is not None:
                        break
            err = self.proc.stderr.read() if self.proc.poll() is not None else ""
            self.close()
            raise RuntimeError(f"the simulated device did not print 'port: <path>' within {timeout_s} s"
                               + (f"; it said: {err.strip()[-400:]}" if err else ""))
        finally:
            sel.close()

    def alive(self):
        return self.proc.poll() is None

    def close(self):
        """Terminate the device process (and remove the temporary folder)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream:
                stream.close()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
