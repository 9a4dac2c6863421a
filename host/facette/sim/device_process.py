"""Start and stop the simulated device (the firmware's posix build: firmware/README.md, "Simulated device")."""
from __future__ import annotations

import os
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

    link : bool, also make ``workdir/tty`` a symlink to the pty and give that as `port`
        (it survives `restart`, as a udev name survives a USB replug)

    Attributes: ``port`` (the path to give the Modbus client), ``pty``, ``side_socket``,
    ``state_dir``, ``proc``.

    The process gets SIGTERM when the *thread* that started it ends (Linux
    PR_SET_PDEATHSIG, so that a killed test run leaves nothing behind): start it
    from a thread that lives as long as you use it (the main thread usually).
    """

    def __init__(self, speed=50.0, side=True, state_dir=None, workdir=None, startup_timeout_s=20.0,
                 extra_args=(), link=False):
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
        self.link = self.workdir / "tty" if link else None
        self.speed = float(speed)
        self.startup_timeout_s = startup_timeout_s
        self.args = [str(device_binary()), "--speed", f"{speed:g}", "--state", str(self.state_dir)]
        if side:
            self.args += ["--side", str(self.side_socket)]
        if link:
            self.args += ["--link", str(self.link)]
        self.args += list(extra_args)
        self.proc = None
        self.pty = None
        self._start()
        # with a link, the port name survives restarts (as a udev name survives a replug)
        self.port = str(self.link) if link else self.pty

    def _start(self):
        # stdout and stderr go to files: a pipe nobody reads could fill up and block the device
        self._out = open(self.workdir / "device.out", "w+")
        self._err = open(self.workdir / "device.log", "a")
        self.proc = subprocess.Popen(self.args, stdout=self._out, stderr=self._err, stdin=subprocess.DEVNULL,
                                     preexec_fn=_die_with_parent)
        deadline = time.monotonic() + self.startup_timeout_s
        while True:
            self._out.seek(0)
            first = self._out.readline()
            if first.startswith("port:") and first.endswith("\n"):
                self.pty = first.split(":", 1)[1].strip()
                break
            if self.proc.poll() is not None or time.monotonic() > deadline:
                log = (self.workdir / "device.log").read_text()[-400:]
                self.close()
                raise RuntimeError(f"the simulated device did not print 'port: <path>' within "
                                   f"{self.startup_timeout_s} s" + (f"; it said: {log.strip()}" if log else ""))
            time.sleep(0.002)
        while self.side_socket is not None and not self.side_socket.exists() or \
                self.link is not None and not self.link.exists():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the simulated device did not open its side channel {self.side_socket}")
            time.sleep(0.002)

    def restart(self):
        """Power-cycle: stop the process and start it again (same flash, same link name)."""
        self._stop_process()
        if self.side_socket is not None and self.side_socket.exists():
            self.side_socket.unlink()
        self._start()
        if self.link is None:
            self.port = self.pty

    def alive(self):
        return self.proc.poll() is None

    def _stop_process(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout=5)
        for fh in (getattr(self, "_out", None), getattr(self, "_err", None)):
            if fh is not None and not fh.closed:
                fh.close()

    def close(self):
        """Terminate the device process (and remove the temporary folder)."""
        self._stop_process()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
