"""DeviceClient against the real firmware core over a pty (build/posix/facette-device)."""
import pytest

from facette.device import registers as R
from facette.device import DeviceClient, DeviceError, DeviceException, DeviceMismatch, DeviceReset


@pytest.fixture
def client(sim_device):
    c = DeviceClient(sim_device.port)
    yield c
    c.close()


def test_identity_and_registers_by_name(client):
    assert client.identity["definition_hash"] == R.DEFINITION_HASH
    assert client.identity["reset_cause"] in R.ResetCause.__members__
    client.write("gap_us", 123456)
    assert client.read("gap_us") == 123456                     # u32 over two words
    client.write_array("light_current_mA", [400, 410, 420], start=2)
    assert client.read_array("light_current_mA")[2:5] == [400, 410, 420]
    block = client.read_block(["state", "fault_bits", "last_error"])
    assert set(block) == {"state", "fault_bits", "last_error"}
    assert client.state() == "IDLE"
    assert client.device_identification()["vendor"] == "facette"


def test_values_out_of_the_definition_range_are_refused_before_sending(client):
    before = client.stats["requests"]
    with pytest.raises(ValueError, match=r"n_lights = 99 is out of range \[1, 16\]"):
        client.write("n_lights", 99)
    with pytest.raises(ValueError, match="read-only"):
        client.write("state", 1)
    with pytest.raises(KeyError, match="no register named 'n_light'"):
        client.read("n_light")
    assert client.stats["requests"] == before                   # nothing went to the device


def test_a_refused_command_says_the_device_reason_in_words(client):
    with pytest.raises(DeviceException) as exc:
        client.command("START")                                 # IDLE: not armed
    assert exc.value.fw_error == -4 and "not allowed in this state" in str(exc.value)
    assert exc.value.exit_code == 1


def test_a_wrong_definition_hash_is_refused(sim_device):
    with pytest.raises(DeviceMismatch, match="update the firmware or this facette"):
        DeviceClient(sim_device.port, expected_hash=0x12345678)


def test_a_port_that_does_not_open_is_bad_input(tmp_path):
    with pytest.raises(DeviceError) as exc:
        DeviceClient(str(tmp_path / "no-such-port"))
    assert exc.value.exit_code == 2 and "cannot open the port" in exc.value.message
    assert "check the port name" in exc.value.hint


def test_a_reboot_is_seen_once_as_a_reset(sim_device):
    c = DeviceClient(sim_device.port)
    try:
        boot = c.check_reset()
        c.command("REBOOT")
        with pytest.raises(DeviceReset) as exc:
            for _ in range(200):
                c.check_reset()
        assert exc.value.old_boot == boot and exc.value.new_boot == boot + 1
        assert c.check_reset() == boot + 1                      # once only
    finally:
        c.close()
