"""Microfacet distributions D(m), masking–shadowing G(s, o, m), sampling and quadrature of m.

Thesis §3.1.2–3.1.3: table 3.1 (Gaussian, Beckmann, GGX; isotropic and anisotropic),
eq 3.17 (Torrance–Sparrow V-cavity), eq 3.18–3.21 (Smith with the distribution's Λ),
eq 3.33–3.36 (importance sampling; the Gaussian is sampled through GGX with σ̃ = √2 σ),
eq 3.58–3.59 (normalisation of the Gaussian).

All directions are unit vectors in the local frame (macro normal n = +z), shape (..., 3).
Roughness ``sigma`` is a float ≥ 0 (isotropic) or a pair (σ_x, σ_y) (anisotropic; Beckmann
and GGX only). For the Gaussian σ is an angle in radians; for Beckmann and GGX a slope RMS.
"""
import functools

import numpy as np
from scipy.special import erfc

__all__ = [
    "DISTRIBUTIONS", "MASKINGS", "SIGMA_FLAT", "check_sigma", "gaussian_norm_exact", "gaussian_norm_rational_tsb2014",
    "distribution_d", "smith_g1", "masking_g", "sample_microfacet_normals", "microfacet_quadrature",
]

DISTRIBUTIONS = ("gaussian", "beckmann", "ggx")
SIGMA_FLAT = 1e-9  # roughness below this is treated as 0 (a flat facet, Dirac lobe)
MASKINGS = ("smith", "vcavity")
_SQRT_PI = np.sqrt(np.pi)


def check_sigma(sigma, distribution="beckmann"):
    """Return (σ_x, σ_y, isotropic) after checking the roughness (each in [0, 10])."""
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution = {distribution!r}: choose one of {', '.join(DISTRIBUTIONS)}")
    arr = np.atleast_1d(np.asarray(sigma, dtype=float))
    if arr.shape not in ((1,), (2,)) or not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > 10):
        raise ValueError(f"sigma = {sigma!r}: give a roughness in [0, 10] (float) or a pair "
                         "(sigma_x, sigma_y) for an anisotropic distribution (the fits use [0, 2])")
    # A lobe narrower than SIGMA_FLAT cannot be resolved in double precision (1 − cos of that
    # angle is below the machine epsilon) and 1/(π σ²) overflows for σ ≲ 1e-154: flat surface.
    arr = np.where(arr < SIGMA_FLAT, 0.0, arr)
    sx, sy = float(arr[0]), float(arr[-1])
    iso = sx == sy
    if not iso and distribution == "gaussian":
        raise ValueError("the Gaussian distribution is isotropic only (thesis table 3.1); "
                         "use distribution='beckmann' or 'ggx' for an anisotropic sigma pair")
    return sx, sy, iso


def check_masking(masking):
    if masking not in MASKINGS:
        raise ValueError(f"masking = {masking!r}: choose one of {', '.join(MASKINGS)} "
                         "('vcavity' = Torrance–Sparrow eq 3.17, 'smith' = eq 3.18–3.21)")
    return masking


@functools.lru_cache(maxsize=4096)
def gaussian_norm_exact(sigma):
    """1/C of the Gaussian distribution: 2π ∫_0^{π/2} exp(−θ²/2σ²) sin θ dθ (eq 3.58), in sr.

    Evaluated by 200-point Gauss–Legendre on [0, min(π/2, 12σ)] (exact to rounding for any
    σ > 0; eq 3.58's erfi form overflows for small σ). Returns 0 for σ = 0.
    """
    s = float(sigma)
    if s == 0.0:
        return 0.0
    top = min(np.pi / 2, 12.0 * s)
    x, w = np.polynomial.legendre.leggauss(200)
    t = 0.5 * top * (x + 1.0)
    return float(2.0 * np.pi * np.sum(0.5 * top * w * np.exp(-t * t / (2 * s * s)) * np.sin(t)))


def gaussian_norm_rational_tsb2014(sigma):
    """1/C of the Gaussian distribution by the rational fit of eq 3.59 (faster, approximate)."""
    s = np.asarray(sigma, dtype=float)
    k = (146.79, -34.7145, 241.138, -384.291, 2287.69)
    kp = (145.294, 1.12103, 677.137, 752.726, -49.709, 2231.53)
    num = k[0] * s**2 + k[1] * s**3 + k[2] * s**4 + k[3] * s**5 + k[4] * s**6
    den = kp[0] + kp[1] * s**2 + kp[2] * s**3 + kp[3] * s**4 + kp[4] * s**5 + kp[5] * s**6
    return 2.0 * np.pi * num / den


def _slope_terms(m, sx, sy):
    """(x/σ_x)² + (y/σ_y)² of the facet slope (−m_x/m_z, −m_y/m_z), and m_z."""
    mz = m[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = (m[..., 0] / (sx * mz)) ** 2 + (m[..., 1] / (sy * mz)) ** 2
    return np.where(mz > 0, q, np.inf), mz


def distribution_d(m, sigma, distribution="beckmann"):
    """Distribution of facet normals D(m) (table 3.1), in 1/sr, normalised so that
    ∫ D(m) (m·n) dω_m = 1.

    Parameters
    ----------
    m : (..., 3) unit facet normals, local frame.
    sigma : float or (σ_x, σ_y).
    distribution : "gaussian" | "beckmann" | "ggx".

    Returns
    -------
    (...) array ≥ 0; 0 for m_z ≤ 0. For σ = 0 (a flat surface, D is a Dirac at n) it is 0
    everywhere: the mirror lobe has no function value (its albedo is still handled by the
    quadrature/sampling routines, which put all weight on m = n).
    """
    sx, sy, _ = check_sigma(sigma, distribution)
    m = np.asarray(m, dtype=float)
    if sx == 0.0 or sy == 0.0:
        return np.zeros(m.shape[:-1])
    q, mz = _slope_terms(m, sx, sy)
    mz4 = np.where(mz > 0, mz, 1.0) ** 4
    with np.errstate(over="ignore", invalid="ignore"):
        if distribution == "beckmann":
            d = np.exp(-q) / (np.pi * sx * sy * mz4)
        elif distribution == "ggx":
            d = 1.0 / (np.pi * sx * sy * mz4 * (1.0 + q) ** 2)
        else:
            theta = np.arctan2(np.hypot(m[..., 0], m[..., 1]), mz)
            c = 1.0 / gaussian_norm_exact(sx)
            d = c * np.exp(-theta**2 / (2 * sx * sx)) / np.where(mz > 0, mz, 1.0)
    return np.where((mz > 0) & np.isfinite(q), d, 0.0)


def _lambda_q(u, sx, sy):
    """α_u tan θ_u of eq 3.20: sqrt((u_x σ_x)² + (u_y σ_y)²) / u_z (inf at the horizon)."""
    uz = u[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(uz > 0, np.hypot(u[..., 0] * sx, u[..., 1] * sy) / np.where(uz > 0, uz, 1.0), np.inf)


def smith_g1(u, sigma, distribution="beckmann"):
    """Smith shadowing (or masking) G_1(u) = 1/(1 + Λ(u)) (eq 3.19), without the χ⁺(u·m) factor.

    Beckmann: eq 3.20; GGX: eq 3.21; Gaussian: the Beckmann Λ with σ̃ = √2 σ (the two
    distributions agree near the normal, eq 3.32). Returns (...) in [0, 1], 0 at and below
    the horizon, 1 at the normal or for σ = 0.
    """
    sx, sy, _ = check_sigma(sigma, distribution)
    u = np.asarray(u, dtype=float)
    if distribution == "gaussian":
        sx, sy = sx * np.sqrt(2.0), sy * np.sqrt(2.0)
    q = _lambda_q(u, sx, sy)  # = 1/a
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if distribution == "ggx":
            g1 = 2.0 / (1.0 + np.sqrt(1.0 + q * q))
        else:
            a = 1.0 / q
            lam = np.where(q > 0, 0.5 * (-erfc(a) + np.exp(-a * a) / (a * _SQRT_PI)), 0.0)
            g1 = 1.0 / (1.0 + lam)
    return np.where(np.isfinite(q), np.nan_to_num(g1, nan=0.0), 0.0)


def masking_g(s, o, m, sigma, distribution="beckmann", masking="smith"):
    """Masking–shadowing G(s, o, m) in [0, 1], shape broadcast of s, o, m without the last axis.

    masking = "vcavity": Torrance–Sparrow eq 3.17; "smith": G_1(s) G_1(o) (eq 3.18), both
    with χ⁺(s·m) χ⁺(o·m) (a facet turned away from s or o gets nothing).
    """
    check_masking(masking)
    s = np.asarray(s, dtype=float)
    o = np.asarray(o, dtype=float)
    m = np.asarray(m, dtype=float)
    sm = np.sum(s * m, axis=-1)
    om = np.sum(o * m, axis=-1)
    visible = (sm > 0) & (om > 0) & (s[..., 2] > 0) & (o[..., 2] > 0)
    if masking == "smith":
        g = smith_g1(s, sigma, distribution) * smith_g1(o, sigma, distribution)
    else:
        mz = m[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            gs = 2.0 * mz * s[..., 2] / np.where(sm > 0, sm, 1.0)
            go = 2.0 * mz * o[..., 2] / np.where(om > 0, om, 1.0)
        g = np.clip(np.minimum(gs, go), 0.0, 1.0)
    return np.where(visible, g, 0.0)


def _normal_from_slopes(px, py):
    inv = 1.0 / np.sqrt(1.0 + px * px + py * py)
    return np.stack([-px * inv, -py * inv, inv], axis=-1)


def _standard_slope_radius(xi1, distribution):
    """Slope radius of the unit-roughness distribution at CDF value xi1 (eq 3.33–3.34)."""
    xi1 = np.clip(xi1, 0.0, 1.0 - 1e-16)
    if distribution == "beckmann":
        return np.sqrt(-np.log1p(-xi1))
    return np.sqrt(xi1 / (1.0 - xi1))  # GGX


def sample_microfacet_normals(xi1, xi2, sigma, distribution="beckmann"):
    """Facet normals with pdf D(m)(m·n) over dω (eq 3.33–3.36), and the importance weights.

    Parameters
    ----------
    xi1, xi2 : arrays in [0, 1) of the same shape (uniform random numbers or quadrature nodes).

    Returns
    -------
    m : (..., 3) unit normals; weight : (...) = D(m)(m·n) / pdf(m), 1 for Beckmann and GGX.
    The anisotropic case scales the unit-roughness slopes by (σ_x, σ_y), which is eq 3.35
    written in slope space. The Gaussian is drawn from GGX with σ̃ = √2 σ (eq 3.36) and
    carries the ratio of the two as its weight (unbounded near grazing facets for σ ≳ 0.5).
    """
    sx, sy, _ = check_sigma(sigma, distribution)
    xi1 = np.asarray(xi1, dtype=float)
    phi = 2.0 * np.pi * np.asarray(xi2, dtype=float)
    if distribution == "gaussian":
        st = np.sqrt(2.0) * sx
        r = _standard_slope_radius(xi1, "ggx")
        m = _normal_from_slopes(st * r * np.cos(phi), st * r * np.sin(phi))
        if sx == 0.0:
            return m, np.ones(xi1.shape)
        with np.errstate(over="ignore", invalid="ignore"):
            p = distribution_d(m, st, "ggx") * m[..., 2]
            w = distribution_d(m, sx, "gaussian") * m[..., 2] / p
        return m, np.where(p > 0, np.nan_to_num(w), 0.0)
    r = _standard_slope_radius(xi1, distribution)
    m = _normal_from_slopes(sx * r * np.cos(phi), sy * r * np.sin(phi))
    return m, np.ones(xi1.shape)


@functools.lru_cache(maxsize=256)
def microfacet_quadrature(sigma, distribution="beckmann", n_theta=48, n_phi=48):
    """Deterministic nodes (m_k, w_k) with Σ_k w_k h(m_k) ≈ ∫ h(m) D(m) (m·n) dω_m.

    Beckmann and GGX: Gauss–Legendre in the CDF variable ξ_1 of eq 3.33–3.34 × uniform
    (periodic trapezoid) in φ, so the nodes follow the peak of D at any σ. Gaussian:
    Gauss–Legendre in θ_m on [0, min(π/2, 10σ)] × uniform φ with the exact density.
    Weights are renormalised to sum to 1 (∫ D (m·n) dω = 1). σ = 0 gives the single node n.
    ``sigma`` must be hashable (float or tuple). Returns read-only arrays (K, 3) and (K,).
    """
    sx, sy, _ = check_sigma(sigma, distribution)
    if sx == 0.0 or sy == 0.0:
        m, w = np.array([[0.0, 0.0, 1.0]]), np.array([1.0])
    else:
        x, wx = np.polynomial.legendre.leggauss(int(n_theta))
        xi2 = (np.arange(int(n_phi)) + 0.5) / int(n_phi)
        if distribution == "gaussian":
            top = min(np.pi / 2, 10.0 * sx)
            th = 0.5 * top * (x + 1.0)
            wt = 0.5 * top * wx * np.exp(-th**2 / (2 * sx * sx)) * np.sin(th)
            th, phi = np.meshgrid(th, 2 * np.pi * xi2, indexing="ij")
            m = np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)], axis=-1)
            w = np.broadcast_to(wt[:, None], th.shape)
        else:
            xi1, xi2g = np.meshgrid(0.5 * (x + 1.0), xi2, indexing="ij")
            m, _ = sample_microfacet_normals(xi1, xi2g, (sx, sy), distribution)
            w = np.broadcast_to(0.5 * wx[:, None], xi1.shape)
        m = m.reshape(-1, 3)
        w = np.asarray(w, dtype=float).reshape(-1)
        w = w / w.sum()
    m.setflags(write=False)
    w.setflags(write=False)
    return m, w
