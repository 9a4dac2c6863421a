"""The calibration wizard on the simulated rig: the whole unattended run, the checks
that stop it, the device's calibration store, and the drift report."""
import json

import numpy as np
import pytest

from facette.calib import load
from facette.wizard import RigStation, Wizard, WizardError, angle_deg
from facette.cli.main import main
from facette.device.client import DeviceClient
from facette.scan.rig import Rig
from facette.sim.device_process import SimulatedDevice


def _wizard(rig, tmp_path, steps=None, **kw):
    lines = []
    station = RigStation(rig, tmp_path / "captures", attended=False, out=lines.append,
                         sim_faults=kw.pop("sim_faults", None))
    return Wizard(station, out=lines.append, steps=steps, **kw), lines


def test_unattended_run_recovers_perturbed_leds_and_equalises_them(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(direction_error_deg=2.0, intensity_error=0.15, seed=4)
    wiz, lines = _wizard(rig, tmp_path)
    prof, path = wiz.run(tmp_path / "profile")
    leds = rig.sim.leds
    # directions from the chrome sphere (thesis rig, 20 px sphere): a tenth of a degree
    assert angle_deg(prof.lights.directions, leds.directions).max() < 0.25
    truth = leds.intensities / leds.intensities.mean(axis=0)
    assert np.abs(prof.lights.intensities / truth - 1).max() < 0.005
    # sensor from the photon transfer curve
    s, t = prof.sensor, rig.sim.sensor
    assert s["gain_e_per_dn"] == pytest.approx(t.gain_e_per_dn, rel=0.05)
    assert s["read_noise_e"] == pytest.approx(t.read_noise_e, rel=0.15)
    assert abs(s["black_level_dn"] - t.black_level_dn) <= 1
    assert prof.pixel_pitch_mm == pytest.approx(rig.sim.scene.pixel_pitch_mm, rel=0.005)
    # gains: in the device's store, kept across another reboot, and they equalise the LEDs
    assert wiz.figures["gains"]["spread_before"] > 0.2 and wiz.figures["gains"]["spread_after"] < 0.01
    wiz.st.reboot()
    np.testing.assert_allclose(rig.gains()[:12], prof.led_gains, atol=1e-4)
    # the profile: checksummed, with its flat field; the transcript says what was found
    again = load(path.parent)
    assert again.sha256 == prof.sha256 and again.flat_field.shape == (48, 64, 3)
    assert again.image_size_px == (64, 48) and again.binning == 2   # the size it was measured at
    np.testing.assert_allclose(again.flat_field.mean(axis=(0, 1)), 1, rtol=1e-4)
    text = "\n".join(lines)
    for needle in ("[1/5] noise", "sensor: gain", "from nominal", "matte vs mirror", "flat field",
                   "kept across a reboot", "verified on a second Spectralon capture", "written to"):
        assert needle in text


def test_missing_or_overexposed_targets_stop_with_what_to_do(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    wiz, _ = _wizard(rig, tmp_path, steps=["spectralon"], sim_faults={"spectralon": "missing"})
    with pytest.raises(WizardError, match=r"spectralon: not found .* Place the target"):
        wiz.run(tmp_path / "p1")
    wiz, _ = _wizard(rig, tmp_path, steps=["mirror"], sim_faults={"mirror_sphere": "overexposed"})
    with pytest.raises(WizardError, match=r"mirror sphere: overexposed .* Shorten the exposures"):
        wiz.run(tmp_path / "p2")
    wiz, _ = _wizard(rig, tmp_path, steps=["spectralon"], exposures=[8_000_000])
    with pytest.raises(WizardError, match=r"overexposed — 100 % .*\(8 s at 500 mA\)"):
        wiz.run(tmp_path / "p3")
    assert not (tmp_path / "p1").exists() and not (tmp_path / "p2").exists()


def test_cli_unattended_keeps_the_previous_profile_and_checks_drift(tmp_path, capsys):
    out = tmp_path / "prof"
    # the rig's button starts each capture (the simulated rig presses it)
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "--button", "-o", str(out), "--only", "mirror,spectralon"]) == 0
    assert "press the rig's button" in capsys.readouterr().out
    first = json.loads((out / "profile.json").read_text())["id"]
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "-o", str(out), "--only", "spectralon",
                 "--base", str(out)]) == 0
    assert (out / f"profile-{first}.json").is_file()
    # an RTI .lp file (written beside each profile) as the base: its directions are kept
    lp = out / f"lights-{first}.lp"
    assert lp.is_file()
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "-o", str(tmp_path / "from-lp"), "--only", "spectralon",
                 "--base", str(lp)]) == 0
    np.testing.assert_allclose(load(tmp_path / "from-lp").lights.directions,
                               load(out / f"profile-{first}.json").lights.directions, atol=1e-8)
    capsys.readouterr()
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "--check", str(out)]) == 0
    assert "within tolerance" in capsys.readouterr().out
    # another rig (other LED errors) against this profile: drift, exit status 1
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "--check", str(out), "--sim-seed", "7",
                 "--sim-direction-error", "2", "--sim-intensity-error", "0.15"]) == 1
    assert "DRIFTED" in capsys.readouterr().out
    assert main(["calibrate", "--rig", "sim", "--yes", "--sim-raw-size", "128x96", "-o", str(tmp_path / "x"), "--only", "spectralon",
                 "--sim-target-fault", "spectralon=missing"]) == 2
    text = capsys.readouterr().out
    assert "not found" in text and "nothing was written" in text
    assert not (tmp_path / "x").exists()


def test_near_leds_positions_and_parallax(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(near=True, direction_error_deg=2.0, intensity_error=0.15, seed=2)
    wiz, lines = _wizard(rig, tmp_path, steps=["mirror", "positions", "spectralon"], led_distance_mm=1500)
    prof, _ = wiz.run(tmp_path / "profile")
    P = rig.sim.leds.positions_mm
    assert prof.lights.positions_mm is not None
    # two placements 40 mm apart, LEDs 1.5 m away: the rays cross at a shallow angle
    err = np.linalg.norm(prof.lights.positions_mm - P, axis=1)
    assert np.median(err) < 0.3 * 1500
    assert angle_deg(prof.lights.directions, P / np.linalg.norm(P, axis=1, keepdims=True)).max() < 0.5
    truth = rig.sim.leds.intensities / rig.sim.leds.intensities.mean(axis=0)
    assert np.abs(prof.lights.intensities / truth - 1).max() < 0.02
    # the drift check of a near-light profile compares directions seen from the same point
    check, lines = _wizard(rig, tmp_path, base=prof)
    ok, report = check.check(prof)
    assert ok and max(report["direction_deg"]) < 0.3, lines


def test_gains_survive_a_power_cycle_of_the_simulated_device(sim_rig_factory, tmp_path):
    """The wizard's gains are in the device's flash: a new device process on the same
    flash (power off and on) reads them back."""
    rig = sim_rig_factory(intensity_error=0.15, seed=5, workdir=tmp_path / "rig1")
    wiz, _ = _wizard(rig, tmp_path, steps=["spectralon", "gains"])
    prof, _ = wiz.run(tmp_path / "profile")
    rig.close()
    dev = SimulatedDevice(speed=2000.0, side=False, state_dir=tmp_path / "rig1" / "device" / "flash",
                          workdir=tmp_path / "power-cycled")
    try:
        r = Rig(DeviceClient(dev.port))
        np.testing.assert_allclose(r.gains()[:12], prof.led_gains, atol=1e-4)
        assert r.device.read("boot_count") >= 1
        r.device.close()
    finally:
        dev.close()
