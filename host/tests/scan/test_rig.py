"""Rig (scan/rig.py) on the real firmware core: limits read from the device and refused by the
host exactly where the device would refuse them at ARM, status, faults, commands."""
import pytest

from facette.device import DeviceClient, DeviceException
from facette.device import registers as R
from facette.scan import Rig
from facette.errors import BadInputError


@pytest.fixture
def rig(sim_device):
    r = Rig(DeviceClient(sim_device.port))
    r.device.write("max_current_mA", 1000)
    r.device.write("max_pulse_us", 20_000_000)
    yield r
    if r.device.state() in ("ARMED", "RUNNING", "PAUSED"):
        r.abort()
    r.device.close()


def test_limits_are_the_devices(rig):
    lim = rig.limits()
    assert lim["max_current_mA"] == 1000 and lim["hard_max_current_mA"] == 1500
    assert lim["max_pulse_us"] == 20_000_000 and len(lim["gains"]) == rig.device.identity["max_leds"]


@pytest.mark.parametrize("current, ok", [(1000, True), (1001, False)])
def test_the_host_refuses_a_current_exactly_where_the_device_would(rig, current, ok):
    rig.device.write("n_lights", 1)
    exps = [(10_000, 0)]
    if ok:
        rig.configure(exps, lights=[0], light_current_mA=current)
        rig.arm()                                                  # the device agrees
        assert rig.device.state() == "ARMED"
        rig.abort()
        return
    with pytest.raises(BadInputError) as exc:
        rig.configure(exps, lights=[0], light_current_mA=current)
    assert "max_current_mA = 1000 mA" in exc.value.message and "at most 1000 mA" in exc.value.hint
    # the device, configured behind the host's back, refuses the same at ARM, in words
    rig.device.write_array("light_current_mA", [current])
    with pytest.raises(DeviceException, match="invalid scan configuration"):
        rig.arm()
    assert rig.last_error() == "invalid scan configuration"


def test_a_pulse_above_max_pulse_us_is_refused_with_the_settle_time_counted(rig):
    settle = rig.device.read("settle_us")
    with pytest.raises(BadInputError, match="max_pulse_us = 20 s"):
        rig.configure([(20_000_000 - settle + 1, 0)], lights=[0])
    rig.configure([(20_000_000 - settle, 0)], lights=[0])        # exactly at the limit
    rig.configure([(20_000_000, 0)], lights=[0], mode="led")      # the LED times it: no settle


def test_a_gain_counts_in_the_current_limit(rig):
    rig.device.write("cal_unlock", R.UNLOCK_KEY)
    rig.device.write("cal_gain", 20000, 3)                         # × 2.0 on LED 3
    try:
        with pytest.raises(BadInputError, match=r"× its calibration gain 2 = 1200 mA"):
            rig.configure([(10_000, 0)], lights=[3], light_current_mA=600)
        rig.configure([(10_000, 0)], lights=[3], light_current_mA=500)
    finally:
        rig.device.write("cal_unlock", R.UNLOCK_KEY)
        rig.device.write("cal_gain", 10000, 3)


def test_configure_refuses_bad_shapes(rig):
    with pytest.raises(ValueError, match="timing mode|mode must be"):
        rig.configure([(10_000, 0)], mode="flash")
    with pytest.raises(ValueError, match="1..16 exposures"):
        rig.configure([])
    with pytest.raises(ValueError, match="unknown timing settings"):
        rig.configure([(10_000, 0)], lights=[0], settle=5)


def test_status_faults_and_commands(rig):
    st = rig.status()
    assert st["state"] in ("IDLE", "ABORTED", "DONE") and isinstance(st["faults"], list)
    assert set(rig.faults()) == {"latched", "log"}
    rig.configure([(10_000, 0), (1_000, 0)], lights=[0, 1])
    rig.start()
    assert rig.wait_state({"DONE"}, timeout_s=30) == "DONE"
    records, seen, lost = rig.frame_records(0)
    assert seen == 4 and lost == 0 and [(r["light"], r["exposure"]) for r in records] == \
        [(0, 0), (0, 1), (1, 0), (1, 1)]
    with pytest.raises(DeviceException, match="not allowed in this state"):
        rig.abort()                                                # nothing running


def test_a_real_rig_answers_what_it_cannot_know_as_unknown(rig, tmp_path):
    """The Rig interface acquisition and the wizard use: a real rig has no truth, no sensor or
    pixel pitch of its own (they come from its profile), a person presses its button and places
    its targets; its latched faults are named."""
    assert rig.sensor is None and rig.pixel_pitch_mm is None
    assert rig.save_truth(tmp_path, [0, 1]) is None and list(tmp_path.iterdir()) == []
    assert not rig.can_press_button and rig.sim is None
    with pytest.raises(BadInputError, match="pressed by a person"):
        rig.press_button()
    assert rig.show_target("spectralon") is None and rig.restore_scene() is None
    assert rig.name == f"rig-{rig.device.identity['serial_number']}"
    # the simulated device boots with no calibration in its flash: CAL_INVALID latched, by name
    assert rig.device.read("fault_bits") == 1 << R.Fault.CAL_INVALID.value
    assert rig.latched_faults() == ["CAL_INVALID"]
