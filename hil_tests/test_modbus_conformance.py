"""Modbus RTU conformance of the device, through pymodbus and raw frames on the serial line.

Runs against a fresh simulated device (build/posix/facette-device) per test, or a real rig
with ``--device PORT`` (then the golden-vector replays assume a freshly booted rig with no
calibration stored). Every function code, each exception, identity, the definition hash,
broadcast, unit-id filtering and a corrupted CRC are covered; protocol/vectors/*.hex are
replayed byte for byte.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import serial
from pymodbus.client import ModbusSerialClient
from pymodbus.pdu import ExceptionResponse

from facette.device import registers as R
from modbus_crc import crc16

VECTORS = Path(__file__).resolve().parent.parent / "protocol" / "vectors"
UNIT = R.UNIT_ID




def frame(hexstr: str) -> bytes:
    body = bytes.fromhex(hexstr.replace(" ", ""))
    return body + crc16(body)


class Line:
    """Raw request/answer exchanges on the serial line."""

    def __init__(self, port: str):
        self.ser = serial.serial_for_url(port, baudrate=R.BAUD, timeout=1.0)
        self.ser.reset_input_buffer()

    def ask(self, request: bytes, expect_len: int | None) -> bytes:
        """Send request; read expect_len bytes (None: expect silence for 0.3 s)."""
        self.ser.reset_input_buffer()
        self.ser.write(request)
        self.ser.flush()
        if expect_len is None:
            self.ser.timeout = 0.3
            got = self.ser.read(1)
            self.ser.timeout = 1.0
            return got
        return self.ser.read(expect_len)

    def close(self):
        self.ser.close()


@pytest.fixture
def client(device_port):
    c = ModbusSerialClient(port=device_port, baudrate=R.BAUD, timeout=1, retries=0)
    assert c.connect(), f"cannot open {device_port}"
    yield c
    c.close()


@pytest.fixture
def line(device_port):
    ln = Line(device_port)
    yield ln
    ln.close()


def addr(name: str, i: int = 0) -> int:
    return R.address_of(name, i)


def read_u32(client, name: str, space: str = "input") -> int:
    fn = client.read_input_registers if space == "input" else client.read_holding_registers
    r = fn(addr(name), count=2, device_id=UNIT)
    assert not r.isError(), r
    return r.registers[0] << 16 | r.registers[1]


def exception_code(r) -> int | None:
    return r.exception_code if isinstance(r, ExceptionResponse) else None


# ---------------------------------------------------------------- identity
def test_identity_43_14_basic_objects(client):
    r = client.read_device_information(read_code=1, object_id=0, device_id=UNIT)
    assert not r.isError(), r
    assert r.information[0] == R.VENDOR.encode()
    assert r.information[1] == R.PRODUCT.encode()
    assert r.information[2] == b"1.0"
    assert r.conformity == 0x81


def test_identity_43_14_individual_object(client):
    r = client.read_device_information(read_code=4, object_id=1, device_id=UNIT)
    assert not r.isError(), r
    assert r.information == {1: R.PRODUCT.encode()}


def test_definition_hash_and_protocol_version_match_the_host_module(client):
    assert read_u32(client, "definition_hash") == R.DEFINITION_HASH
    r = client.read_input_registers(addr("protocol_version"), count=1, device_id=UNIT)
    assert r.registers == [R.PROTOCOL_VERSION]


def test_identity_registers(client):
    r = client.read_input_registers(addr("fw_version"), count=12, device_id=UNIT)
    assert not r.isError(), r
    regs = r.registers
    assert regs[addr("max_leds")] == 16 and regs[addr("ring_len")] == 16
    assert regs[addr("boot_count")] >= 1
    assert regs[addr("reset_cause")] in set(R.ResetCause)


# ---------------------------------------------------------------- function codes
def test_03_reads_every_holding_register_default(client):
    for reg in R.REGISTERS.values():
        if reg.space != "holding" or reg.name in ("command", "cal_unlock", "cal_gain", "cal_serial"):
            continue
        for i in range(reg.count):
            r = client.read_holding_registers(reg.address + i * reg.stride, count=reg.words,
                                              device_id=UNIT)
            assert not r.isError(), (reg.name, i, r)
            v = r.registers[0] << 16 | r.registers[1] if reg.words == 2 else r.registers[0]
            if reg.type == "i16" and v >= 0x8000:
                v -= 0x10000
            assert v == reg.default[i], (reg.name, i)


def test_04_reads_the_whole_frame_ring_in_one_request(client):
    r = client.read_input_registers(addr("ring_frame"), count=125, device_id=UNIT)
    assert not r.isError() and len(r.registers) == 125


def test_06_writes_and_reads_back(client):
    r = client.write_register(addr("n_lights"), 5, device_id=UNIT)
    assert not r.isError() and r.registers == [5]
    assert client.read_holding_registers(addr("n_lights"), count=1, device_id=UNIT).registers == [5]


def test_16_writes_a_u32_high_word_first(client):
    value = 2_500_000
    r = client.write_registers(addr("exposure_time_us", 3), [value >> 16, value & 0xFFFF],
                               device_id=UNIT)
    assert not r.isError(), r
    # element 0 untouched
    assert read_u32(client, "exposure_time_us", "holding") == R.REGISTERS["exposure_time_us"].default[0]
    got = client.read_holding_registers(addr("exposure_time_us", 3), count=2, device_id=UNIT)
    assert got.registers[0] << 16 | got.registers[1] == value


def test_08_00_echoes_the_data(client):
    r = client.diag_query_data(b"\xBE\xEF", device_id=UNIT)
    assert not r.isError(), r
    assert r.message == b"\xBE\xEF"


# ---------------------------------------------------------------- exceptions
def test_exception_01_illegal_function(line):
    assert line.ask(frame("01 05 0000 FF00"), 5) == frame("01 85 01")
    assert line.ask(frame("01 08 0004 0000"), 5) == frame("01 88 01")


def test_exception_02_illegal_data_address(client):
    assert exception_code(client.read_holding_registers(0x0000, count=1, device_id=UNIT)) == 2
    assert exception_code(client.read_input_registers(addr("n_lights"), count=1, device_id=UNIT)) == 2
    # a u32 is written whole or not at all
    assert exception_code(client.write_register(addr("exposure_time_us"), 1, device_id=UNIT)) == 2


def test_exception_03_illegal_data_value_changes_nothing(client):
    before = client.read_holding_registers(addr("n_lights"), count=2, device_id=UNIT).registers
    assert exception_code(client.write_register(addr("n_lights"), 17, device_id=UNIT)) == 3
    assert exception_code(client.write_registers(addr("n_lights"), [3, 99], device_id=UNIT)) == 3
    assert client.read_holding_registers(addr("n_lights"), count=2, device_id=UNIT).registers == before


def test_exception_03_quantity_out_of_range(line):
    # pymodbus refuses to send these, so they go as raw frames
    assert line.ask(frame("01 04 0000 007E"), 5) == frame("01 84 03")
    assert line.ask(frame("01 03 1100 0000"), 5) == frame("01 83 03")


def test_exception_04_refused_command_and_locked_calibration(client):
    assert exception_code(client.write_register(addr("command"), R.Command.START, device_id=UNIT)) == 4
    last = client.read_input_registers(addr("last_error"), count=1, device_id=UNIT).registers[0]
    assert last - 0x10000 == -4  # FW_ERR_STATE
    assert exception_code(client.write_register(addr("cal_gain", 0), 12000, device_id=UNIT)) == 4


# ---------------------------------------------------------------- addressing rules
def test_broadcast_write_is_executed_without_answer(line):
    assert line.ask(frame("00 06 1100 0003"), None) == b""
    assert line.ask(frame("01 03 1100 0001"), 7) == frame("01 03 02 0003")


def test_other_unit_id_gets_no_answer(line):
    assert line.ask(frame("07 03 1100 0001"), None) == b""


def test_corrupted_crc_gets_no_answer_and_changes_nothing(line):
    bad = bytearray(frame("01 06 1100 0002"))
    bad[-1] ^= 0x55
    assert line.ask(bytes(bad), None) == b""
    assert line.ask(frame("01 03 1100 0001"), 7) == frame("01 03 02 000C")


@pytest.mark.parametrize("name", sorted(p.name for p in VECTORS.glob("*.hex")))
def test_golden_vectors_byte_for_byte(line, name):
    request = None
    pairs = 0
    for text in (VECTORS / name).read_text().splitlines():
        if text.startswith(">"):
            request = bytes.fromhex(text[1:])
        elif text.startswith("<"):
            want = b"" if text[1:].strip() == "-" else bytes.fromhex(text[1:])
            got = line.ask(request, len(want) if want else None)
            assert got == want, f"{name}: request {request.hex(' ')}"
            pairs += 1
    assert pairs > 5


# ---------------------------------------------------------------- a scan over Modbus
def test_small_led_scan_fills_the_frame_ring(client):
    w = lambda name, v, i=0: client.write_register(addr(name, i), v, device_id=UNIT)  # noqa: E731
    assert not w("timing_mode", R.TimingMode.LED).isError()
    assert not w("n_lights", 3).isError()
    assert not w("n_exposures", 2).isError()
    for e, t in enumerate((5000, 70000)):
        client.write_registers(addr("exposure_time_us", e), [t >> 16, t & 0xFFFF], device_id=UNIT)
    assert not w("command", R.Command.ARM).isError()
    assert not w("command", R.Command.START).isError()
    for _ in range(2000):  # polls, not sleeps: each request takes real time on the pty
        state = client.read_input_registers(addr("state"), count=1, device_id=UNIT).registers[0]
        if state != R.State.RUNNING:
            break
    assert state == R.State.DONE
    status = client.read_input_registers(addr("frames_done"), count=2, device_id=UNIT).registers
    assert status == [6, 6]
    ring = client.read_input_registers(addr("ring_frame"), count=6 * 8, device_id=UNIT).registers
    for k in range(6):
        rec = ring[8 * k: 8 * k + 8]
        assert rec[0] == k and rec[1] == k // 2 and rec[2] == k % 2
        assert rec[3] == 500 and rec[4] == 500
        assert rec[7] == 5  # valid, flash-sync seen (the simulated device's own camera)


# ================================================================ simulated device contract
# The posix build's side channel and options, as fixed by the shared contract (the rig
# simulator codes to them). These need the simulated device, not a real rig.
import os  # noqa: E402
import re  # noqa: E402
import signal  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import threading  # noqa: E402

from posix_device import POSIX_DEVICE, start_posix_device, stop_posix_device  # noqa: E402

EVENT = re.compile(r"^(\d+) (led -?\d+ \d+|shutter [01] frame=\d+ light=\d+ exp=\d+ exp_us=\d+ "
                   r"mode=(camera|bulb|led)|focus [01]|boot \d+)$")


class Side:
    """Side-channel client; with auto=True it acks events and answers openings with sync."""

    def __init__(self, path: str, auto: bool = True):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.connect(path)
        self.lines: list[str] = []
        self.auto = auto
        self.cond = threading.Condition()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        buf = b""
        while True:
            try:
                chunk = self.sock.recv(4096)
            except OSError:
                return
            if not chunk:
                return
            buf += chunk
            while b"\n" in buf:
                raw, buf = buf.split(b"\n", 1)
                line = raw.decode()
                parts = line.split()
                if self.auto and parts[1] == "shutter" and parts[2] == "1":
                    self.send(f"sync {parts[0]}", "ack")
                elif self.auto and parts[1] in ("shutter", "led"):
                    self.send("ack")
                with self.cond:
                    self.lines.append(line)
                    self.cond.notify_all()

    def send(self, *lines: str):
        try:
            self.sock.sendall("".join(line + "\n" for line in lines).encode())
        except OSError:  # the device side closed (reset of the test, teardown)
            pass

    def wait_for(self, pattern: str, timeout: float = 5.0) -> str:
        rx = re.compile(pattern)
        with self.cond:
            ok = self.cond.wait_for(lambda: any(rx.search(x) for x in self.lines), timeout)
            assert ok, f"no side-channel line matching {pattern!r} in {self.lines[-5:]}"
            return next(x for x in self.lines if rx.search(x))

    def close(self):
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.thread.join(timeout=2)
        self.sock.close()


@pytest.fixture
def sim(tmp_path):
    dev = start_posix_device(tmp_path)
    yield dev
    stop_posix_device(dev)


def modbus(port):
    c = ModbusSerialClient(port=port, baudrate=R.BAUD, timeout=1, retries=0)
    assert c.connect()
    return c


def wreg(c, name, v, i=0):
    reg = R.REGISTERS[name]
    a = addr(name, i)
    r = (c.write_registers(a, [v >> 16, v & 0xFFFF], device_id=UNIT) if reg.words == 2
         else c.write_register(a, v & 0xFFFF, device_id=UNIT))
    assert not r.isError(), (name, r)


def rreg(c, name, i=0):
    reg = R.REGISTERS[name]
    fn = c.read_input_registers if reg.space == "input" else c.read_holding_registers
    r = fn(addr(name, i), count=reg.words, device_id=UNIT)
    assert not r.isError(), (name, r)
    return r.registers[0] << 16 | r.registers[1] if reg.words == 2 else r.registers[0]


def one_frame_scan(c, mode=R.TimingMode.LED, exp_us=20_000, lights=1):
    wreg(c, "timing_mode", int(mode))
    wreg(c, "n_lights", lights)
    wreg(c, "n_exposures", 1)
    wreg(c, "exposure_time_us", exp_us)
    wreg(c, "command", int(R.Command.ARM))
    wreg(c, "command", int(R.Command.START))


def wait_state(c, *states, polls=3000):
    for _ in range(polls):  # request/answer round trips, no sleeping
        s = rreg(c, "state")
        if s in states:
            return R.State(s)
    return R.State(s)


def test_sim_prints_the_port_first_and_links_it(tmp_path):
    link = tmp_path / "ttyRIG"
    proc = subprocess.Popen([os.fspath(POSIX_DEVICE), "--link", os.fspath(link)],
                            stdout=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()
        assert re.fullmatch(r"port: /dev/pts/\d+\n", first)
        assert os.path.realpath(link) == first.split(": ")[1].strip()
        c = modbus(os.fspath(link))
        assert rreg(c, "definition_hash") == R.DEFINITION_HASH
        c.close()
    finally:
        proc.terminate()
        proc.wait(timeout=5)
        proc.stdout.close()
    assert not link.exists()  # removed on exit


def test_sim_refuses_bad_options_with_a_message():
    r = subprocess.run([os.fspath(POSIX_DEVICE), "--speed", "-3"], capture_output=True, text=True)
    assert r.returncode == 2 and "--speed -3: give a number > 0" in r.stderr


def test_sim_events_follow_the_contract_and_carry_the_frame(sim):
    side = Side(sim.side)
    c = modbus(sim.port)
    wreg(c, "prefocus_us", 10_000)
    one_frame_scan(c, R.TimingMode.BULB, exp_us=30_000, lights=2)
    assert wait_state(c, R.State.DONE) == R.State.DONE
    side.wait_for(r" shutter 0 frame=1 ")
    c.close()
    side.close()
    lines = side.lines
    assert lines[0].split()[1:] == ["boot", "1"]
    assert all(EVENT.match(x) for x in lines), [x for x in lines if not EVENT.match(x)]
    t = {k: int(side.wait_for(p).split()[0]) for k, p in
         (("on", r" led 0 500$"), ("open", r" shutter 1 frame=0 light=0 exp=0 exp_us=30000 mode=bulb"),
          ("close", r" shutter 0 frame=0"), ("off", r" led -1 0$"))}
    assert t["close"] - t["open"] == 30_000 and t["off"] == t["close"]
    assert t["open"] - t["on"] == R.REGISTERS["settle_us"].default[0]


def test_sim_lockstep_freezes_virtual_time_until_ack(sim):
    side = Side(sim.side, auto=False)
    c = modbus(sim.port)
    one_frame_scan(c, R.TimingMode.LED, exp_us=1000)
    side.wait_for(r" shutter 1 frame=0")
    left = [rreg(c, "time_left_us") for _ in range(20)]
    assert len(set(left)) == 1 and rreg(c, "state") == R.State.RUNNING
    side.send(f"sync {side.lines[-1].split()[0]}", "ack")
    side.wait_for(r" led 0 500$")
    side.send("ack")
    side.wait_for(r" led -1 0$")
    side.send("ack")
    side.wait_for(r" shutter 0 frame=0")
    side.send("ack")
    assert wait_state(c, R.State.DONE) == R.State.DONE
    assert rreg(c, "ring_flags", 0) == 5  # the sync we sent was counted
    c.close()
    side.close()


def test_sim_miss_sync_without_simulator_retries_then_faults(sim):
    side = Side(sim.side)
    side.send("miss_sync 1")
    side.close()
    c = modbus(sim.port)
    one_frame_scan(c)
    assert wait_state(c, R.State.DONE, R.State.FAULT) == R.State.DONE
    assert rreg(c, "retries_used") == 1 and rreg(c, "ring_count") == 2
    side = Side(sim.side)
    side.send("miss_sync 2")
    side.close()
    wreg(c, "command", int(R.Command.ARM))
    wreg(c, "command", int(R.Command.START))
    assert wait_state(c, R.State.FAULT) == R.State.FAULT
    assert rreg(c, "fault_bits") & (1 << R.Fault.SYNC_MISSED)
    c.close()


def test_sim_side_channel_lines_sent_before_hanging_up_are_carried_out(sim):
    """A client may send its lines and hang up before the device accepts it (the
    device was busy: under load it often is). Its greeting then fails (EPIPE); the
    lines it sent must still be read and carried out."""
    os.kill(sim.process.pid, signal.SIGSTOP)     # the device cannot accept yet
    try:
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.connect(sim.side)
        s.sendall(b"miss_sync 1\n")
        s.shutdown(socket.SHUT_RDWR)
        s.close()
    finally:
        os.kill(sim.process.pid, signal.SIGCONT)
    c = modbus(sim.port)
    one_frame_scan(c)
    assert wait_state(c, R.State.DONE, R.State.FAULT) == R.State.DONE
    assert rreg(c, "retries_used") == 1 and rreg(c, "ring_count") == 2   # the missed sync
    c.close()


def test_sim_injected_faults_and_measurements(sim):
    side = Side(sim.side)
    c = modbus(sim.port)
    side.send("supply 11500", "ntc 4321")
    for _ in range(200):
        if rreg(c, "led_temp_cC") == 4321:
            break
    assert rreg(c, "led_temp_cC") == 4321 and rreg(c, "supply_mV") == 11500
    side.send("led_fault 0 open")
    one_frame_scan(c)
    assert wait_state(c, R.State.FAULT) == R.State.FAULT
    assert rreg(c, "fault_bits") & (1 << R.Fault.LED_OPEN)
    side.send("led_fault 0 ok")
    wreg(c, "command", int(R.Command.CLEAR_FAULTS))
    side.send("ntc 9000")
    assert wait_state(c, R.State.FAULT) == R.State.FAULT
    assert rreg(c, "fault_bits") & (1 << R.Fault.OVERTEMP)
    c.close()
    side.close()


def test_sim_button_starts_and_aborts_the_scan(sim):
    side = Side(sim.side)
    c = modbus(sim.port)
    wreg(c, "n_lights", 2)
    side.send("button 1")
    rreg(c, "state")  # let the device see the level for a while (debounce in virtual time)
    side.send("button 0")
    # default bracket: 2 lights x 28 s of exposures, far longer than these few requests
    assert wait_state(c, R.State.RUNNING) == R.State.RUNNING
    side.send("button 1")
    rreg(c, "state")
    side.send("button 0")
    assert wait_state(c, R.State.ABORTED) == R.State.ABORTED
    assert rreg(c, "led_channel") == 0xFFFF  # -1: lights off
    c.close()
    side.close()


def test_sim_reset_keeps_flash_and_counts_boots(sim):
    side = Side(sim.side)
    c = modbus(sim.port)
    wreg(c, "cal_unlock", R.UNLOCK_KEY)
    wreg(c, "cal_gain", 12345, 2)
    wreg(c, "command", int(R.Command.SAVE))
    side.send("reset")
    side.wait_for(r" boot 2$")
    assert rreg(c, "boot_count") == 2 and rreg(c, "reset_cause") == R.ResetCause.PIN
    assert rreg(c, "cal_gain", 2) == 12345 and rreg(c, "cal_sequence") == 1
    c.close()
    side.close()


def test_sim_state_dir_keeps_calibration_across_restarts(tmp_path):
    state = tmp_path / "state"
    (tmp_path / "a").mkdir()
    dev = start_posix_device(tmp_path / "a", state=state)
    c = modbus(dev.port)
    wreg(c, "cal_unlock", R.UNLOCK_KEY)
    wreg(c, "cal_serial", 777_000)
    wreg(c, "command", int(R.Command.SAVE))
    c.close()
    stop_posix_device(dev)
    (tmp_path / "b").mkdir()
    dev = start_posix_device(tmp_path / "b", state=state)
    c = modbus(dev.port)
    assert rreg(c, "serial_number") == 777_000 and rreg(c, "boot_count") == 2
    c.close()
    stop_posix_device(dev)


def test_sim_bit_errors_are_caught_by_the_crc(sim):
    side = Side(sim.side)
    ln = Line(sim.port)
    side.send("biterr 1.0")
    rreg_line = frame("01 03 1100 0001")
    got = ln.ask(rreg_line, None)
    assert got == b""  # every byte corrupted: no frame passes its CRC
    side.send("biterr 0")
    assert ln.ask(rreg_line, 7) == frame("01 03 02 000C")
    ln.close()
    side.close()
