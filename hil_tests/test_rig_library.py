"""Protocol conformance through the library (facette.device): a fresh simulated rig,
or the real rig given with ``--device PORT`` (tests that need the rig simulator's
camera say so by using ``sim_rig_factory`` directly)."""
import numpy as np
import pytest

import facette
from facette.device import DeviceClient, DeviceException, DeviceMismatch, DeviceReset, registers


@pytest.fixture
def lib_rig(request, sim_rig_factory):
    given = request.config.getoption("--device")
    if not given:
        yield sim_rig_factory()
        return
    rig = facette.connect(given)
    yield rig
    rig.close()


def test_identity_and_definition_hash(lib_rig):
    rig = lib_rig
    ident = rig.identity
    assert ident["definition_hash"] == f"{registers.DEFINITION_HASH:#010x}"
    assert ident["protocol_version"] == registers.PROTOCOL_VERSION
    assert ident["boot_count"] >= 1 and ident["ring_len"] == 16
    info = rig.device.device_identification()
    assert info["vendor"] == registers.VENDOR and info["product_code"] == registers.PRODUCT
    assert info["revision"] == ident["fw_version"]


def test_a_device_of_another_definition_is_refused(lib_rig):
    rig = lib_rig
    rig.device.close()                          # free the port for a host of another definition
    with pytest.raises(DeviceMismatch, match="speaks protocol definition"):
        DeviceClient(rig.device.url, expected_hash=registers.DEFINITION_HASH ^ 0x1)
    ok = DeviceClient(rig.device.url)           # the matching host is accepted
    assert ok.identity["definition_hash"] == registers.DEFINITION_HASH
    ok.close()


def test_register_round_trip_and_range_checks(lib_rig):
    rig = lib_rig
    dev = rig.device
    dev.write("gap_us", 123456)
    assert dev.read("gap_us") == 123456
    dev.write_array("exposure_time_us", [1000, 2000, 3000], start=2)
    assert dev.read_array("exposure_time_us")[2:5] == [1000, 2000, 3000]
    with pytest.raises(ValueError, match="out of range"):          # refused on the host side
        dev.write("n_lights", 17)
    reg = registers.register("n_lights")
    with pytest.raises(DeviceException, match="exception 03") as exc:   # and by the device itself
        dev.write_words(reg.address, [17], what="write n_lights=17")
    assert exc.value.code == 3 and exc.value.fw_error == -3
    assert dev.read("n_lights") != 17


def test_commands_follow_the_state_machine(lib_rig):
    rig = lib_rig
    with pytest.raises(DeviceException, match="not allowed in this state"):
        rig.pause()                                             # nothing is running
    rig.clear_faults()
    rig.configure([(1000, 0)], lights=[0, 1], mode="bulb")
    rig.arm()
    assert rig.device.state() == "ARMED"
    assert rig.progress() == (0, 2)
    rig.abort()
    assert rig.device.state() == "ABORTED"


def test_gains_persist_in_flash_across_a_reboot(lib_rig):
    rig = lib_rig
    original = rig.gains()
    gains = list(np.round(np.linspace(0.8, 1.2, len(original)), 4))
    rig.set_gains(gains, save=True)
    boot = rig.device.check_reset()
    rig.reboot()
    with pytest.raises(DeviceReset):            # seen through the boot count
        for _ in range(500):
            rig.device.check_reset()
    assert rig.device.boot_count == boot + 1
    assert rig.gains() == pytest.approx(gains, abs=1e-4)
    rig.set_gains(original, save=True)          # leave a real rig as it was


def test_frame_records_match_what_the_camera_took(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    scan = rig.scan(tmp_path / "s", lights=[0, 5], exposures=[20000, 5000], mode="bulb", progress=False)
    frames = scan.manifest.frames
    assert [(f.light, f.exposure) for f in frames] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert all(f.sync and f.current_meas_mA == f.current_set_mA == 500 for f in frames)
    starts = [f.start_us for f in frames]
    assert starts == sorted(starts)
    sim_frames = rig.sim.simulator.frames
    # the camera integrated 500 mA over exactly the bulb time, on the right LED channel
    for rec, sf in zip(frames, sim_frames):
        ch = [0, 5][rec.light]
        q = np.asarray(sf["charge_mA_us"])
        assert q[ch] == pytest.approx(500 * rec.time_us, rel=1e-6)
        assert np.count_nonzero(q) == 1
