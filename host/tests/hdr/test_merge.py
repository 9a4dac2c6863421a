"""HDR merge: unbiased, variance calibrated, and documented results at the edges."""
import numpy as np
import pytest

from facette.hdr import MERGE_METHODS, THESIS_BRACKET_S, merge, merge_debevec1997, merge_inverse_variance
from facette.camera.sensor import SensorModel, bayer_mosaic_rggb

SENSOR = SensorModel()
SAT = SENSOR.saturation_dn - SENSOR.black_level_dn
TIMES = np.array(THESIS_BRACKET_S)  # thesis bracket, s


def _frames(x_dn_per_s, times, seed=0, sensor=SENSOR):
    """Half-size frames (black-subtracted DN) and peaks of radiance x (DN/s), via the sensor."""
    rng = np.random.default_rng(seed)
    frames, peaks = [], []
    for t in times:
        raw = sensor.expose_charge(bayer_mosaic_rggb(x_dn_per_s * sensor.gain_e_per_dn * t), t,
                                   rng).astype(np.float32) - sensor.black_level_dn
        frames.append(np.stack([raw[0::2, 0::2], 0.5 * (raw[0::2, 1::2] + raw[1::2, 0::2]),
                                raw[1::2, 1::2]], -1))
        peaks.append(np.stack([raw[0::2, 0::2], np.maximum(raw[0::2, 1::2], raw[1::2, 0::2]),
                               raw[1::2, 1::2]], -1))
    return frames, peaks


def _scene(h=120, w=160, seed=3):
    rng = np.random.default_rng(seed)
    return np.exp(rng.uniform(np.log(20.0), np.log(4e5), (h, w, 3)))  # DN/s, 4 decades


def _merge(method, x, seed=0, **kw):
    frames, peaks = _frames(x, TIMES, seed)
    return merge(frames, TIMES, SENSOR, method=method, peaks=peaks, n_photosites=(1, 2, 1),
                 times_s=TIMES, **kw)


def test_inverse_variance_unbiased_and_variance_calibrated():
    x = _scene()
    r = _merge("inverse_variance", x)
    z = (r.radiance - x) / np.sqrt(r.variance)
    assert np.all(r.n_used >= 1) and not r.saturated.any()
    assert abs(z.mean()) < 0.03          # unbiased: mean error well below one σ
    assert 0.95 < z.std() < 1.05         # the reported variance is the real one
    rel = (r.radiance - x) / x
    assert abs(np.median(rel)) < 2e-3
    # Reported SNR: the predicted and the achieved relative error agree for bright pixels.
    bright = x > 1e4
    predicted = np.sqrt(np.mean(1 / r.snr[bright] ** 2))
    assert np.sqrt(np.mean(rel[bright] ** 2)) == pytest.approx(predicted, rel=0.1)


def test_inverse_variance_beats_debevec_hat_on_same_frames():
    x = _scene()
    errs = {m: np.mean((_merge(m, x, seed=5).radiance - x) ** 2 / x ** 2) for m in MERGE_METHODS}
    assert errs["inverse_variance"] < errs["debevec1997"]


def test_second_pass_removes_self_weight_bias():
    # Dim pixels: weights from the measured signal favour low draws (bias); re-weighting fixes it.
    x = np.full((200, 200, 3), 60.0)
    frames, peaks = _frames(x, TIMES, seed=2)
    one = merge_inverse_variance(frames, TIMES, SENSOR, peaks=peaks, times_s=TIMES,
                                 n_photosites=(1, 2, 1), iterations=1)
    two = merge_inverse_variance(frames, TIMES, SENSOR, peaks=peaks, times_s=TIMES,
                                 n_photosites=(1, 2, 1), iterations=2)
    assert abs(two.radiance.mean() / 60.0 - 1) < abs(one.radiance.mean() / 60.0 - 1)
    assert abs(two.radiance.mean() / 60.0 - 1) < 2e-3


@pytest.mark.parametrize("method", sorted(MERGE_METHODS))
def test_noise_free_input_recovered_exactly(method):
    x = np.array([[[1.0, 50.0, 900.0]], [[3000.0, 7000.0, 12000.0]]])  # DN/s, (2, 1, 3)
    frames = [np.minimum(x * t, SAT) for t in TIMES]
    r = merge(frames, TIMES, SENSOR, method=method)
    assert r.radiance.shape == (2, 1, 3) and r.radiance.dtype == np.float32
    assert np.allclose(r.radiance, x, rtol=1e-5)


def test_saturated_sample_is_excluded():
    x = np.full((30, 30, 3), 4000.0)       # saturates at 15, 10 s (60000 DN), fine at 2 s
    r = _merge("inverse_variance", x)
    assert np.all(r.n_used == 5)
    assert abs(r.radiance.mean() / 4000.0 - 1) < 1e-3


def test_every_frame_saturated_gives_lower_bound_and_infinite_variance():
    frames = [np.full((4, 5, 3), float(SAT)) for _ in TIMES]
    for method in MERGE_METHODS:
        r = merge(frames, TIMES, SENSOR, method=method)
        assert r.saturated.all()
        assert np.allclose(r.radiance, SAT / TIMES.min())
        assert np.all(np.isinf(r.variance))


def test_every_frame_black_gives_zero_with_finite_variance():
    rng = np.random.default_rng(0)
    sigma = np.sqrt(SENSOR.variance_dn2(0.0))
    frames = [rng.normal(0, sigma, (50, 50, 3)) for _ in TIMES]
    for method in MERGE_METHODS:
        r = merge(frames, TIMES, SENSOR, method=method)
        assert np.all(r.n_used >= 1) and not r.saturated.any()
        assert np.all(np.isfinite(r.radiance)) and np.all(np.isfinite(r.variance))
        # Documented: the hat weights favour positive noise outliers of short frames.
        assert abs(r.radiance.mean()) < sigma
    r = merge_inverse_variance(frames, TIMES, SENSOR)
    # Inverse variance: essentially the 15 s frame alone (σ/15 per pixel), mean near 0.
    assert abs(r.radiance.mean()) < 5 * sigma / 15 / np.sqrt(r.radiance.size)
    assert np.median(r.variance) == pytest.approx(SENSOR.variance_dn2(0.0) / 15 ** 2, rel=0.1)


def test_missing_exposure_is_an_error():
    frames = [np.zeros((4, 4, 3))] * 6
    with pytest.raises(ValueError, match="6 frames"):
        merge(frames, TIMES, SENSOR)


def test_nan_frame_raises_or_is_excluded():
    x = np.full((10, 10, 3), 500.0)
    frames = [np.minimum(x * t, SAT) for t in TIMES]
    frames[3] = frames[3].copy()
    frames[3][2, 2, 1] = np.nan
    with pytest.raises(ValueError, match=r"frame\(s\) \[3\].*NaN"):
        merge(frames, TIMES, SENSOR)
    r = merge(frames, TIMES, SENSOR, invalid="exclude")
    assert np.allclose(r.radiance, 500.0) and r.n_used[2, 2, 1] == r.n_used[0, 0, 1] - 1
    allnan = [f.copy() for f in frames]
    for f in allnan:
        f[0, 0, 0] = np.nan
    r = merge(allnan, TIMES, SENSOR, invalid="exclude")
    assert np.isnan(r.radiance[0, 0, 0]) and np.isinf(r.variance[0, 0, 0])
    assert r.n_used[0, 0, 0] == 0


def test_mismatched_sizes_and_bad_exposures():
    with pytest.raises(ValueError, match="different sizes"):
        merge([np.zeros((4, 4, 3)), np.zeros((4, 5, 3))], [1, 2], SENSOR)
    with pytest.raises(ValueError, match="> 0"):
        merge([np.zeros((4, 4, 3))] * 2, [1, 0], SENSOR)
    with pytest.raises(ValueError, match="no frames"):
        merge([], [], SENSOR)
    with pytest.raises(ValueError, match="unknown HDR merge method"):
        merge([np.zeros((4, 4, 3))], [1], SENSOR, method="mean")


def test_two_d_frames_and_profile_dict_sensor():
    x = np.full((6, 7), 100.0)
    r = merge_debevec1997([x * t for t in (1.0, 2.0)], [1.0, 2.0],
                          {"gain_e_per_dn": 2.0, "read_noise_e": 3.0, "dark_current_e_per_s": 0.0,
                           "black_level_dn": 0, "white_level_dn": 16383})
    assert r.radiance.shape == (6, 7, 1) and np.allclose(r.radiance, 100.0)


def test_rows_per_block_independent():
    x = _scene(70, 30)
    frames, peaks = _frames(x, TIMES, 9)
    from facette.hdr._merge import _block_inverse_variance, _run_blocks
    a = _run_blocks(_block_inverse_variance, frames, TIMES, SENSOR, TIMES, peaks, (1, 2, 1), None,
                    "raise", "inverse_variance", rows_per_block=7, saturation_sigma=3.0,
                    black_sigma=3.0, iterations=2)
    b = merge_inverse_variance(frames, TIMES, SENSOR, times_s=TIMES, peaks=peaks,
                               n_photosites=(1, 2, 1))
    assert np.array_equal(a.radiance, b.radiance) and np.array_equal(a.variance, b.variance)
    c = merge_inverse_variance(frames, TIMES, SENSOR, times_s=TIMES, peaks=peaks,
                               n_photosites=(1, 2, 1), workers=1)
    assert np.array_equal(c.radiance, b.radiance) and np.array_equal(c.n_used, b.n_used)


def _oracle(frames, peaks, k, t, sensor, n_ph, method, iterations=2, sat_sigma=3.0, black_sigma=3.0):
    """Eq 2.14 in float64 on the whole (n, H, W, C) stack, written from the module notes:
    the reference the block-wise float32 merge must match."""
    z = np.stack(frames).astype(np.float64)
    pk = np.stack(peaks).astype(np.float64)
    k = np.asarray(k, float)[:, None, None, None]
    g = sensor.gain_e_per_dn
    floor = (sensor.read_noise_e / g) ** 2 + 1 / 12
    n_ph = np.asarray(n_ph, float)
    var = lambda s, n: (np.maximum(s, 0) / g + floor) / n   # noqa: E731  eq 2.13
    sat = sensor.saturation_dn - sensor.black_level_dn
    dark = (sensor.dark_current_e_per_s * np.asarray(t, float) / g)[:, None, None, None]
    finite = np.isfinite(z)
    saturated = (pk >= sat - sat_sigma * np.sqrt(var(sat, 1.0))) & finite
    usable = ~saturated & finite
    near_black = z < dark + black_sigma * np.sqrt(var(0.0, n_ph))
    longer = np.zeros_like(usable)
    for u in range(len(frames)):
        longer[u] = (usable & (k > k[u])).any(axis=0)
    valid = usable & ~(near_black & longer)
    z0 = np.where(valid, z - dark, 0.0)
    if method == "inverse_variance":
        w = np.where(valid, k ** 2 / var(np.where(valid, z, 0.0), n_ph), 0.0)
        for _ in range(iterations):
            est = (w * z0 / k).sum(0) / w.sum(0)
            sig = np.where(np.isfinite(est), np.maximum(est, 0), 0)[None] * k + dark
            den = w.sum(0)
            w = np.where(valid, k ** 2 / var(sig, n_ph), 0.0)
        rad, v = est, 1 / den
    else:
        hat = np.clip(np.minimum(z0, sat - z0), 0, None)
        w = np.where(valid, np.maximum(hat, 1e-6), 0.0)
        rad = (w * z0 / k).sum(0) / w.sum(0)
        v = (w ** 2 * np.where(valid, var(np.where(valid, z, 0.0), n_ph) / k ** 2, 0)).sum(0) \
            / w.sum(0) ** 2
    none = ~valid.any(0)
    rad = np.where(none, np.nan, rad)
    v = np.where(none, np.inf, v)
    all_sat = saturated.all(0)
    return np.where(all_sat, sat / k.min(), rad), v, valid.sum(0), all_sat


@pytest.mark.parametrize("method", sorted(MERGE_METHODS))
def test_blockwise_float32_merge_equals_float64_reference(method):
    # Dark, mid, bright and everywhere-saturated pixels, one NaN sample, several blocks and
    # threads: the fast merge gives the float64 reference's values within float32 precision.
    x = _scene(90, 70, seed=11)
    x[:5] = 3.0                     # black in most frames
    x[-5:] = 1e7                    # saturated in every frame
    frames, peaks = _frames(x, TIMES, seed=2)
    frames[2][40, 30, 1] = np.nan
    with np.errstate(all="ignore"):
        rad0, var0, n0, sat0 = _oracle(frames, peaks, TIMES, TIMES, SENSOR, (1, 2, 1), method)
    r = merge(frames, TIMES, SENSOR, method=method, peaks=peaks, n_photosites=(1, 2, 1),
              times_s=TIMES, invalid="exclude", workers=2)
    assert np.array_equal(r.n_used, n0) and np.array_equal(r.saturated, sat0)
    assert r.saturated[-5:].all() and np.isnan(r.radiance).sum() == np.isnan(rad0).sum()
    ok = np.isfinite(rad0)
    np.testing.assert_allclose(r.radiance[ok], rad0[ok], rtol=2e-5)
    fin = np.isfinite(var0)
    assert np.array_equal(np.isfinite(r.variance), fin)
    np.testing.assert_allclose(r.variance[fin], var0[fin], rtol=2e-5)
