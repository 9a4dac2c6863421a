"""Sensor model: noise statistics follow thesis eq 2.12–2.13."""
import numpy as np
import pytest

from facette.camera.sensor import SensorModel, bayer_mosaic_rggb


def _stats(sensor, e_per_s, t_s, n=400_000, seed=1):
    h = n // 4
    irr = np.full((h, 1, 3), e_per_s, dtype=np.float64)
    raw = sensor.expose(irr, t_s, np.random.default_rng(seed)).astype(np.float64)
    return raw.mean(), raw.var(ddof=1), raw.size


@pytest.mark.parametrize("e_per_s,t_s", [(0.0, 1.0), (50.0, 0.2), (2000.0, 2.0), (1e4, 1.0)])
def test_mean_and_variance_match_eq_2_13(e_per_s, t_s):
    s = SensorModel(gain_e_per_dn=1.7, read_noise_e=5.0, dark_current_e_per_s=3.0)
    mean, var, n = _stats(s, e_per_s, t_s)
    exp_mean = s.black_level_dn + (e_per_s + s.dark_current_e_per_s) * t_s / s.gain_e_per_dn
    exp_var = s.variance_dn2(exp_mean - s.black_level_dn)
    # Standard error of the mean and of the sample variance (~ var·sqrt(2/n) for near-Gaussian).
    assert abs(mean - exp_mean) < 5 * np.sqrt(exp_var / n)
    assert abs(var - exp_var) < 5 * exp_var * np.sqrt(2.0 / n) + 0.01


def test_quantisation_term_present_when_noise_free():
    # No read noise, no light, no dark: only the ADC rounding remains, and the output is exact.
    s = SensorModel(read_noise_e=0.0, dark_current_e_per_s=0.0)
    raw = s.expose(np.zeros((4, 5, 3)), 1.0, 0)
    assert np.all(raw == s.black_level_dn)
    assert s.variance_dn2(0.0) == pytest.approx(1 / 12)


def test_saturation_clips_at_full_well_and_white_level():
    s = SensorModel(gain_e_per_dn=1.0, full_well_e=5000.0, black_level_dn=100)
    raw = s.expose(np.full((8, 8, 3), 1e6), 1.0, 0)
    # Full well (5000 e-) reached before the white level: values sit at black + 5000 ± read noise.
    assert abs(raw.mean() - (100 + 5000)) < 3
    assert s.saturation_dn == 5100
    s2 = SensorModel(gain_e_per_dn=1.0)  # 40000 e- well > 15871 DN of range
    raw2 = s2.expose(np.full((8, 8, 3), 1e7), 1.0, 0)
    assert np.all(raw2 == s2.white_level_dn)


def test_bayer_layout_rggb():
    irr = np.zeros((2, 3, 3))
    irr[..., 0], irr[..., 1], irr[..., 2] = 1000.0, 5000.0, 9000.0
    s = SensorModel(read_noise_e=0, dark_current_e_per_s=0, gain_e_per_dn=1.0)
    raw = s.expose(irr, 1.0, 3).astype(float) - s.black_level_dn
    assert raw.shape == (4, 6) and raw.dtype == float
    r, g1, g2, b = raw[0::2, 0::2], raw[0::2, 1::2], raw[1::2, 0::2], raw[1::2, 1::2]
    assert np.all(r < 1300) and np.all(b > 8500)
    assert np.all(abs(g1 - 5000) < 400) and np.all(abs(g2 - 5000) < 400)
    m = bayer_mosaic_rggb(np.arange(12).reshape(2, 2, 3))
    assert m[0, 0] == 0 and m[0, 1] == 1 and m[1, 0] == 1 and m[1, 1] == 2


def test_deterministic_with_seed_and_dtype():
    s = SensorModel()
    irr = np.random.default_rng(0).uniform(0, 1e4, (6, 7, 3))
    a, b = s.expose(irr, 0.5, 42), s.expose(irr, 0.5, 42)
    assert a.dtype == np.uint16 and a.shape == (12, 14)
    assert np.array_equal(a, b)


@pytest.mark.parametrize("bad", [dict(gain_e_per_dn=0), dict(read_noise_e=-1),
                                 dict(black_level_dn=20000), dict(full_well_e=0)])
def test_bad_parameters_rejected(bad):
    with pytest.raises(ValueError):
        SensorModel(**bad)


def test_bad_inputs_rejected():
    s = SensorModel()
    with pytest.raises(ValueError, match="shape"):
        s.expose(np.zeros((4, 4)), 1.0)
    with pytest.raises(ValueError, match="exposure time"):
        s.expose(np.zeros((4, 4, 3)), -1.0)
    with pytest.raises(ValueError, match="finite"):
        s.expose(np.full((4, 4, 3), np.nan), 1.0)


def test_profile_round_trip_and_iso():
    s = SensorModel(gain_e_per_dn=2.5, read_noise_e=3.0)
    d = s.to_profile_dict()
    assert SensorModel.from_profile_dict(d) == s
    assert SensorModel.from_profile_dict({"gain_e_per_dn": 2.0, "unknown": 1}).gain_e_per_dn == 2.0
    assert s.at_iso(800).gain_e_per_dn == pytest.approx(1.25)
