"""Photon transfer curve: the sensor model's parameters come back from dark and flat frames."""
import numpy as np
import pytest

from facette.hdr import estimate_sensor_ptc, estimate_sensor_ptc_files
from facette.sim.dng import write_dng
from facette.camera.sensor import SensorModel

COLOUR = np.array([0.5, 1.0, 0.3])


def _series(s, h=64, w=64, seed=0, flat_times=None):
    rng = np.random.default_rng(seed)
    zero = np.zeros((h, w, 3))
    darks = [(t, s.expose(zero, t, rng), s.expose(zero, t, rng)) for t in (0.001, 5.0, 15.0)]
    flat = np.ones((h, w, 3)) * COLOUR * 1000.0
    times = np.geomspace(0.05, 60, 12) if flat_times is None else flat_times
    flats = [(t, s.expose(flat, t, rng), s.expose(flat, t, rng)) for t in times]
    return darks, flats


@pytest.mark.parametrize("truth", [
    SensorModel(gain_e_per_dn=1.8, read_noise_e=3.5, dark_current_e_per_s=2.0, full_well_e=25000),
    SensorModel(),                                   # ADC white level clips before the well
    SensorModel(gain_e_per_dn=0.6, read_noise_e=8.0, dark_current_e_per_s=0.0, black_level_dn=128),
])
def test_recovers_sensor_parameters(truth):
    r = estimate_sensor_ptc(*_series(truth))
    assert r.gain_e_per_dn == pytest.approx(truth.gain_e_per_dn, rel=0.04)
    assert r.read_noise_e == pytest.approx(truth.read_noise_e, rel=0.08)
    assert r.dark_current_e_per_s == pytest.approx(truth.dark_current_e_per_s, abs=0.15)
    assert r.black_level_dn == pytest.approx(truth.black_level_dn, abs=0.5)
    assert r.white_level_dn == pytest.approx(truth.saturation_dn, abs=15)
    assert (r.full_well_e is None) == (truth.saturation_dn >= truth.white_level_dn)
    assert r.fit_rms_rel < 0.1
    d = r.to_profile_dict()
    assert {"gain_e_per_dn", "read_noise_e", "dark_current_e_per_s", "black_level_dn",
            "white_level_dn"} <= set(d)
    model = r.sensor_model()
    assert model.saturation_dn == pytest.approx(truth.saturation_dn, abs=15)


def test_from_dng_files(tmp_path):
    truth = SensorModel(gain_e_per_dn=2.2, read_noise_e=5.0, dark_current_e_per_s=1.0)
    darks, flats = _series(truth, flat_times=np.geomspace(0.05, 8, 6))

    def files(series, prefix):
        out = []
        for i, (t, a, b) in enumerate(series):
            for j, m in enumerate((a, b)):
                out.append(write_dng(tmp_path / f"{prefix}{i:02d}{j}.dng", m, truth.black_level_dn,
                                     truth.white_level_dn, t, 400))
        return out

    r = estimate_sensor_ptc_files(files(darks, "D"), files(flats, "F"))
    assert r.gain_e_per_dn == pytest.approx(2.2, rel=0.05)
    assert r.read_noise_e == pytest.approx(5.0, rel=0.1)


def test_too_few_or_saturated_flats_are_clear_errors():
    s = SensorModel()
    darks, flats = _series(s)
    with pytest.raises(ValueError, match="at least 3 flat"):
        estimate_sensor_ptc(darks, flats[:2])
    with pytest.raises(ValueError, match="dark"):
        estimate_sensor_ptc([], flats)
    with pytest.raises(ValueError, match="unsaturated"):
        estimate_sensor_ptc(darks, _series(s, flat_times=[100, 120, 150, 200])[1])  # all clipped
