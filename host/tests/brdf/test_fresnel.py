import numpy as np
import pytest

from facette.brdf import fresnel_dielectric, r_e_molenaar1999, r_i_simonot2009
from facette.brdf._fresnel import _r_e_integral


def textbook_fresnel(c, n):
    g = np.sqrt(n * n + c * c - 1)
    return 0.5 * (g - c) ** 2 / (g + c) ** 2 * (1 + (c * (g + c) - 1) ** 2 / (c * (g - c) + 1) ** 2)


def test_fresnel_matches_the_textbook_form_and_its_limits():
    c = np.linspace(0.01, 1, 50)
    for n in (1.2, 1.5, 2.5):
        np.testing.assert_allclose(fresnel_dielectric(c, n), textbook_fresnel(c, n), rtol=1e-12)
        assert fresnel_dielectric(1.0, n) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12)
        assert fresnel_dielectric(0.0, n) == pytest.approx(1.0)
    assert np.all(fresnel_dielectric(c, 1.0) == 0)


def test_fresnel_stays_exact_as_n_goes_to_one():
    # normal incidence: ((n-1)/(n+1))^2 ~ eps^2/4, which the textbook form loses entirely
    for eps in (1e-9, 1e-6, 1e-3):
        assert fresnel_dielectric(1.0, 1 + eps) == pytest.approx((eps / (2 + eps)) ** 2, rel=1e-9)
    assert np.all(np.isfinite(fresnel_dielectric(np.linspace(0, 1, 11), 1 + 1e-9)))


def test_molenaar_r_e_agrees_with_the_direct_integral_of_fresnel():
    for n in (1.05, 1.1, 1.3, 1.5, 2.0, 2.5):
        assert r_e_molenaar1999(n) == pytest.approx(_r_e_integral(n), abs=1e-12)
    assert r_e_molenaar1999(1.5) == pytest.approx(0.0918, abs=5e-4)  # diffuse reflectance of glass


@pytest.mark.parametrize("n", [1.0, 1 + 1e-9, 1 + 1e-6, 1 + 1e-3, 1.0499999, 1.05])
def test_r_e_and_r_i_are_stable_near_one(n):
    r_e, r_i = r_e_molenaar1999(n), r_i_simonot2009(n)
    assert np.isfinite(r_e) and np.isfinite(r_i)
    assert 0 <= r_e < r_i < 1 or n == 1.0
    if n > 1:  # leading order r_e ~ (n - 1)/3
        assert r_e == pytest.approx((n - 1) / 3, rel=0.2)
    # Simonot's relation n^2 (1 - r_i) = 1 - r_e
    assert n * n * (1 - r_i) == pytest.approx(1 - r_e, abs=1e-14)


def test_r_e_is_continuous_across_the_branch_switch():
    below, above = r_e_molenaar1999(1.05 - 1e-12), r_e_molenaar1999(1.05)
    assert abs(below - above) < 1e-12


@pytest.mark.parametrize("bad", [0.9, float("nan"), float("inf"), -1])
def test_bad_index_raises_a_clear_error(bad):
    with pytest.raises(ValueError, match="refractive index"):
        r_e_molenaar1999(bad)
