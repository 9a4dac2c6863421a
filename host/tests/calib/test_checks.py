"""facette.calib.checks: a capture's exposure check and the angle between directions."""
import numpy as np
import pytest

from facette.calib import nominal_light_directions
from facette.calib.checks import WizardError, angle_deg, check_exposure

FULL = 15871.0          # white − black, DN
LONG, SHORT, MA = 1_000_000, 60_000, 500



def _images(level_of_full_scale_at_long, m=12, shape=(20, 30)):
    """HDR images (DN/(µs·mA)) whose value reaches the given fraction of full scale at LONG µs."""
    v = level_of_full_scale_at_long * FULL / (LONG * MA)
    return np.full((m,) + shape + (3,), v)



def test_a_usable_capture_passes_and_reports_its_level():
    level, sat = check_exposure(_images(0.35), LONG, SHORT, MA, FULL, "spectralon")
    np.testing.assert_allclose(level, 0.35)
    assert np.all(sat == 0)



def test_missing_target_dark_led_and_overexposure_are_named():
    with pytest.raises(WizardError, match=r"spectralon: not found — the image is dark \(2.0 % .* Place"):
        check_exposure(_images(0.02), LONG, SHORT, MA, FULL, "spectralon")
    img = _images(0.35)
    img[4] *= 0.01
    with pytest.raises(WizardError, match=r"LED\(s\) \[4\] gave almost no light"):
        check_exposure(img, LONG, SHORT, MA, FULL, "spectralon")
    # saturated at the shortest exposure: LONG/SHORT × 0.35 ≈ 5.8 × full scale at LONG is not enough,
    # 20 × full scale is
    img = _images(0.35)
    img[2, :5] = 20.0 * FULL / (LONG * MA)
    with pytest.raises(WizardError, match=r"overexposed — 25 % .* LED\(s\) \[2\]\. Shorten the exposures"):
        check_exposure(img, LONG, SHORT, MA, FULL, "spectralon")
    # a mask limits the check to the target
    mask = np.zeros((20, 30), bool)
    mask[10:] = True
    check_exposure(img, LONG, SHORT, MA, FULL, "spectralon", mask=mask)



def test_angle_deg():
    d = nominal_light_directions()
    np.testing.assert_allclose(angle_deg(d, d), 0, atol=1e-6)
    assert angle_deg([0, 0, 1.0], [np.sin(0.1), 0, np.cos(0.1)]) == pytest.approx(np.degrees(0.1))
