"""Fixtures of the hardware-in-the-loop tests.

QEMU board (``--qemu-elf``): ``qemu_board`` boots the STM32F405 build under
``qemu-system-arm -M netduinoplus2`` with USART1 on a local TCP port and yields
its pyserial URL (``socket://127.0.0.1:PORT``). ``make qemu-test`` builds the ELF
and passes it; without the option, test_qemu_board.py is not collected.
"""
from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from modbus_crc import crc16
from posix_device import REPO, POSIX_DEVICE, PosixDevice, start_posix_device, stop_posix_device, stop_process  # noqa: F401

QEMU_TEST_FILE = "test_qemu_board.py"
QEMU_BOOT_TIMEOUT_S = 10.0


def pytest_addoption(parser):
    dev = parser.getgroup("device")
    dev.addoption("--device", metavar="PORT_OR_URL", default=None,
                  help="serial port or pyserial URL of a real rig for the Modbus conformance "
                       "tests (default: start a fresh simulated device, build/posix/facette-device)")
    group = parser.getgroup("qemu board")
    group.addoption("--qemu-elf", metavar="PATH", default=None,
                    help="STM32F405 ELF to boot under qemu-system-arm -M netduinoplus2 "
                         "for hil_tests/test_qemu_board.py (make qemu-test passes it)")


def pytest_ignore_collect(collection_path, config):
    # The QEMU board tests need a firmware build: they run from `make qemu-test`,
    # not in the plain `pytest` run (which has no ELF yet on a fresh clone).
    # (A file named on the command line is collected anyway; its tests then stop
    # at the qemu_board fixture, which says that --qemu-elf is missing.)
    if collection_path.name == QEMU_TEST_FILE and config.getoption("--qemu-elf") is None:
        return True
    return None


@dataclass
class QemuBoard:
    """A running emulated board: ``url`` for pyserial/pymodbus, QEMU's process and log."""

    url: str
    port: int
    process: subprocess.Popen
    log_path: Path

    def log_tail(self, lines: int = 30) -> str:
        """Last lines of QEMU's log (guest errors; add ``unimp`` to ``-d`` to see every
        access to a device QEMU does not model, about three per main-loop pass)."""
        try:
            text = self.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return "(no QEMU log)"
        return "\n".join(text[-lines:])


def _free_local_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(proc: subprocess.Popen, port: int, timeout_s: float) -> bool:
    """Poll until QEMU accepts on port (True) or exits / times out (False)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return False
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.02)   # poll interval while QEMU opens its socket
    return False




def _wait_modbus_ready(url: str, timeout_s: float) -> bool:
    """Poll with a Modbus 08/00 echo until the firmware answers it.

    QEMU listens before the guest has enabled its USART, and bytes that arrive
    earlier are dropped, so the first request after boot would be lost."""
    import serial   # pyserial: the same transport the tests use

    pdu = bytes([1, 0x08, 0x00, 0x00, 0xA5, 0x5A])
    request = pdu + crc16(pdu)
    deadline = time.monotonic() + timeout_s
    with serial.serial_for_url(url, timeout=0.05) as port:
        while time.monotonic() < deadline:
            port.reset_input_buffer()
            port.write(request)
            answer = b""
            answer_deadline = time.monotonic() + 0.1
            while len(answer) < len(request) and time.monotonic() < answer_deadline:
                answer += port.read(len(request) - len(answer))
            if answer == request:
                return True
    return False


@pytest.fixture
def qemu_board(request, tmp_path):
    """Boot the --qemu-elf firmware under QEMU; killed at teardown whatever happens."""
    elf = request.config.getoption("--qemu-elf")
    if elf is None:
        raise pytest.UsageError("qemu_board needs --qemu-elf PATH (make qemu-test passes it)")
    elf = Path(elf)
    if not elf.is_file():
        raise FileNotFoundError(f"--qemu-elf {elf}: no such file; build it with `make firmware`")
    qemu = shutil.which("qemu-system-arm")
    if qemu is None:
        raise FileNotFoundError("qemu-system-arm not found: run `make deps` "
                                "(tools/install-debian-deps.sh installs qemu-system-arm)")
    log_path = tmp_path / "qemu.log"
    out_path = tmp_path / "qemu.out"
    for _attempt in range(3):   # the free port can be taken between probe and bind
        port = _free_local_port()
        # nodelay: QEMU sends each transmitted byte on its own; with Nagle on,
        # every answer would wait ~40 ms for the client's delayed ACK.
        cmd = [qemu, "-M", "netduinoplus2", "-nographic", "-monitor", "none",
               "-serial", f"tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on",
               "-kernel", os.fspath(elf), "-d", "guest_errors", "-D", os.fspath(log_path)]
        with open(out_path, "wb") as out:
            proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out,
                                    stderr=subprocess.STDOUT)
        request.addfinalizer(lambda p=proc: stop_process(p))
        if _wait_listening(proc, port, QEMU_BOOT_TIMEOUT_S):
            board = QemuBoard(f"socket://127.0.0.1:{port}", port, proc, log_path)
            if not _wait_modbus_ready(board.url, QEMU_BOOT_TIMEOUT_S):
                raise RuntimeError(f"the firmware under QEMU does not answer a Modbus "
                                   f"08/00 echo within {QEMU_BOOT_TIMEOUT_S} s\n"
                                   f"{board.log_tail()}")
            return board
        stop_process(proc)
    raise RuntimeError(f"QEMU did not open its serial port: {' '.join(cmd)}\n"
                       f"{out_path.read_text(errors='replace')}")


# ---------------------------------------------------------------- rig library (test_rig_*.py)
# A fresh simulated rig per test: the posix device plus the rig simulator (camera, LEDs,
# faults) on its side channel, through `facette.connect("sim")`. Options go to
# facette.sim.SimulatedRig (faults="biterr=1e-3", scene=..., speed=...).
RIG_SIM_SPEED = 2000.0


@pytest.fixture
def sim_rig_factory():
    """make(**options) -> a connected simulated Rig; every rig is closed at teardown."""
    import facette

    rigs = []

    def make(**options):
        options.setdefault("speed", RIG_SIM_SPEED)
        rig = facette.connect("sim", **options)
        rigs.append(rig)
        return rig

    yield make
    for rig in rigs:
        rig.close()


# ---------------------------------------------------------------- simulated device (posix build)
# `posix_device` starts a fresh build/posix/facette-device per test (its own pty, side-channel
# socket and flash state directory) and stops it at teardown; `device_port` is the port the
# Modbus conformance tests talk to: --device when given, else the fresh simulated device's pty.
@pytest.fixture
def posix_device(tmp_path):
    """A fresh simulated device, stopped at teardown."""
    dev = start_posix_device(tmp_path)
    yield dev
    stop_posix_device(dev)


@pytest.fixture
def device_port(request, tmp_path):
    """--device when given, else the pty of a fresh simulated device."""
    given = request.config.getoption("--device")
    if given:
        yield given
        return
    dev = start_posix_device(tmp_path)
    yield dev.port
    stop_posix_device(dev)
