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
