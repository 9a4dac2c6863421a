"""Bracketing: the thesis's fixed bracket, and adaptive plans that keep their promises."""
import numpy as np
import pytest

from facette.device.registers import REGISTERS
from facette.hdr import THESIS_BRACKET_US, bracket_fixed, merge, plan_adaptive, predicted_snr
from facette.hdr._bracket import frame_overhead_s
from facette.camera.sensor import SensorModel, bayer_mosaic_rggb

SENSOR = SensorModel()
SAT = SENSOR.saturation_dn - SENSOR.black_level_dn


def _shoot(x, exposures, rng):
    """Half-size frames and peaks of radiance x (DN per µs·mA) for [(time_us, mA), ...]."""
    frames, peaks = [], []
    for t_us, i_ma in exposures:
        raw = SENSOR.expose_charge(bayer_mosaic_rggb(x * SENSOR.gain_e_per_dn * t_us * i_ma),
                                   t_us * 1e-6, rng).astype(np.float32) - SENSOR.black_level_dn
        frames.append(np.stack([raw[0::2, 0::2], 0.5 * (raw[0::2, 1::2] + raw[1::2, 0::2]),
                                raw[1::2, 1::2]], -1))
        peaks.append(np.stack([raw[0::2, 0::2], np.maximum(raw[0::2, 1::2], raw[1::2, 0::2]),
                               raw[1::2, 1::2]], -1))
    return frames, peaks


def _scene(seed=0, h=60, w=80, decades=2.5):
    rng = np.random.default_rng(seed)
    x = np.exp(rng.uniform(0, decades * np.log(10), (h, w, 3)))
    return x / x.max() * 0.8 * SAT / (33333 * 500)  # brightest: 80 % of saturation at 1/30 s, 500 mA


def test_fixed_thesis_bracket():
    plan = bracket_fixed("thesis2016", n_lights=12, current_mA=500)
    assert plan.exposures[0] == [(15_000_000, 500), (10_000_000, 500), (2_000_000, 500),
                                 (1_000_000, 500), (200_000, 500), (66_667, 500), (33_333, 500)]
    assert plan.n_frames() == 84
    assert plan.exposure_time_s() == pytest.approx(12 * 28.3, abs=1e-3)
    assert plan.rig_time_s() == pytest.approx(12 * 28.3 + 84 * frame_overhead_s("bulb"), abs=1e-3)
    regs = plan.registers()
    assert regs["exposure_time_us"][0] == 15_000_000 and regs["exposure_current_mA"] == [500] * 7
    with pytest.raises(ValueError, match="unknown fixed bracket"):
        bracket_fixed("canon")


def test_adaptive_plan_meets_target_without_clipping():
    x = _scene()
    rng = np.random.default_rng(1)
    meter = (33333, 500)
    m = _shoot(x, [meter], rng)[0][0]
    plan = plan_adaptive([m], [meter], SENSOR, target_snr_db=40.0, mode="led")
    pred = plan.predicted[0]
    assert pred["target_met"] and pred["snr_db_min"] >= 40.0 - 0.01
    exps = plan.exposures[0]
    assert all(i <= 1000 for _, i in exps)
    # Shortest exposure: the brightest pixel stays below saturation.
    k_min = min(t * i for t, i in exps)
    assert x.max() * k_min < 0.9 * SAT
    # Simulate the plan: measured SNR over the covered range reaches the target (within 1 dB).
    frames, peaks = _shoot(x, exps, rng)
    r = merge(frames, [t * i for t, i in exps], SENSOR, peaks=peaks, n_photosites=(1, 2, 1),
              times_s=[t * 1e-6 for t, _ in exps])
    lo, hi = pred["radiance_range"]
    sel = (x >= lo) & (x <= hi)
    rel_rms = np.sqrt(np.mean(((r.radiance - x) / x)[sel] ** 2))
    assert -20 * np.log10(rel_rms) >= 39.0
    assert not r.saturated.any()


def test_adaptive_uses_fewer_frames_for_narrow_scenes_and_far_less_time_than_fixed():
    rng = np.random.default_rng(2)
    meter = (33333, 500)
    narrow = _shoot(_scene(decades=0.5), [meter], rng)[0][0]
    wide = _shoot(_scene(decades=3.0), [meter], rng)[0][0]
    p_narrow = plan_adaptive([narrow], [meter], SENSOR, target_snr_db=40.0)
    p_wide = plan_adaptive([wide], [meter], SENSOR, target_snr_db=40.0)
    assert p_narrow.n_frames() < p_wide.n_frames()
    assert p_wide.rig_time_s() < bracket_fixed("thesis2016", 1).rig_time_s()


def test_timing_modes():
    x = _scene(decades=1.0)
    meter = (33333, 500)
    m = _shoot(x, [meter], np.random.default_rng(3))[0][0]
    bulb = plan_adaptive([m], [meter], SENSOR, mode="bulb", light_current_mA=400)
    assert {i for _, i in bulb.exposures[0]} == {400}
    cam = plan_adaptive([m], [meter], SENSOR, mode="camera", light_current_mA=500)
    stops = np.log2(np.array([t for t, _ in cam.exposures[0]]) * 1e-6) * 3
    assert np.allclose(stops, np.round(stops), atol=1e-3)  # 1/3-stop shutter speeds
    led = plan_adaptive([m], [meter], SENSOR, mode="led", max_current_mA=1000)
    assert led.exposure_time_s() < bulb.exposure_time_s()
    with pytest.raises(ValueError, match="timing mode"):
        plan_adaptive([m], [meter], SENSOR, mode="flash")


def test_registers_expressible_only_when_shared():
    p = bracket_fixed("thesis2016", 3)
    assert p.registers() is not None
    p.exposures[1] = [(t, 700) for t, _ in p.exposures[1]]
    regs = p.registers()
    assert regs["light_current_mA"] == [500, 700, 500] and regs["exposure_current_mA"] == [0] * 7
    p.exposures[2] = p.exposures[2][:3]
    assert p.registers() is None


def test_predicted_snr_and_black_metering():
    k = [1e6, 1e7]
    snr = predicted_snr(np.array([1e-5, 1e-4, 1.0]), k, SENSOR)
    assert snr[0] < snr[1]          # more light, more SNR
    assert snr[2] == 0              # saturated in every exposure: no information
    with pytest.raises(ValueError, match="black"):
        plan_adaptive([np.zeros((8, 8, 3))], [(1000, 100)], SENSOR)
    with pytest.raises(ValueError, match="selects no pixel"):
        plan_adaptive([np.ones((8, 8, 3))], [(1000, 100)], SENSOR, masks=np.zeros((8, 8), bool))


def test_shared_plan_covers_every_light_and_feeds_run_scan():
    rng = np.random.default_rng(4)
    meter = (33333, 500)
    ms = [_shoot(_scene(seed=s, decades=d), [meter], rng)[0][0] for s, d in ((0, 1.0), (1, 2.5))]
    own = plan_adaptive(ms, [meter] * 2, SENSOR, target_snr_db=38.0)
    shared = plan_adaptive(ms, [meter] * 2, SENSOR, target_snr_db=38.0, shared=True)
    assert own.exposures[0] != own.exposures[1]
    with pytest.raises(ValueError, match="shared=True"):
        own.scan_kwargs()
    kw = shared.scan_kwargs()
    assert kw["mode"] == "led" and kw["exposures"] == shared.exposures[0] == shared.exposures[1]
    assert shared.n_frames() >= own.n_frames()
    assert all(p["target_met"] for p in shared.predicted)


def test_the_thesis_bracket_in_us_is_the_protocol_default():
    assert THESIS_BRACKET_US == (15_000_000, 10_000_000, 2_000_000, 1_000_000, 200_000, 66_667, 33_333)
    assert REGISTERS["exposure_time_us"].default[:7] == THESIS_BRACKET_US


def test_per_light_plan_never_longer_than_the_shared_list():
    # Two lights, one four times dimmer: each light's own list costs no more exposure
    # than the one list covering both, and every exposure still meets the target.
    rng = np.random.default_rng(5)
    meter = (33333, 500)
    x = _scene(decades=1.0)
    meters = [_shoot(x, [meter], rng)[0][0], _shoot(x / 4, [meter], rng)[0][0]]
    own = plan_adaptive(meters, [meter] * 2, SENSOR, target_snr_db=40.0, mode="led")
    one = plan_adaptive(meters, [meter] * 2, SENSOR, target_snr_db=40.0, mode="led", shared=True)
    for li in range(2):
        assert sum(t * i for t, i in own.exposures[li]) <= sum(t * i for t, i in one.exposures[li])
        assert own.predicted[li]["target_met"] and one.predicted[li]["target_met"]
    assert own.exposure_time_s() < one.exposure_time_s()


def test_one_frame_plan_is_no_longer_than_the_target_needs():
    # A narrow scene met by one frame: that frame is shortened to just reach the target,
    # not stretched to put the highlight at the headroom.
    rng = np.random.default_rng(6)
    meter = (33333, 500)
    x = _scene(decades=0.3)
    plan = plan_adaptive([_shoot(x, [meter], rng)[0][0]], [meter], SENSOR, target_snr_db=40.0,
                         mode="led")
    (t, i), = plan.exposures[0]
    lo, hi = plan.predicted[0]["radiance_range"]
    assert hi * t * i < 0.85 * SAT * 0.99
    assert plan.predicted[0]["snr_db_min"] == pytest.approx(40.0, abs=0.5)
