"""Each injected fault on the simulated rig: the scan completes through retries, or it
stops with a clear message and an intact journal, and no captured frame is lost."""
import json

import pytest

from facette.scan import ScanDirectory, ScanError

SHORT = [(200_000, 0), (20_000, 0), (2_000, 0)]
N = 12 * len(SHORT)


def _journal(scan_dir):
    return [json.loads(x) for x in (scan_dir / "journal.jsonl").read_text().splitlines()]


def _nothing_lost(rig, scan_dir):
    """Every file the simulated camera wrote is in raw/ or raw/unmatched/, and the
    manifest's frames all match their sha256."""
    written = len(rig.sim.simulator.frames)
    kept = len(list((scan_dir / "raw").glob("*.dng"))) + len(list((scan_dir / "raw").glob("unmatched/*.dng")))
    assert kept == written
    assert rig.camera.pending() == []
    assert ScanDirectory(scan_dir).verify() == []
    captured = [e for e in _journal(scan_dir) if e["step"] == "captured"]
    assert len({e["file"] for e in captured}) == len(ScanDirectory(scan_dir).manifest.frames)


def test_serial_bit_errors_are_absorbed_by_retries(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(faults="biterr=5e-3")
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    assert rig.device.stats["retries"] > 0                   # errors happened and were retried
    _nothing_lost(rig, tmp_path / "s")


def test_device_reset_mid_scan_reconnects_and_completes(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(faults="reset_at_shot=10")
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    assert rig.sim.simulator.boots == [1, 2]
    resets = [e for e in _journal(tmp_path / "s") if e["step"] == "device_reset"]
    assert len(resets) == 1 and resets[0]["new_boot"] == resets[0]["old_boot"] + 1
    # frames of the first run are kept; later runs take only what is missing (the
    # light that was interrupted, with its missing exposures, then the rest)
    runs = {f.run for f in scan.manifest.frames}
    assert 0 in runs and len(runs) >= 2
    # the simulated camera waits for the host to take each file before the next shot
    # (facette.sim back-pressure), so all 10 shots before the reset are matched
    first = [f for f in scan.manifest.frames if f.run == 0]
    assert len(first) == 10 and all(f.light <= 3 for f in first)
    _nothing_lost(rig, tmp_path / "s")


def test_missed_flash_sync_is_retried_by_the_device(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(faults="miss_sync_shots=5")
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    assert rig.device.read("retries_used") == 1
    no_sync = [e for e in _journal(tmp_path / "s") if e["step"] == "no_sync"]
    assert len(no_sync) == 1
    retried = [f for f in scan.manifest.frames if f.retry]
    assert [(f.light, f.exposure) for f in retried] == [(no_sync[0]["light"], no_sync[0]["exposure"])]
    _nothing_lost(rig, tmp_path / "s")


def test_open_led_stops_the_scan_with_a_clear_message_then_resumes(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(faults="open_led=3")
    with pytest.raises(ScanError, match=r"LED_OPEN.*run the same scan again to resume"):
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    sd = ScanDirectory(tmp_path / "s")
    assert len(sd.manifest.frames) == 3 * len(SHORT)       # lights 0..2 complete
    steps = [e["step"] for e in _journal(tmp_path / "s")]
    assert steps[-1] == "interrupted" and "stopped" in steps[-4:]
    assert "LED_OPEN" in _journal(tmp_path / "s")[-1]["error"]
    _nothing_lost(rig, tmp_path / "s")
    with pytest.raises(ScanError, match="latched faults"):   # not cleared: refused, nothing shot
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    rig.sim.simulator.led_fault(3, "ok")                      # repaired
    rig.clear_faults()
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    _nothing_lost(rig, tmp_path / "s")


def test_over_temperature_stops_the_scan_then_resumes_when_cool(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(faults="overtemp_at_shot=8")
    with pytest.raises(ScanError, match="OVERTEMP"):
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert rig.faults()["latched"] == ["OVERTEMP"]
    n = len(ScanDirectory(tmp_path / "s").manifest.frames)
    assert 8 <= n < N
    _nothing_lost(rig, tmp_path / "s")
    rig.sim.set_temperature(25.0)
    rig.clear_faults()
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    _nothing_lost(rig, tmp_path / "s")


def test_power_cut_mid_scan_reopens_the_port_and_completes(sim_rig_factory, tmp_path):
    # the device process stops and starts again (flash kept): a new pseudo-terminal appears
    # behind the same port name, as a USB rig re-enumerates after a power cut
    rig = sim_rig_factory(faults="power_cut_at_shot=10")
    old_pid = rig.sim.device.proc.pid
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == N
    assert rig.sim.power_cycles == 1 and rig.device.stats.get("reopens", 0) >= 1
    assert rig.sim.simulator.boots == [1, 2]                  # the boot count survived in flash
    resets = [e for e in _journal(tmp_path / "s") if e["step"] == "device_reset"]
    assert len(resets) == 1
    assert rig.sim.device.proc.pid != old_pid                 # a new process serves the port
    _nothing_lost(rig, tmp_path / "s")
