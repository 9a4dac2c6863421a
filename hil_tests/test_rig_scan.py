"""Full scans on the simulated rig: the scan directory, abort, pause, resume."""
import json

import numpy as np
import pytest

from facette.camera.raw import read_exposure_metadata, read_raw
from facette.scan import (THESIS_BRACKET_US, ScanAborted, ScanDirectory, ScanDirectoryError, ScanError,
                          sha256_file)

SHORT = [(200_000, 0), (20_000, 0), (2_000, 0)]


def _nothing_lost(rig, scan_dir):
    """Every file the simulated camera wrote is in raw/ or raw/unmatched/ (none left behind)."""
    written = len(rig.sim.simulator.frames)
    kept = len(list((scan_dir / "raw").glob("*.dng"))) + len(list((scan_dir / "raw").glob("unmatched/*.dng")))
    assert kept == written
    assert rig.camera.pending() == []


def test_full_default_scan_writes_the_contract_directory(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    scan = rig.scan(tmp_path / "plaque", progress=False)
    m = json.loads((tmp_path / "plaque" / "scan.json").read_text())
    assert m["schema"] == 2 and m["complete"] and m["truth"] == "truth.npz"   # docs/scan-format.md
    assert len(m["lights"]) == 12 and len(m["exposures"]) == len(THESIS_BRACKET_US)
    assert [e["time_us"] for e in m["exposures"]] == list(THESIS_BRACKET_US)
    assert len(m["frames"]) == 12 * 7 and scan.verify() == []
    for light in m["lights"]:
        assert np.linalg.norm(light["direction"]) == pytest.approx(1.0)
    f = m["frames"][0]
    assert set(f) >= {"file", "light", "exposure", "time_us", "current_set_mA", "current_meas_mA",
                      "start_us", "sync", "sha256"}
    assert f["sha256"] == sha256_file(tmp_path / "plaque" / f["file"])
    # rig time: the device's own timeline (exposures plus settle and gap per frame)
    settle, gap = rig.device.read("settle_us"), rig.device.read("gap_us")
    lower = 12 * sum(THESIS_BRACKET_US) * 1e-6
    assert lower < m["rig_time_s"] <= lower + 84 * (settle + gap) * 1e-6 + 1.0
    # DNG metadata: exposure time and ISO as configured
    for fr in m["frames"][:7]:
        t, iso, _ = read_exposure_metadata(tmp_path / "plaque" / fr["file"])
        assert t == pytest.approx(fr["time_us"] * 1e-6, rel=1e-5) and iso == 400
    truth = np.load(tmp_path / "plaque" / "truth.npz")
    assert truth["normals"].shape == (48, 64, 3) and truth["mask"].dtype == bool
    assert truth["light_dirs"].shape == (12, 3) and truth["light_intensity"].shape == (12, 3)
    assert json.loads(str(truth["brdf"]))["model"] == "cook_torrance"
    journal = [json.loads(line) for line in (tmp_path / "plaque" / "journal.jsonl").read_text().splitlines()]
    assert journal[0]["step"] == "begin" and journal[-1]["step"] == "done"
    assert sum(e["step"] == "captured" for e in journal) == 84
    _nothing_lost(rig, tmp_path / "plaque")


def test_pixels_follow_the_sensor_model_of_the_rendered_scene(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    scan = rig.scan(tmp_path / "s", lights=[2], exposures=[(1_000_000, 0)], progress=False)
    frame = read_raw(tmp_path / "s" / scan.manifest.frames[0].file)
    sensor = rig.sim.sensor
    expect_e = rig.sim.radiance[2] * 500 * 1_000_000                 # e- = e-/(mA·µs) × mA × µs
    expect_dn = (expect_e + sensor.dark_current_e_per_s * 1.0) / sensor.gain_e_per_dn
    ok = expect_dn[..., 1] * sensor.gain_e_per_dn < 0.8 * sensor.full_well_e
    measured = np.asarray(frame.image)[..., 1]                         # green: two photosites averaged
    resid = (measured - expect_dn[..., 1])[ok]
    sigma = np.sqrt(sensor.variance_dn2(expect_dn[..., 1][ok]) / 2)
    assert abs(np.mean(resid / sigma)) < 0.2                           # unbiased
    assert 0.8 < np.std(resid / sigma) < 1.25                          # noise as eq 2.13 says


def test_abort_then_resume_keeps_every_frame(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    taken = []

    def abort_after_five(record):
        taken.append(record)
        if len(taken) == 5:
            rig.abort()

    with pytest.raises(ScanAborted, match="run the same scan again to resume"):
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False, on_frame=abort_after_five)
    sd = ScanDirectory(tmp_path / "s")
    assert 5 <= len(sd.manifest.frames) < 36 and sd.verify() == []
    before = {f.file: f.sha256 for f in sd.manifest.frames}
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert len(scan.manifest.frames) == 36 and scan.verify() == []
    after = {f.file: f.sha256 for f in scan.manifest.frames}
    assert all(after[k] == v for k, v in before.items())              # earlier frames untouched
    _nothing_lost(rig, tmp_path / "s")


def test_resume_in_a_new_session_after_the_host_died(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()

    def die(record):
        if record.light == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False, on_frame=die)
    n_before = len(ScanDirectory(tmp_path / "s").manifest.frames)
    rig.close()
    rig2 = sim_rig_factory()                                          # a new rig and host session
    scan = rig2.scan(tmp_path / "s", exposures=SHORT, progress=False)
    assert n_before == 13 and len(scan.manifest.frames) == 36 and scan.verify() == []
    # the new run only took what was missing
    assert len(rig2.sim.simulator.frames) == 36 - n_before


def test_pause_and_resume_mid_scan(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    states = []

    def pause_once(record):
        if record.light == 1 and record.exposure == 0:
            rig.pause()
            states.append(rig.wait_state({"PAUSED"}, timeout_s=10))
            done = rig.progress()[0]
            states.append(rig.progress()[0] == done)
            rig.resume()

    scan = rig.scan(tmp_path / "s", lights=[0, 1, 2], exposures=SHORT, progress=False, on_frame=pause_once)
    assert states == ["PAUSED", True]
    assert len(scan.manifest.frames) == 9 and scan.verify() == []


def test_button_starts_the_scan(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    scan = rig.scan(tmp_path / "s", lights=[0, 1], exposures=SHORT[:1], button="press", progress=False)
    assert len(scan.manifest.frames) == 2
    starts = [json.loads(x) for x in (tmp_path / "s" / "journal.jsonl").read_text().splitlines()
              if '"start"' in x]
    assert starts[0]["button"] == "press"


def test_a_directory_holding_another_scan_is_refused(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    rig.scan(tmp_path / "s", lights=[0], exposures=SHORT[:1], progress=False)
    with pytest.raises(ScanDirectoryError, match="holds another scan"):
        rig.scan(tmp_path / "s", lights=[0, 1], exposures=SHORT[:1], progress=False)
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(ScanDirectoryError, match="not empty"):
        rig.scan(tmp_path / "other", lights=[0], exposures=SHORT[:1], progress=False)


def test_led_defined_exposures_bracket_by_duration_and_current(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    exposures = [(5000, 1000), (5000, 200), (500, 200)]          # (pulse µs, mA)
    scan = rig.scan(tmp_path / "s", lights=[0, 7], exposures=exposures, mode="led", progress=False)
    frames = scan.manifest.frames
    assert [e.current_mA for e in scan.manifest.exposures] == [1000, 200, 200]
    for rec, sim_frame in zip(frames, rig.sim.simulator.frames):
        t_us, ma = exposures[rec.exposure]
        assert rec.current_set_mA == ma and rec.current_meas_mA == ma
        charge = np.asarray(sim_frame["charge_mA_us"])
        assert charge[[0, 7][rec.light]] == pytest.approx(t_us * ma)    # the pulse, nothing else
        assert charge.sum() == pytest.approx(t_us * ma)
        assert sim_frame["window_us"] > t_us                                # the shutter window is longer


def test_design_script_scan_then_process_matches_the_truth(sim_rig_factory, tmp_path):
    """docs/conventions.md, "Scripting": rig.scan(...) then facette.process(scan, ...), compared
    with truth.npz."""
    import facette
    from facette.calib import Lights, Profile

    rig = sim_rig_factory()
    leds = rig.sim.leds        # a perfect calibration: the simulator's own LEDs
    profile = Profile(rig="sim", id="sim-truth", lights=Lights(leds.directions, leds.intensities),
                      pixel_pitch_mm=rig.sim.scene.pixel_pitch_mm)
    scan = rig.scan(tmp_path / "plaque", profile=profile, progress=False)
    assert scan.manifest.profile["id"] == "sim-truth"
    result = facette.process(scan, outputs=["normals"])
    truth = np.load(tmp_path / "plaque" / "truth.npz")
    n, tn = np.asarray(result.normals), truth["normals"]
    ang = np.degrees(np.arccos(np.clip(np.sum(n * tn, axis=-1), -1, 1)))
    h, w = tn.shape[:2]
    sphere = truth["mask"] & (np.arange(w)[None, :] > 0.6 * w)
    # the sphere is smooth, mostly diffuse and lit by every LED: normals within 1°; the
    # plaque's relief has cast shadows and highlights (hierarchical elimination): within 3°
    assert sphere.sum() > 100 and np.nanmedian(ang[sphere]) < 1.0
    plaque = truth["mask"] & (np.arange(w)[None, :] < 0.5 * w)
    assert plaque.sum() > 300 and np.nanmedian(ang[plaque]) < 3.0


def test_wait_button_scans_only_once_the_rig_button_is_pressed(sim_rig_factory, tmp_path):
    import threading
    import time

    rig = sim_rig_factory()
    out = {}

    def scan():
        out["scan"] = rig.scan(tmp_path / "s", lights=[0], exposures=SHORT[:1], button="wait", progress=False)

    worker = threading.Thread(target=scan)
    worker.start()
    journal = tmp_path / "s" / "journal.jsonl"
    deadline = time.monotonic() + 30
    while not (journal.exists() and '"step": "start"' in journal.read_text()):
        assert time.monotonic() < deadline, "the host never got ready to start"
        time.sleep(0.005)                                   # poll the journal, bounded
    assert worker.is_alive() and rig.sim.simulator.shots == 0   # nothing is taken before the press
    rig.sim.press_button()
    worker.join(timeout=60)
    assert not worker.is_alive() and len(out["scan"].manifest.frames) == 1


def test_a_stray_camera_image_is_never_filed_under_a_frame_name(sim_rig_factory, tmp_path):
    """Someone presses the camera's own release mid-scan: that image has no frame record."""
    from facette.sim.dng import write_dng

    rig = sim_rig_factory()

    def stray(record):
        if (record.light, record.exposure) == (1, 0):
            mosaic = np.full((96, 128), 600, np.uint16)
            write_dng(rig.camera.folder / "DSC_9999.dng", mosaic, 512, 16383, 1 / 250, 400)

    # (the device may already have taken the next frame: the stray lands on exposure 1 or 2)
    with pytest.raises(ScanError, match="exposed 0.004 s but the rig took light 1 exposure [12]"):
        rig.scan(tmp_path / "s", lights=[0, 1, 2], exposures=SHORT, progress=False, on_frame=stray)
    sd = ScanDirectory(tmp_path / "s")
    assert (tmp_path / "s" / "raw" / "unmatched" / "DSC_9999.dng").is_file()
    assert sd.verify() == [] and len(sd.manifest.frames) in (4, 5)
    scan = rig.scan(tmp_path / "s", lights=[0, 1, 2], exposures=SHORT, progress=False)   # resume
    assert len(scan.manifest.frames) == 9 and scan.verify() == []
    raw = tmp_path / "s" / "raw"
    kept = len(list(raw.glob("*.dng"))) + len(list(raw.glob("unmatched/*.dng")))
    assert kept == len(rig.sim.simulator.frames) + 1          # every camera image plus the stray
