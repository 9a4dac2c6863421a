"""run_scan (scan/acquire.py) on the simulated rig (the real firmware core over a pty): a plan is
checked before the directory exists, one writer at a time, damaged frames taken again, a
refused button press said in words, a silent link reported while waiting."""
import json
import os
import signal
import threading

import pytest

import facette
from facette.errors import BadInputError
from facette.scan import (Rig, ScanDirectory, ScanDirectoryError, ScanError, ScanOptions, default_plan,
                          run_scan, sha256_file)
from facette.scan.directory import ScanDirectoryBusy

SHORT = [(200_000, 0), (20_000, 0)]


@pytest.fixture(scope="module")
def rig():
    r = facette.connect("sim", raw_shape=(24, 32), speed=2000)
    yield r
    r.close()


class _RigWithoutSimulator(Rig):
    """The simulated device and its camera seen only through the `Rig` interface, as a real rig
    is: no truth, no sensor, no pixel pitch, a button a person presses, and no simulator to look
    behind it."""

    def __init__(self, sim_rig):
        super().__init__(sim_rig.device, camera=sim_rig.camera)

    @property
    def sim(self):
        raise AssertionError("the acquisition looked behind the rig interface (rig.sim)")


def intact(d):
    m = ScanDirectory(d).manifest
    assert all(sha256_file(d / f.file) == f.sha256 for f in m.frames)
    return len(m.frames)


@pytest.mark.parametrize("kw, words", [
    (dict(lights=[0, 0, 1]), "light 0 is listed twice"),
    (dict(light_current_mA=-100), "currents >= 1 mA"),
    (dict(light_current_mA=1200), "max_current_mA = 1000 mA"),
    (dict(lights=[13]), "LED channel 13 is not in profile"),
    (dict(exposures=[(25_000_000, 0)], mode="led"), "max_pulse_us = 20 s"),
    (dict(exposures=[0]), "exposure times are >= 1 µs"),
    (dict(exposures=[1000] * 17), "1..16 exposures"),
])
def test_a_refused_plan_leaves_no_directory(rig, tmp_path, kw, words):
    kw = {"exposures": SHORT, "lights": [0, 1], **kw}
    with pytest.raises(BadInputError, match=None) as exc:
        rig.scan(tmp_path / "s", profile=_profile(), progress=False, **kw)
    assert words in str(exc.value)
    assert not (tmp_path / "s").exists()


def _profile():
    from facette.sim.device_process import REPO_ROOT

    return REPO_ROOT / "calibration" / "profiles" / "sim-default"


def test_default_plan_checks():
    assert default_plan(3).lights == [0, 1, 2]
    with pytest.raises(BadInputError, match="2 light currents for 3 lights"):
        default_plan(3, light_current_mA=[500, 500])


def test_one_writer_at_a_time(rig, tmp_path):
    holder = ScanDirectory(tmp_path / "s")
    holder.lock()                                   # another writer (its own open file)
    try:
        with pytest.raises(ScanDirectoryBusy, match=f"pid {os.getpid()}"):
            rig.scan(tmp_path / "s", lights=[0], exposures=SHORT, progress=False)
    finally:
        holder.unlock()
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [".facette.lock"]
    rig.scan(tmp_path / "s", lights=[0], exposures=SHORT, progress=False)   # the lock was released
    assert intact(tmp_path / "s") == 2


def test_an_adaptive_scan_into_a_busy_directory_meters_nothing(rig, tmp_path):
    d = tmp_path / "s"
    holder = ScanDirectory(d)
    holder.lock()                     # a scan is writing here (e.g. still metering)
    meter = d / "meter"
    meter.mkdir()
    (meter / "frame.dng").write_bytes(b"the first scan's metering frame")
    before = sorted((p.name, p.stat().st_mtime_ns, p.read_bytes()) for p in meter.iterdir())
    try:
        with pytest.raises(ScanDirectoryBusy, match=f"pid {os.getpid()}"):
            rig.scan(d, lights=[0, 1], exposures="adaptive", progress=False)
    finally:
        holder.unlock()
    assert sorted((p.name, p.stat().st_mtime_ns, p.read_bytes()) for p in meter.iterdir()) == before
    assert sorted(p.name for p in d.iterdir()) == [".facette.lock", "meter"]


def test_a_damaged_frame_is_set_aside_and_taken_again(rig, tmp_path):
    d = tmp_path / "s"
    rig.scan(d, lights=[0, 1], exposures=SHORT, progress=False)
    victim = d / "raw" / "L01_E00.dng"
    victim.write_bytes(victim.read_bytes()[:-10] + b"0123456789")
    damaged = victim.read_bytes()
    sd = rig.scan(d, lights=[0, 1], exposures=SHORT, progress=False)
    assert sd.notes == ["raw/L01_E00.dng: sha256 differs from scan.json (the file changed after capture); "
                        "kept as raw/damaged/L01_E00.dng and taken again"]
    assert intact(d) == 4 and (d / "raw" / "damaged" / "L01_E00.dng").read_bytes() == damaged
    assert any(e["step"] == "damaged" for e in sd.read_journal())


def test_another_plan_in_the_directory_says_what_differs(rig, tmp_path):
    d = tmp_path / "s"
    rig.scan(d, lights=[0], exposures=SHORT, progress=False)
    with pytest.raises(ScanDirectoryError) as exc:
        rig.scan(d, lights=[0, 1], exposures=SHORT, progress=False)
    assert "lights: this directory has [0], the command asks for [0, 1]" in exc.value.message
    assert intact(d) == 2


def test_a_refused_button_press_is_said_in_words(rig, tmp_path):
    """The device refuses to arm (a configuration changed behind the host's back): a person's
    press on the rig's button must not leave the host waiting forever."""
    from facette.scan._device_run import DeviceRuns

    sd = ScanDirectory(tmp_path / "s")
    sd.path.mkdir()
    acq = DeviceRuns(rig, sd, default_plan(1, SHORT), ScanOptions(frame_timeout_s=5.0))
    rig.configure(SHORT, lights=[0])
    rig.device.write_array("light_current_mA", [1200])               # above max_current_mA
    press = threading.Timer(0.3, rig.sim.press_button, kwargs={"timeout_s": 0.5})
    press.start()
    try:
        with pytest.raises(ScanError, match=r"refused to start the scan: invalid scan configuration "
                                             r"\(last_error -7\)"):
            acq.wait_button({"RUNNING", "PAUSED", "FAULT"})
    finally:
        press.join()
        rig.device.write_array("light_current_mA", [500])


def test_a_silent_link_is_reported_while_waiting_then_stops_the_scan(tmp_path, capsys):
    r = facette.connect("sim", raw_shape=(24, 32), speed=20)
    stopped = []

    def freeze(record):
        if not stopped:
            stopped.append(record)
            os.kill(r.sim.device.proc.pid, signal.SIGSTOP)
    try:
        with pytest.raises(ScanError) as exc:
            r.scan(tmp_path / "s", lights=[0, 1], exposures=SHORT, progress=False, on_frame=freeze,
                   link_timeout_s=4)
    finally:
        os.kill(r.sim.device.proc.pid, signal.SIGCONT)
        r.close()
    assert "lost the link to the device" in exc.value.message and "1/4 frames kept" in exc.value.message
    assert "check the cable and the rig's power" in exc.value.hint
    err = capsys.readouterr().err
    assert "no answer from the device" in err and "retrying until 4 s" in err
    assert intact(tmp_path / "s") == 1


def test_acquisition_knows_the_rig_only_through_its_interface(rig, tmp_path):
    """The same device and camera scanned as a real rig (no simulator behind the interface)
    and as the simulated one: only what the interface answers differs."""
    real = _RigWithoutSimulator(rig)
    assert real.sensor is None and real.pixel_pitch_mm is None and not real.can_press_button
    assert real.save_truth(tmp_path, [0]) is None and not (tmp_path / "truth.npz").exists()
    scan = run_scan(real, tmp_path / "real", exposures=SHORT, lights=[0, 1], progress=False)
    m = scan.manifest
    assert m.complete and len(m.frames) == 4 and m.truth is None and m.pixel_pitch_mm is None
    assert not (tmp_path / "real" / "truth.npz").exists() and intact(tmp_path / "real") == 4
    options = ScanOptions(exposures=SHORT, lights=[0, 1], progress=False)
    scan = run_scan(rig, tmp_path / "sim", options=options)
    m = scan.manifest
    assert m.truth == "truth.npz" and (tmp_path / "sim" / "truth.npz").is_file()
    assert m.pixel_pitch_mm == rig.sim.scene.pixel_pitch_mm == rig.pixel_pitch_mm
    assert rig.sensor is rig.sim.sensor and rig.can_press_button


def test_a_host_press_of_a_real_rigs_button_is_refused_before_anything_is_touched(rig, tmp_path):
    with pytest.raises(BadInputError) as exc:
        run_scan(_RigWithoutSimulator(rig), tmp_path / "s", exposures=SHORT, lights=[0], button="press",
                 progress=False)
    assert "pressed by a person" in exc.value.message and "button='wait'" in exc.value.hint
    assert not (tmp_path / "s").exists()
    with pytest.raises(TypeError, match="hold"):          # settings are ScanOptions' fields
        run_scan(rig, tmp_path / "s", exposures=SHORT, hold=True)
    assert not (tmp_path / "s").exists()


def test_camera_files_without_exposure_time_are_said_once(rig, tmp_path, monkeypatch):
    import facette.scan._frames as frames
    monkeypatch.setattr(frames, "read_exposure_metadata", lambda path: (None, None, {}))   # a Blackmagic DNG
    sd = rig.scan(tmp_path / "s", lights=[0, 1], exposures=SHORT, progress=False)
    assert sd.notes == [frames.NO_EXPOSURE_NOTE] and intact(tmp_path / "s") == 4
