"""Dielectric Fresnel reflectance and the diffuse interface reflectances r_e, r_i.

Thesis eq 3.7–3.9 (Fresnel, unpolarised, dielectric), eq 3.12–3.13 (r_i, r_e after
Molenaar et al. 1999) and Simonot's relation n_i² (1 − r_i) = 1 − r_e.
"""
import numpy as np

__all__ = ["fresnel_dielectric", "r_e_molenaar1999", "r_i_simonot2009", "check_n_i"]

# Below this n_i − 1, eq 3.13 loses digits (terms of order 1/(n⁴ − 1)² cancel): the
# external diffuse reflectance is integrated directly instead (see r_e_molenaar1999).
_MOLENAAR_MIN_EXCESS = 0.05


N_I_MAX = 100.0


def check_n_i(n_i):
    """Return n_i as a float after checking 1 ≤ n_i ≤ N_I_MAX (relative index of the interface).

    Dielectrics lie in [1, 2.5] (the LI fits' range). Larger indices stand for a metal's lobe
    beside a Lambertian part (facette.fit: diffuse "lambert"): a real index of the same reflectance
    at normal incidence, F0 = ((n − 1)/(n + 1))² (0.5 at n 5.8, 0.9 at n 38), whose Fresnel factor
    is as flat as a conductor's away from grazing angles."""
    n = float(n_i)
    if not np.isfinite(n) or n < 1.0 or n > N_I_MAX:
        raise ValueError(f"n_i = {n_i!r}: the relative refractive index must be a finite number in "
                         f"[1, {N_I_MAX:g}] (1 = no interface; dielectrics [1, 2.5], larger: a metal's lobe)")
    return n


def fresnel_dielectric(c, n_i):
    """Unpolarised Fresnel reflectance of a dielectric interface (eq 3.7–3.9).

    Parameters
    ----------
    c : array_like, cosine between the incident direction and the facet normal, in [0, 1]
        (negative values are taken by absolute value).
    n_i : float ≥ 1, relative index n_1 / n_0 (light arrives from the n_0 side).

    Returns
    -------
    ndarray like c, in [0, 1]: 0 for n_i = 1, 1 at grazing incidence (c = 0) when n_i > 1.
    float32 input stays float32 (the per-pixel photometric-stereo terms); anything else is float64.

    Notes
    -----
    Written with g − c = (n_i² − 1)/(g + c) so that it stays exact as n_i → 1, where the
    textbook form subtracts two nearly equal numbers.
    """
    n = check_n_i(n_i)
    c = np.asarray(c)
    c = np.abs(c if c.dtype == np.float32 else c.astype(float))
    c = np.minimum(c, c.dtype.type(1))
    eta = c.dtype.type((n - 1.0) * (n + 1.0))  # n² − 1 without cancellation
    if eta == 0.0:
        return np.zeros_like(c)
    g = np.sqrt(eta + c * c)
    gpc = g + c
    gmc = eta / gpc
    a = gmc / gpc
    num = c * gpc - 1
    den = c * gmc + 1
    return c.dtype.type(0.5) * a * a * (1 + (num / den) ** 2)


def _r_e_integral(n):
    """External diffuse reflectance ∫ F(θ) sin 2θ dθ = ∫_0^1 F(c) 2c dc, integrated directly.

    F rises from ~((n−1)/(n+1))² to 1 inside c ≲ √(n² − 1): composite Gauss–Legendre on
    geometrically graded intervals resolves that layer for any n − 1 ≥ 0 (error < 1e-14).
    """
    eta = (n - 1.0) * (n + 1.0)
    if eta == 0.0:
        return 0.0
    w0 = np.sqrt(eta)
    edges = [0.0]
    e = w0 / 64.0
    while e < 1.0:
        edges.append(e)
        e *= 2.0
    edges.append(1.0)
    x, w = np.polynomial.legendre.leggauss(24)
    a = np.asarray(edges[:-1])[:, None]
    b = np.asarray(edges[1:])[:, None]
    c = 0.5 * (b - a) * x[None, :] + 0.5 * (b + a)
    wc = 0.5 * (b - a) * w[None, :]
    return float(np.sum(wc * 2.0 * c * fresnel_dielectric(c, n)))


def r_e_molenaar1999(n_i):
    """Diffuse (Lambertian-illuminated) reflectance of a flat interface seen from outside.

    Parameters
    ----------
    n_i : float in [1, N_I_MAX].

    Returns
    -------
    float in [0, 1): 0 at n_i = 1, ≈ 0.0918 at n_i = 1.5.

    Notes
    -----
    Eq 3.13 (Molenaar, ten Bosch & Zijp 1999) for n_i − 1 ≥ 0.05. Closer to 1 its terms
    (each ~1/(n_i⁴ − 1)²) cancel to all digits (at n_i = 1 + 1e-9 the formula returns
    garbage or NaN), so there r_e = ∫_0^1 F(c) 2c dc is integrated directly (eq 3.12 form),
    which agrees with eq 3.13 to < 1e-12 at the switch. Near 1, r_e ≈ (n_i − 1)/3 → 0
    (continuous: the singularities are in the formula, not in the quantity).
    """
    n = check_n_i(n_i)
    if n - 1.0 < _MOLENAAR_MIN_EXCESS:
        return _r_e_integral(n)
    n2 = n * n
    n4 = n2 * n2
    return (0.5
            - 2.0 * n ** 3 * (n2 + 2.0 * n - 1.0) / ((n2 + 1.0) * (n4 - 1.0))
            + (n - 1.0) * (3.0 * n + 1.0) / (6.0 * (n + 1.0) ** 2)
            + 8.0 * n4 * (n4 + 1.0) / ((n2 + 1.0) * (n4 - 1.0) ** 2) * np.log(n)
            + n2 * (n2 - 1.0) ** 2 / (n2 + 1.0) ** 3 * np.log((n - 1.0) / (n + 1.0)))


def r_i_simonot2009(n_i):
    """Internal diffuse reflectance r_i of the interface, from n_i² (1 − r_i) = 1 − r_e.

    Returns a float in [0, 1): 0 at n_i = 1, ≈ 0.596 at n_i = 1.5 (total internal reflection).
    """
    n = check_n_i(n_i)
    return 1.0 - (1.0 - r_e_molenaar1999(n)) / (n * n)
