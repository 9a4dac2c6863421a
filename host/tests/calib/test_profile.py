import json

import numpy as np
import pytest

from facette.calib import Lights, Profile, ProfileError, load, nominal_light_directions, save


def _profile(**kw):
    d = nominal_light_directions()
    return Profile(rig="test", lights=Lights(d, np.ones((12, 3))), **kw)


def test_nominal_directions_match_the_thesis_rings():
    d = nominal_light_directions()
    theta = np.rad2deg(np.arccos(d[:, 2]))
    phi = np.rad2deg(np.arctan2(d[:, 1], d[:, 0])) % 360
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1)
    np.testing.assert_allclose(theta[::2], 30)
    np.testing.assert_allclose(theta[1::2], 15)
    np.testing.assert_allclose(phi, np.arange(12) * 30, atol=1e-9)


def test_round_trip_with_flat_field_and_previous_kept(tmp_path):
    ff = np.random.default_rng(0).uniform(0.9, 1.1, (4, 5, 3)).astype(np.float32)
    p = _profile(flat_field=ff, pixel_pitch_mm=0.0667,
                 sensor={"gain_e_per_dn": 1.5, "read_noise_e": 3.0, "dark_current_e_per_s": 0.1,
                         "black_level_dn": 600, "white_level_dn": 16383})
    save(p, tmp_path)
    q = load(tmp_path)
    np.testing.assert_allclose(q.lights.directions, p.lights.directions)
    np.testing.assert_array_equal(q.flat_field, ff)
    assert q.sensor["gain_e_per_dn"] == 1.5 and q.sha256 == p.sha256
    save(_profile(id="second"), tmp_path)
    assert load(tmp_path).id == "second"
    assert len(list(tmp_path.glob("profile-*.json"))) == 1  # the first one is kept


def test_tampered_or_broken_profiles_are_refused(tmp_path):
    path = save(_profile(), tmp_path)
    data = json.loads(path.read_text())
    data["lights"][0]["intensity"] = [2, 2, 2]
    path.write_text(json.dumps(data))
    with pytest.raises(ProfileError, match="checksum"):
        load(tmp_path)
    path.write_text("{not json")
    with pytest.raises(ProfileError, match="not valid JSON"):
        load(tmp_path)
    with pytest.raises(ProfileError, match="no calibration profile"):
        load(tmp_path / "nowhere")


def test_lights_are_validated():
    with pytest.raises(ProfileError, match="unit vectors"):
        Lights(np.ones((3, 3)), np.ones((3, 3)))
    with pytest.raises(ProfileError, match="positive"):
        Lights(nominal_light_directions(), np.zeros((12, 3)))
    with pytest.raises(ProfileError, match="sensor"):
        _profile(sensor={"gain_e_per_dn": 1})


def test_radiometric_scale_round_trip_and_validation(tmp_path):
    save(_profile(radiometric_scale=[2.0, 3.0, 4.0]), tmp_path)
    assert load(tmp_path).radiometric_scale == [2.0, 3.0, 4.0]
    save(_profile(), tmp_path)
    assert load(tmp_path).radiometric_scale is None   # relative-only profiles stay readable
    with pytest.raises(ProfileError, match="radiometric_scale"):
        _profile(radiometric_scale=[1.0, -1.0, 1.0])


def _smooth_flat(w, h):
    """A smooth flat field sampled at pixel centres of a (w, h) grid of one 120-unit-wide field."""
    x = (np.arange(w) + 0.5) / w - 0.5
    y = (np.arange(h) + 0.5 - h / 2) / w
    f = 1 + 0.05 * x[None, :] + 0.03 * y[:, None] ** 2 * 4
    f = np.repeat(f[..., None], 3, axis=-1).astype(np.float32)
    return f / f.mean()


def test_another_binning_scales_the_pitch_and_resamples_the_flat_field(tmp_path):
    p = _profile(flat_field=_smooth_flat(64, 48), pixel_pitch_mm=1.875, binning=2)
    assert p.measured_size() == (64, 48)
    save(p, tmp_path)
    q = load(tmp_path)
    assert q.image_size_px == (64, 48) and q.binning == 2
    same = q.at_size((64, 48))
    assert same.pixel_pitch_mm == 1.875 and same.flat_field is q.flat_field
    # 4x finer, and the camera's 3:2 frame (fewer rows of the same width): pitch /4 and /33.5,
    # the flat field follows the same smooth function on the new grid.
    for w, h in ((256, 192), (2144, 1424)):
        at = q.at_size((w, h))
        assert at.pixel_pitch_mm == pytest.approx(1.875 * 64 / w)
        assert at.flat_field.shape == (h, w, 3)
        ref = _smooth_flat(w, h)
        inner = (slice(h // 16, -h // 16), slice(w // 16, -w // 16))
        np.testing.assert_allclose(at.flat_field[inner], ref[inner] * at.flat_field[inner].mean()
                                   / ref[inner].mean(), rtol=2e-3)
        assert "64×48" in at.note and f"{w}×{h}" in at.note


def test_a_size_that_is_not_the_same_sensor_is_a_clear_error():
    from facette.calib import ResolutionError

    p = _profile(flat_field=_smooth_flat(64, 48), pixel_pitch_mm=1.875)
    with pytest.raises(ResolutionError, match=r"64×48 px.*128×128 px"):
        p.at_size((128, 128))          # a taller field than the one calibrated
    with pytest.raises(ProfileError, match="flat field is 64×48 px but the profile says"):
        _profile(flat_field=_smooth_flat(64, 48), image_size_px=(32, 24))
    # no size known at all: the values as they are, and a note saying so
    at = _profile(pixel_pitch_mm=2.0).at_size((640, 480))
    assert at.pixel_pitch_mm == 2.0 and "records no image size" in at.note


def test_the_committed_sim_profile_serves_every_simulated_size():
    from facette.sim.device_process import REPO_ROOT

    p = load(REPO_ROOT / "calibration" / "profiles" / "sim-default")
    assert p.measured_size() == (256, 192)       # measured at 512x384 RAW
    for raw_w, raw_h in ((128, 96), (1072, 712), (4288, 2848)):
        w = raw_w // 2
        # the simulator keeps a 120 mm wide field: the calibrated pitch follows it (0.2 %)
        assert p.at_size((w, raw_h // 2)).pixel_pitch_mm == pytest.approx(120 / w, rel=2e-3)
