"""BRDF models with one call signature: ``f(s, o, **params) -> ndarray`` (1/sr).

s, o : (..., 3) unit vectors in the local frame (normal +z), broadcasting against each other.
K_d (``kd``) is a float in [0, 1] or a length-C sequence (one per colour channel); the
result has shape (...) or (..., C). Values are 0 at and below the horizon.
"""
import numpy as np

from facette._registry import Registry

from ._fresnel import check_n_i, fresnel_dielectric
from ._shading import li_kappa
from ._microfacet import check_masking, check_sigma, distribution_d, masking_g
from ._volume import rough_lambert_terms, volume_integral, _angles
from ._interreflection import interreflection_vcavity

__all__ = ["lambert", "oren_nayar1994", "cook_torrance1982", "brdf_li", "li_specular", "li_volume",
           "li_kd_factor", "get", "MODELS", "prepare_directions", "check_kd"]

INTERREFLECTION_MIN_SIGMA = 0.2  # §3.2.1: below this the extra bounces add nothing notable


def prepare_directions(s, o):
    """Broadcast s, o to a common (..., 3) shape, normalised; ValueError on bad input."""
    s = np.asarray(s, dtype=float)
    o = np.asarray(o, dtype=float)
    if s.shape[-1:] != (3,) or o.shape[-1:] != (3,):
        raise ValueError(f"s and o must be arrays of 3-vectors (..., 3); got shapes {s.shape} and {o.shape}")
    try:
        s, o = np.broadcast_arrays(s, o)
    except ValueError:
        raise ValueError(f"s {s.shape} and o {o.shape} do not broadcast against each other") from None
    ns = np.linalg.norm(s, axis=-1, keepdims=True)
    no = np.linalg.norm(o, axis=-1, keepdims=True)
    if not (np.all(np.isfinite(ns)) and np.all(np.isfinite(no))) or np.any(ns == 0) or np.any(no == 0):
        raise ValueError("s and o must be finite, non-zero direction vectors (unit vectors, local frame n = +z)")
    return s / ns, o / no


def check_kd(kd):
    """Return (kd as float ndarray of shape () or (C,), per_channel flag)."""
    k = np.asarray(kd, dtype=float)
    if k.ndim > 1 or not np.all(np.isfinite(k)) or np.any(k < 0) or np.any(k > 1):
        raise ValueError(f"kd = {kd!r}: K_d is a reflectance in [0, 1], a float or one value per channel")
    return k, k.ndim == 1


def _above(s, o):
    return (s[..., 2] > 0) & (o[..., 2] > 0)


def lambert(s, o, kd):
    """Lambert: f = K_d / π above the horizon."""
    s, o = prepare_directions(s, o)
    kd, pc = check_kd(kd)
    up = _above(s, o).astype(float)
    return up[..., None] * kd / np.pi if pc else up * kd / np.pi


def oren_nayar1994(s, o, kd, sigma, interreflection=True):
    """Oren–Nayar rough Lambertian surface (Gaussian facets, V-cavity), eq 3.56–3.57.

    sigma : float ≥ 0, slope-angle standard deviation in radians (σ = 0 is Lambert).
    interreflection : add the two-bounce term L_2 of Oren & Nayar 1994,
        0.17 K_d²/π · σ²/(σ² + 0.13) · [1 − cos Δφ (2β/π)²].
    """
    s, o = prepare_directions(s, o)
    kd, pc = check_kd(kd)
    sx, _, _ = check_sigma(sigma, "gaussian")
    ts, to, _, cphi = _angles(s, o)
    up = _above(s, o)
    bracket = np.where(up, rough_lambert_terms(ts, to, cphi, sx, "gaussian"), 0.0)
    beta = np.minimum(ts, to)
    l2 = np.where(up, 0.17 / np.pi * sx * sx / (sx * sx + 0.13) * (1.0 - cphi * (2 * beta / np.pi) ** 2), 0.0)
    if pc:
        out = bracket[..., None] * kd / np.pi
        return out + (l2[..., None] * kd**2 if interreflection else 0.0)
    return bracket * kd / np.pi + (l2 * kd**2 if interreflection else 0.0)


def li_specular(s, o, sigma, n_i, distribution="beckmann", masking="smith", prepared=False):
    """Specular part, closed form (eq 3.10): F(s·h) D(h) G(s, o, h) / (4 (s·n)(o·n)), (...).

    0 for σ = 0 (a Dirac lobe has no function value) and for n_i = 1 (no interface).
    prepared : s, o are already `prepare_directions`' output (unit, one shape): not checked nor
    normalised again. For a caller that evaluates the lobe many times on the same directions (the
    BRDF fit: re-normalising its samples' cell directions was ~40 % of its time on DiLiGenT cat).
    """
    n = check_n_i(n_i)
    sx, sy, _ = check_sigma(sigma, distribution)
    check_masking(masking)
    if not prepared:
        s, o = prepare_directions(s, o)
    if distribution == "beckmann" and masking == "smith" and sx == sy and sx > 0:
        # compiled, one pass: the BRDF fit spent 17 % of a `process` run here (16-bit DiLiGenT ball)
        from ._lobe_jit import li_specular_beckmann_smith     # numba: loaded on first use
        s2, o2 = (np.ascontiguousarray(a.reshape(-1, 3)) for a in (s, o))
        out = np.empty(s2.shape[0])
        li_specular_beckmann_smith(s2, o2, float(sx), (n - 1.0) * (n + 1.0), out)
        return out.reshape(s.shape[:-1])
    return _li_specular_arrays(s, o, sigma, n, distribution, masking)


def _li_specular_arrays(s, o, sigma, n, distribution, masking):
    """`li_specular` in numpy, any distribution and masking; s, o unit (..., 3) of one shape."""
    h = s + o
    hn = np.linalg.norm(h, axis=-1, keepdims=True)
    h = h / np.where(hn > 0, hn, 1.0)
    up = _above(s, o)
    f = fresnel_dielectric(np.sum(s * h, axis=-1), n)
    d = distribution_d(h, sigma, distribution)
    g = masking_g(s, o, h, sigma, distribution, masking)
    den = 4.0 * s[..., 2] * o[..., 2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        val = f * d * g / np.where(up, den, 1.0)
    return np.where(up & (d > 0), val, 0.0)


# K_d / (π n_i² (1 − K_d r_i)) of eq 3.15 (the only place K_d enters the single-bounce model): κ itself
li_kd_factor = li_kappa


def li_volume(s, o, kd, sigma, n_i, distribution="beckmann", masking="smith", volume="quadrature", **options):
    """Volume part f_v (eq 3.15) by the chosen evaluation; (...) or (..., C)."""
    s, o = prepare_directions(s, o)
    kd, pc = check_kd(kd)
    up = _above(s, o)
    integral = np.where(up, volume_integral(s, o, sigma, n_i, distribution, masking, volume, **options), 0.0)
    fac = li_kd_factor(kd, n_i, sigma, volume)
    return integral[..., None] * fac if pc else integral * fac


def brdf_li(s, o, kd, sigma, n_i, distribution="beckmann", masking="smith", volume="quadrature",
            interreflection="auto", **options):
    """The interfaced Lambertian (LI) microfacet BRDF (thesis ch. 3, Simonot 2009), in 1/sr.

    Parameters
    ----------
    s, o : (..., 3) unit vectors, local frame (n = +z).
    kd : float or (C,) in [0, 1], substrate reflectance per channel.
    sigma : float ≥ 0 (fits use [0, 2]) or (σ_x, σ_y) for an anisotropic Beckmann/GGX.
    n_i : float in [1, 100] (dielectric fits use [1, 2.5]), relative index of the interface.
    distribution : "beckmann" | "ggx" | "gaussian".   masking : "smith" | "vcavity".
    volume : "quadrature" (reference) | "monte_carlo" | "table" | "approx".
    interreflection : "auto" (V-cavity two-bounce term added when σ ≥ 0.2 and masking is
        "vcavity", with a quadrature/table/MC volume; the approx formula has it built in),
        True, or False. Simulated per call (2048 paths per pair), or read from a table
        built once per (σ, n_i, D) with volume="table".
    **options : passed to the volume evaluation (n_theta, n_phi, n_samples, rng, step_deg).

    Returns
    -------
    (...) or (..., C): f_s (eq 3.10) + f_v (eq 3.15) [+ inter-reflections, §3.2.1].

    Notes
    -----
    K_d = 0 gives the specular microfacet model; n_i = 1 gives Lambertian microfacets
    (Oren–Nayar-like); n_i = 1 and σ = 0 gives Lambert exactly.
    """
    s, o = prepare_directions(s, o)
    kd, pc = check_kd(kd)
    sx, _, _ = check_sigma(sigma, distribution)
    spec = li_specular(s, o, sigma, n_i, distribution, masking)
    vol = li_volume(s, o, kd, sigma, n_i, distribution, masking, volume, **options)
    out = (spec[..., None] if pc else spec) + vol
    if interreflection == "auto":
        interreflection = volume != "approx" and masking == "vcavity" and sx >= INTERREFLECTION_MIN_SIGMA
    if interreflection:
        if masking != "vcavity":
            raise ValueError("inter-reflections are simulated in V-cavities: use masking='vcavity' "
                             "(or interreflection=False)")
        step = options.get("step_deg", 5.0) if volume == "table" else None
        out = out + interreflection_vcavity(s, o, kd, sigma, n_i, distribution, table_step_deg=step)
    return out


def cook_torrance1982(s, o, kd, sigma, n_i, distribution="beckmann", masking="vcavity"):
    """Cook–Torrance: K_d/π + F D G / (4 (s·n)(o·n)) (Lambert + specular microfacets, eq 3.10)."""
    s, o = prepare_directions(s, o)
    kd, pc = check_kd(kd)
    spec = li_specular(s, o, sigma, n_i, distribution, masking)
    diff = _above(s, o).astype(float) / np.pi
    if pc:
        return spec[..., None] + diff[..., None] * kd
    return spec + diff * kd


# The BRDF model names, kept here once (the fit uses them too).
MODELS = Registry("BRDF model")
MODELS.add("lambert", lambert)
MODELS.add("oren_nayar", oren_nayar1994)
MODELS.add("cook_torrance", cook_torrance1982)
MODELS.add("li", brdf_li)


def get(name):
    """The model callable by name: "lambert", "oren_nayar", "cook_torrance" or "li"."""
    return MODELS[name]
