"""The STM32F405 build booted under QEMU (netduinoplus2), spoken to over Modbus RTU.

`make qemu-test` builds build/stm32f4/facette-stm32f4.elf and runs this file with
``--qemu-elf``; the ``qemu_board`` fixture (conftest.py) boots it with USART1 on a
local TCP port and kills QEMU afterwards. The host side is pymodbus's serial
client on pyserial's ``socket://`` URL, plus pyserial alone for the raw-frame
checks. What QEMU does not model (RCC, GPIO, ADC conversions, DAC, flash
controller, IWDG) is handled by the port as documented in
firmware/ports/stm32f4/README.md; the expectations below follow from it.
"""
from __future__ import annotations

import struct
import time

import pytest
import serial
from pymodbus.client import ModbusSerialClient
from pymodbus.pdu import ExceptionResponse

from facette.device import registers as R
from modbus_crc import crc16

UNIT = R.UNIT_ID
EMULATED_UID = 0x454D5531   # hal_unique_id() when the RCC is absent ("EMU1")
REQUEST_TIMEOUT_S = 1.0


@pytest.fixture
def modbus(qemu_board):
    """pymodbus RTU client on the board's socket:// URL."""
    client = ModbusSerialClient(qemu_board.url, baudrate=R.BAUD, timeout=REQUEST_TIMEOUT_S,
                                retries=3)
    assert client.connect(), f"cannot open {qemu_board.url}\n{qemu_board.log_tail()}"
    yield client
    client.close()


def _ok(response, what):
    assert not response.isError(), f"{what}: {response}"
    return response


def _read(client, name, index=0):
    """Read one register (element `index`) by name, decoded per its type."""
    reg = R.REGISTERS[name]
    address = reg.address + index * reg.stride
    if reg.space == "input":
        rr = client.read_input_registers(address, count=reg.words, device_id=UNIT)
    else:
        rr = client.read_holding_registers(address, count=reg.words, device_id=UNIT)
    words = _ok(rr, f"read {name}").registers
    if reg.type == "u32":
        return words[0] << 16 | words[1]
    if reg.type == "i16":
        return struct.unpack(">h", struct.pack(">H", words[0]))[0]
    return words[0]


def _write(client, name, value):
    """Write a holding register by name: 06 for 16-bit, 16 for u32 (high word first)."""
    reg = R.REGISTERS[name]
    if reg.type == "u32":
        return client.write_registers(reg.address, [value >> 16 & 0xFFFF, value & 0xFFFF],
                                      device_id=UNIT)
    return client.write_register(reg.address, value & 0xFFFF, device_id=UNIT)




def _read_frame(port: serial.Serial, expected_len: int, timeout_s: float) -> bytes:
    """Bytes received until expected_len or the deadline (bounded poll)."""
    deadline = time.monotonic() + timeout_s
    data = b""
    while len(data) < expected_len and time.monotonic() < deadline:
        data += port.read(expected_len - len(data))
    return data


def test_read_device_identification_43_14(modbus):
    rr = _ok(modbus.read_device_information(read_code=1, object_id=0, device_id=UNIT),
             "43/14 basic")
    fw_version = _read(modbus, "fw_version")
    assert rr.information[0].decode() == R.VENDOR
    assert rr.information[1].decode() == R.PRODUCT
    assert rr.information[2].decode() == f"{fw_version >> 8}.{fw_version & 0xFF}"


def test_identity_registers_and_definition_hash(modbus):
    assert _read(modbus, "definition_hash") == R.DEFINITION_HASH
    assert _read(modbus, "protocol_version") == R.PROTOCOL_VERSION
    assert _read(modbus, "max_leds") == 16
    # No calibration is stored (QEMU's flash is a ROM), so the serial number is
    # the port's unique id, which is fixed under emulation.
    assert _read(modbus, "serial_number") == EMULATED_UID
    # QEMU has no RCC reset flags and no backup domain.
    assert _read(modbus, "reset_cause") == R.ResetCause.UNKNOWN
    assert _read(modbus, "boot_count") == 1


def test_boots_idle_with_only_the_missing_calibration_fault(modbus):
    # The emulated board reports a healthy idle rig (no ADC under QEMU): no
    # temperature, supply or LED fault may be latched at boot. The flash holds
    # no calibration record, which the core latches as CAL_INVALID.
    assert _read(modbus, "state") == R.State.IDLE
    assert _read(modbus, "fault_bits") == 1 << R.Fault.CAL_INVALID
    assert _read(modbus, "led_temp_cC") == 2500
    assert _read(modbus, "supply_mV") == 12000
    assert _read(modbus, "led_channel") == -1


@pytest.mark.parametrize("name", ["settle_us", "n_lights", "max_current_mA"])
def test_configuration_register_written_and_read_back(modbus, name):
    reg = R.REGISTERS[name]
    value = (reg.minimum + reg.maximum) // 2
    if value == reg.default[0]:
        value += 1
    _ok(_write(modbus, name, value), f"write {name}")
    assert _read(modbus, name) == value


@pytest.mark.parametrize("name", ["settle_us", "n_lights", "max_current_mA"])
def test_out_of_range_write_is_exception_03_and_changes_nothing(modbus, name):
    reg = R.REGISTERS[name]
    before = _read(modbus, name)
    rr = _write(modbus, name, reg.maximum + 1)
    assert isinstance(rr, ExceptionResponse), f"write {name}={reg.maximum + 1}: {rr}"
    assert rr.exception_code == 3
    assert _read(modbus, name) == before


def test_frame_with_bad_crc_gets_no_answer_and_the_next_one_does(qemu_board):
    reg = R.REGISTERS["definition_hash"]
    pdu = struct.pack(">BBHH", UNIT, 0x04, reg.address, 2)
    good = pdu + crc16(pdu)
    bad = good[:-1] + bytes([good[-1] ^ 0xFF])
    expected = struct.pack(">BBBI", UNIT, 0x04, 4, R.DEFINITION_HASH)
    expected += crc16(expected)
    with serial.serial_for_url(qemu_board.url, baudrate=R.BAUD, timeout=0.05) as port:
        # The device may still be booting: retry the good frame until it answers.
        answer = b""
        deadline = time.monotonic() + 5.0
        while answer != expected and time.monotonic() < deadline:
            port.reset_input_buffer()
            port.write(good)
            answer = _read_frame(port, len(expected), REQUEST_TIMEOUT_S)
        assert answer == expected, f"no answer to a valid request\n{qemu_board.log_tail()}"

        port.write(bad)
        assert _read_frame(port, 1, 0.5) == b"", "a frame with a bad CRC was answered"
        # The bad frame must have been dropped at the 3.5-character silence,
        # not glued to the next request.
        port.write(good)
        assert _read_frame(port, len(expected), REQUEST_TIMEOUT_S) == expected


def test_uptime_follows_the_host_clock(modbus):
    """The µs clock (SysTick at the emulated 168 MHz) runs at real-time rate: two
    increments of uptime_s two counts apart are about two seconds apart on the host.
    Each increment is bracketed by host times, from the request before the last read
    that still showed the old count to the reply that showed the new one, so a slow
    reply on a loaded machine widens the bracket instead of failing the test."""
    def next_increment(after, timeout_s=5.0):
        deadline = time.monotonic() + timeout_s
        sent_before = time.monotonic()
        while time.monotonic() < deadline:
            sent = time.monotonic()
            now = _read(modbus, "uptime_s")
            if now > after:
                return now, sent_before, time.monotonic()
            sent_before = sent
            time.sleep(0.01)   # poll interval
        raise AssertionError(f"uptime_s stuck at {after} for {timeout_s} s")

    first, _, _ = next_increment(_read(modbus, "uptime_s"))
    second, lo_a, hi_a = next_increment(first)
    later, lo_b, hi_b = next_increment(second + 1)
    counts = later - second   # 2, or more when a reply came late
    shortest, longest = lo_b - hi_a, hi_b - lo_a
    # Within 4x: a wrong SysTick source or reload is off by 8x (HCLK/8) or 10.5x (HSI),
    # while a guest starved of the host CPU misses ticks (2.9 and 4.2 s for 2 counts
    # under 3 busy loops on 2 cores).
    assert shortest < counts * 4.0 and longest > counts / 4.0, \
        f"{counts} counts of uptime_s took {shortest:.2f}-{longest:.2f} s of host time"


def test_scan_runs_on_the_board_timer_and_faults_without_flash_sync(modbus):
    """A 1 x 1 LED-timed scan runs on the one-shot timer (under QEMU: the SysTick
    backstop, TIM5 compares are not modelled). No camera drives the sync input
    (QEMU has no GPIO), so the frame is retried once and SYNC_MISSED latches."""
    config = {"n_lights": 1, "n_exposures": 1, "timing_mode": R.TimingMode.LED, "retries": 1,
              "settle_us": 0, "gap_us": 3000, "led_pre_us": 1000, "led_post_us": 1000,
              "sync_timeout_us": 5000}
    _ok(_write(modbus, "command", R.Command.CLEAR_FAULTS), "clear faults")
    for name, value in config.items():
        _ok(_write(modbus, name, value), f"write {name}")
    reg = R.REGISTERS["exposure_time_us"]
    _ok(modbus.write_registers(reg.address, [0, 2000], device_id=UNIT), "exposure 0")
    _ok(_write(modbus, "command", R.Command.ARM), "arm")
    assert _read(modbus, "state") == R.State.ARMED
    _ok(_write(modbus, "command", R.Command.START), "start")

    deadline = time.monotonic() + 10.0
    state = _read(modbus, "state")
    while state in (R.State.ARMED, R.State.RUNNING) and time.monotonic() < deadline:
        time.sleep(0.01)   # poll interval
        state = _read(modbus, "state")
    assert state == R.State.FAULT, f"scan ended in {R.State(state).name}"
    assert _read(modbus, "fault_bits") & (1 << R.Fault.SYNC_MISSED)
    assert _read(modbus, "ring_count") == 2

    def ring(name, i):
        reg = R.REGISTERS[name]
        rr = modbus.read_input_registers(reg.address + i * reg.stride, count=reg.words,
                                         device_id=UNIT)
        words = _ok(rr, f"read {name}[{i}]").registers
        return words[0] << 16 | words[1] if reg.type == "u32" else words[0]

    # flags: bit 0 sync seen, bit 1 retry, bit 2 valid.
    assert [ring("ring_flags", i) for i in range(2)] == [0b100, 0b110]
    set_mA = ring("ring_current_set_mA", 0)
    assert set_mA == R.REGISTERS["light_current_mA"].default[0]
    # The emulated sense reads the DAC setpoint back (within one DAC step, ~0.5 mA).
    assert abs(ring("ring_current_meas_mA", 0) - set_mA) <= 1
    # The retry's shutter opens once the sync wait and the gap are over, not before.
    # QEMU is not real-time: on a loaded host the SysTick backstop may run a few ms
    # late, so the upper bound only tells one wait from two (5000 + 3000 twice).
    step = ring("ring_start_us", 1) - ring("ring_start_us", 0)
    assert 5000 + 3000 <= step < 2 * (5000 + 3000), step


def test_calibration_save_reports_the_flash_error_on_the_emulated_rom(modbus):
    """QEMU's flash is a ROM: the port's erase read-back fails, and the device
    answers exception 04 (flash error) instead of claiming a save."""
    _ok(_write(modbus, "cal_unlock", R.UNLOCK_KEY), "unlock")
    rr = _write(modbus, "command", R.Command.SAVE)
    assert isinstance(rr, ExceptionResponse) and rr.exception_code == 4, rr
    assert _read(modbus, "last_error") == -8   # FW_ERR_FLASH
    assert _read(modbus, "cal_sequence") == 0


def test_reboot_command_resets_the_board(modbus):
    reg = R.REGISTERS["n_lights"]
    changed = reg.default[0] - 1
    _ok(_write(modbus, "n_lights", changed), "write n_lights")
    assert _read(modbus, "n_lights") == changed
    _ok(_write(modbus, "command", R.Command.REBOOT), "reboot")
    # After the reset the configuration is back to its defaults.
    deadline = time.monotonic() + 5.0
    value = changed
    while value == changed and time.monotonic() < deadline:
        time.sleep(0.01)   # poll interval
        value = _read(modbus, "n_lights")
    assert value == reg.default[0]
    assert _read(modbus, "uptime_s") <= 3   # since the reset, even with slow replies
    assert _read(modbus, "state") == R.State.IDLE


def test_host_device_client_talks_to_the_board(qemu_board):
    """facette.device.DeviceClient reaches the emulated board through its
    socket:// URL exactly as a serial port, and refuses another definition."""
    from facette.device.client import DeviceClient, DeviceMismatch

    dev = DeviceClient(qemu_board.url)
    try:
        assert dev.identity["definition_hash"] == R.DEFINITION_HASH
        assert dev.identity["serial_number"] == EMULATED_UID
        dev.write("gap_us", 123457)
        assert dev.read("gap_us") == 123457
    finally:
        dev.close()
    with pytest.raises(DeviceMismatch):
        DeviceClient(qemu_board.url, expected_hash=R.DEFINITION_HASH ^ 1)
