import numpy as np
import pytest

from facette.calib import nominal_light_directions
from facette.calib.spectralon import flat_field, led_current_gains, spectralon_intensities
from facette.calib.targets import channel_reflectance, load_target, render_spectralon

SHAPE, PITCH = (60, 80), 0.5


def _vignetting():
    yy, xx = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    r2 = ((xx - 39.5) / 40) ** 2 + ((yy - 29.5) / 40) ** 2
    return 1 - 0.15 * r2


def _stack(intensities, dirs=None, positions=None, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    rho = channel_reflectance()
    out = []
    for i, I in enumerate(intensities):
        kw = {"direction": dirs[i]} if positions is None else {"position_mm": positions[i]}
        img = render_spectralon(SHAPE, PITCH, intensity=I, reflectance=rho, vignetting=_vignetting(), **kw)
        out.append(img * (1 + noise * rng.standard_normal(img.shape)))
    return np.stack(out), rho


def test_certificate_is_a_99_percent_grade():
    spec = load_target("spectralon-99")
    wl, r = np.array(spec["wavelength_nm"]), np.array(spec["reflectance"])
    assert wl[0] == 400 and wl[-1] == 700
    band = r[(wl >= 500) & (wl <= 700)]
    assert band.min() >= 0.985 and band.max() <= 0.995
    rho = channel_reflectance(spec)
    assert rho.shape == (3,) and np.all((rho > 0.98) & (rho < 0.995))
    assert rho[0] > rho[2]          # the certificate rises towards the red


def test_intensities_recovered_per_led_and_channel_distant_lights():
    d = nominal_light_directions()
    I = np.random.default_rng(1).uniform(0.85, 1.15, (12, 3))
    imgs, rho = _stack(I, dirs=d, noise=0.01)
    res = spectralon_intensities(imgs, d, rho)
    truth = I / I.mean(axis=0)
    assert res.intensities.shape == (12, 3)
    np.testing.assert_allclose(res.intensities, truth, rtol=2e-3)
    np.testing.assert_allclose(res.intensities.mean(axis=0), 1)
    # the absolute values carry the reflectance correction: radiance ρ/π·I·cos → I
    ratio = res.absolute / I            # one common factor: the vignetting's mean over the target
    np.testing.assert_allclose(ratio, ratio.mean(), rtol=3e-3)
    assert 0.9 < ratio.mean() < 1.0


def test_near_lights_use_per_pixel_cosine_and_falloff():
    d = nominal_light_directions()
    P = d * 300.0                       # close LEDs: strong fall-off across the field
    I = np.random.default_rng(2).uniform(0.85, 1.15, (12, 3))
    imgs, rho = _stack(I, positions=P)
    truth = I / I.mean(axis=0)
    near = spectralon_intensities(imgs, positions_mm=P, pixel_pitch_mm=PITCH, reflectance=rho)
    np.testing.assert_allclose(near.intensities, truth, rtol=1e-6)
    far = spectralon_intensities(imgs, d, rho)
    # ignoring the near-light geometry leaves a bias the near model removes
    assert np.abs(far.intensities / truth - 1).max() > 10 * np.abs(near.intensities / truth - 1).max()
    with pytest.raises(ValueError, match="pixel_pitch_mm"):
        spectralon_intensities(imgs, positions_mm=P, reflectance=rho)


def test_flat_field_mean_one_with_and_without_falloff():
    d = nominal_light_directions()
    P = d * 300.0
    imgs, rho = _stack(np.ones((12, 3)), positions=P)
    v = _vignetting() / _vignetting().mean()
    ff = flat_field(imgs, positions_mm=P, pixel_pitch_mm=PITCH, mask=np.ones(SHAPE, bool))
    assert ff.shape == SHAPE + (3,) and ff.dtype == np.float32
    np.testing.assert_allclose(ff.mean(axis=(0, 1)), 1, rtol=1e-5)
    np.testing.assert_allclose(ff[..., 1], v, rtol=1e-4)          # only the camera's share
    ff_all = flat_field(imgs, d, mask=np.ones(SHAPE, bool))        # includes the fall-off
    assert np.abs(ff_all[..., 1] / v - 1).max() > 0.003
    # outside the mask the polynomial surface fills in smoothly
    mask = np.zeros(SHAPE, bool)
    mask[5:-5, 5:-5] = True
    ff_m = flat_field(imgs, positions_mm=P, pixel_pitch_mm=PITCH, mask=mask)
    np.testing.assert_allclose(ff_m[..., 1], v, rtol=2e-3)


def test_bad_inputs_say_what_to_do():
    d = nominal_light_directions()
    imgs, rho = _stack(np.ones((12, 3)), dirs=d)
    with pytest.raises(ValueError, match="one Spectralon image per LED"):
        spectralon_intensities(imgs[:5], d, rho)
    bad = imgs.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        spectralon_intensities(bad, d, rho)
    with pytest.raises(ValueError, match="fill most of the field"):
        spectralon_intensities(imgs, d, rho, mask=np.zeros(SHAPE, bool))
    dark = imgs.copy()
    dark[3] = 0
    with pytest.raises(ValueError, match="no light"):
        spectralon_intensities(dark, d, rho, mask=np.ones(SHAPE, bool))


def test_led_gains_equalise_to_the_dimmest():
    I = np.array([[1.0, 1.1, 1.2], [0.9, 0.95, 1.0], [1.1, 1.0, 0.9]])
    g = led_current_gains(I)
    np.testing.assert_allclose(g * I[:, 1], 0.95)
    assert g.max() == pytest.approx(1.0)
    # measured with gains already in force: the new gains compound
    g2 = led_current_gains(I, current_gains=[0.8, 1.0, 0.9])
    np.testing.assert_allclose(g2, np.array([0.8, 1.0, 0.9]) * 0.95 / I[:, 1])
    with pytest.raises(ValueError, match=r"LED\(s\) \[1\]"):
        led_current_gains([1.0, 0.1, 1.0], target="mean")


def test_led_gains_lowest_target_stays_in_the_device_range():
    I = np.array([0.57, 0.9, 1.0, 1.33])       # 133 % spread: the dimmest cannot be the target
    with pytest.raises(ValueError, match="outside the device's range"):
        led_current_gains(I, target="min", limits=(0.5, 2.0))
    g = led_current_gains(I, target="lowest", limits=(0.5, 2.0))
    np.testing.assert_allclose(g * I, (g * I)[0])            # equal light
    assert g.min() == pytest.approx(0.5) and g.max() <= 2.0
    np.testing.assert_allclose(led_current_gains(I[1:3], target="lowest"), [1.0, 0.9])


def test_apply_flat_field_divides_and_refuses_other_resolutions():
    from facette.calib import apply_flat_field

    ff = np.random.default_rng(5).uniform(0.8, 1.2, SHAPE + (3,)).astype(np.float32)
    imgs = np.ones((2,) + SHAPE + (3,), np.float32) * ff
    np.testing.assert_allclose(apply_flat_field(imgs, ff), 1, rtol=1e-6)
    assert apply_flat_field(imgs, None) is imgs
    with pytest.raises(ValueError, match="another resolution"):
        apply_flat_field(imgs, ff[:10])
    with pytest.raises(ValueError, match="damaged"):
        apply_flat_field(imgs, np.zeros_like(ff))
