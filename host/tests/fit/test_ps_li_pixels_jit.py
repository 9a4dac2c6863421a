"""brightest_excess (the compiled highlight test of Pixels.start) against the array form it replaced."""
import numpy as np

from facette.fit._ps_li_pixels_jit import brightest_excess


def _array_form(values, usable, normals, lights, albedo):
    # the numpy form `_highlight_starts` had before the compiled pass (its has_highlight, argmax)
    lam_pred = (normals @ lights.T if lights.ndim == 2 else np.einsum("nj,nmj->nm", normals, lights)) * \
        (albedo / np.pi)[:, None]
    excess = np.where(usable, values, -np.inf) - lam_pred
    brightest = np.argmax(excess, axis=1)
    with np.errstate(invalid="ignore"):
        mean_v = np.nanmean(np.where(usable, values, np.nan), axis=1) if usable.any(1).all() else \
            np.array([np.nanmean(np.where(u, v, np.nan)) if u.any() else np.nan for v, u in zip(values, usable)],
                     np.float32)
    margin = np.take_along_axis(excess, brightest[:, None], 1)[:, 0] - 0.1 * np.nan_to_num(mean_v)
    return margin > 0, brightest, margin


def _inputs(n, m, near, seed):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3)).astype(np.float32) * [0.4, 0.4, 0] + [0, 0, 1]
    normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
    lights = rng.normal(size=(n, m, 3) if near else (m, 3)) * 0.5 + [0, 0, 1]
    lights = lights / np.linalg.norm(lights, axis=-1, keepdims=True)
    lights = lights.astype(np.float32 if near else np.float64)      # as _check_inputs hands them
    albedo = rng.uniform(0.1, 0.9, n).astype(np.float32)
    values = np.clip(np.einsum("nj,n...mj->nm", normals, lights[None] if not near else lights)
                     if near else normals @ lights.T, 0, None) * (albedo / np.pi)[:, None]
    values = (values * rng.uniform(0.97, 1.03, values.shape)).astype(np.float32)
    values[rng.random(values.shape) < 0.05] *= 4                    # highlights
    usable = rng.random(values.shape) > 0.2
    values[~usable & (rng.random(values.shape) < 0.5)] = np.nan      # unusable values may be anything
    usable[0] = False                                               # no usable light
    usable[1, 1:] = False                                           # one usable light
    return values, usable, normals, lights, albedo


def test_compiled_highlight_test_equals_the_array_form():
    for near in (False, True):
        for seed in range(3):
            values, usable, normals, lights, albedo = _inputs(3000, 12, near, seed)
            has, brightest = brightest_excess(values, usable, normals, lights, albedo / np.pi)
            want_has, want_brightest, margin = _array_form(values, usable, normals, lights, albedo)
            np.testing.assert_array_equal(brightest, want_brightest)
            # the same verdict but within rounding of the 10 % test (float64 sums against float32)
            clear = np.abs(margin) > 1e-6 * np.nanmax(values)
            np.testing.assert_array_equal(has[clear], want_has[clear])
            assert clear.mean() > 0.99 and 0.05 < has.mean() < 0.95
            assert not has[0] and brightest[0] == 0                 # no usable light: no highlight


def test_compiled_highlight_test_on_no_pixels():
    has, brightest = brightest_excess(np.zeros((0, 5), np.float32), np.zeros((0, 5), bool),
                                      np.zeros((0, 3), np.float32), np.eye(5, 3), np.zeros(0, np.float32))
    assert has.shape == (0,) and brightest.shape == (0,)


def test_channel_and_usable_equals_the_array_form():
    # Pixels.start's usable flags and green values, against the numpy passes they replaced
    from facette.fit._ps_li_pixels_jit import channel_and_usable
    from facette.recon._ps import _usable
    rng = np.random.default_rng(4)
    flat = rng.uniform(0, 1, (7, 500, 3)).astype(np.float32)
    flat[rng.random(flat.shape) < 0.05] = np.nan                   # unusable in one channel or another
    flat[2, 10, 1] = np.float32(0.95)                              # exactly at the level, in float32
    flat[3, 11, 0] = np.inf
    idx = np.flatnonzero(rng.random(500) < 0.7)
    for channel, saturation in ((1, None), (1, 0.95), (0, 0.5)):
        values, ok = channel_and_usable(flat, idx, channel, saturation)
        want_ok = np.all(np.isfinite(flat[:, idx, :]), axis=2).T & _usable(flat[:, idx, channel], saturation).T
        np.testing.assert_array_equal(ok, want_ok)
        np.testing.assert_array_equal(values, flat[:, idx, channel].T)
        assert values.flags.c_contiguous and 0.05 < (~ok).mean() < 0.9
    assert not channel_and_usable(flat, np.array([10]), 1, 0.95)[1][0, 2]    # 0.95 is not below 0.95
    values, ok = channel_and_usable(flat, np.zeros(0, np.int64), 1, None)
    assert values.shape == (0, 7) and ok.shape == (0, 7)


def test_compiled_lobe_test_equals_the_array_form():
    # split_levels' "some light inside the fitted lobe", against the numpy form it replaced
    from facette.fit._ps_li_pixels_jit import any_light_in_lobe
    for near in (False, True):
        _, _, normals, lights, _ = _inputs(3000, 12, near, 7)
        h = lights + np.float32([0, 0, 1])
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        cos_min = np.float32(np.sqrt(1 / (1 + np.float32((2.5 * 0.1) ** 2))))
        ch = normals @ h.T if h.ndim == 2 else np.einsum("nj,nmj->nm", normals, h)
        want = np.any(ch > cos_min, axis=1)
        got = any_light_in_lobe(normals, h, cos_min)
        clear = np.all(np.abs(ch - cos_min) > 1e-6, axis=1)
        np.testing.assert_array_equal(got[clear], want[clear])
        assert clear.mean() > 0.99 and 0.05 < got.mean() < 0.95
    assert any_light_in_lobe(np.zeros((0, 3), np.float32), np.eye(3), 0.5).shape == (0,)
