"""Directional albedo ρ(s) = ∫ f(s, o) (o·n) dω_o of the LI model (energy conservation, eq 3.2)."""
import numpy as np

from ._fresnel import fresnel_dielectric
from ._microfacet import masking_g, microfacet_quadrature, check_sigma
from ._models import li_kd_factor, prepare_directions
from ._volume import volume_integral

__all__ = ["directional_albedo"]


def directional_albedo(s, kd, sigma, n_i, distribution="beckmann", masking="smith", volume="quadrature",
                       n_theta_o=16, n_phi_o=32, **options):
    """Directional albedo of the single-bounce LI model for incident directions s (..., 3) -> (...).

    Specular part: over half-vectors with the D-following nodes (so a σ → 0 lobe is exact):
    ρ_s = ∫ F(s·h) G(s, o, h) (s·h) / ((s·n)(h·n)) D(h)(h·n) dω_h, o the mirror of s about h.
    Volume part: Gauss–Legendre in cos²θ_o × uniform φ_o (cosine-weighted) of f_v.
    Scalar kd only. A value ≤ 1 is what eq 3.2 demands.
    """
    s, _ = prepare_directions(s, np.array([0.0, 0.0, 1.0]))
    sx, sy, iso = check_sigma(sigma, distribution)
    sig = sx if iso else (sx, sy)
    m, w = microfacet_quadrature(sig, distribution, 64, 64)
    shape = s.shape[:-1]
    s2 = s.reshape(-1, 1, 3)
    sh = np.sum(s2 * m[None], axis=-1)
    o = 2.0 * sh[..., None] * m[None] - s2
    g = masking_g(s2, o, m[None], sig, distribution, masking)
    with np.errstate(divide="ignore", invalid="ignore"):
        term = fresnel_dielectric(sh, n_i) * g * sh / (s2[..., 2] * m[None, :, 2])
    ok = (sh > 0) & (o[..., 2] > 0) & (s2[..., 2] > 0)
    rho_s = np.where(ok, term, 0.0) @ w
    # volume part: o = cosine-weighted nodes, ∫ f_v (o·n) dω = π ∫∫ f_v dξ1 dξ2
    x, wx = np.polynomial.legendre.leggauss(int(n_theta_o))
    xi1 = 0.5 * (x + 1.0)
    phi = 2 * np.pi * (np.arange(int(n_phi_o)) + 0.5) / int(n_phi_o)
    r = np.sqrt(xi1)[:, None]
    oo = np.stack([r * np.cos(phi), r * np.sin(phi), np.broadcast_to(np.sqrt(1 - xi1)[:, None], (len(xi1), len(phi)))],
                  axis=-1).reshape(-1, 3)
    wo = (np.pi * 0.5 * wx[:, None] / len(phi) * np.ones((1, len(phi)))).reshape(-1)
    vals = volume_integral(s2, oo[None], sig, n_i, distribution, masking, volume, **options)
    rho_v = (vals @ wo) * li_kd_factor(float(kd), n_i, sig, volume)
    return (rho_s + rho_v).reshape(shape)
