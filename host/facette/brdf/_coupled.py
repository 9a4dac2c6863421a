"""The coupled diffuse part: a Lambertian substrate seen through the lobe's rough interface.

Light reaches the substrate only in the share the interface transmits, and leaves it in the
share the interface lets out: the diffuse part is weighted by t(θ), the rough interface's
transmittance, once towards the light and once towards the camera (Kelemen & Szirmay-Kalos 2001,
"A microfacet based coupled specular-matte BRDF model", Eurographics short papers, §3). Inside, the
substrate's light is diffuse, so in and out are independent: the term is separable,
B = (n·s) t(n·s) t(n·v), with the LI model's interface constants for K_d
(κ = K_d / (π n_i² (1 − K_d r_i)), facette.brdf.li_kappa). The LI volume part (eq 3.15) couples
the two transmissions through the facets' shadowing; this form does not.

The substrate's light that the interface sends back in (the 1 − K_d r_i of κ) is the rough
interface's too: r_i = 2 ∫ E(μ) μ dμ, E(μ) the share the facets reflect back of light meeting them
from inside, single scattering as t(θ) is (`coupled_internal_reflectance`). The LI substrate keeps
the thesis's smooth-interface r_i (eq 3.13, Simonot's n_i² (1 − r_i) = 1 − r_e, which assumes the
interface loses nothing). At σ 0.4, n_i 1.5 the two are 0.495 and 0.596: with the smooth one, K_d
fitted to Mitsuba's rough plastic (whose multiple internal bounces use its own rough interface's
reflectance) came out 4-6 % low, the shortfall this difference predicts (0.943 / 0.952 / 0.962 of
the truth for K_d 0.6 / 0.5 / 0.4 against 0.940 / 0.949 / 0.960 measured).

t(θ) is the single-scattering transmittance of the facets (the visible facets' distribution, the
refracted share 1 − F, and Smith's G_1 of the refracted direction, `lobe_transmittance_beckmann_smith`),
not Kelemen's 1 − E(θ) (E the lobe's directional albedo): 1 − E also counts as transmitted the light
the facets mask after a reflection, a few % at grazing for a broad lobe. Against Mitsuba 3's
`roughplastic` (the same construction, σ 0.4, n_i 1.5) its diffuse part over t(θ_s) t(θ_o) varied by
−2.5 % at grazing to +1.5 % at the normal with 1 − E and is flat to 0.2 % with T; a fit with 1 − E made up
for it with n_i (Mitsuba's rough plastic sphere, the true normals: n_i 1.58 for 1.50).

    coupled_transmittance(sigma, n_i) -> (mu (K,), t (K,))
    coupled_internal_reflectance(sigma, n_i) -> r_i of the rough interface, seen from the substrate
    diffuse_r_i(n_i, sigma, volume) -> the r_i of κ = K_d / (π n_i² (1 − K_d r_i)) for a diffuse part
    coupled_terms(cs, co, sigma, n_i) -> B (N, m) float32
    volume_integral_coupled(s, o, sigma, n_i) -> I = t(θ_s) t(θ_o) (the BRDF fits' volume="coupled")
"""
import functools

import numpy as np

from ._fresnel import check_n_i, r_i_simonot2009
from ._microfacet import microfacet_quadrature
from ._nodes import node_point, nodes_around

__all__ = ["coupled_terms", "coupled_transmittance", "coupled_internal_reflectance", "diffuse_r_i",
           "volume_integral_coupled"]

MU_NODES = 65           # cos θ nodes of t(θ), linear interpolation between them
# half-vector nodes of the albedo's quadrature (n_θ, n_φ of microfacet_quadrature): against 64 × 48,
# at most 0.0015 of t off at σ 0.01-0.5, n_i 1.2-2.0; ~2 ms a node (compiled), computed once
HALF_VECTORS = (32, 24)


@functools.lru_cache(maxsize=512)
def coupled_transmittance(sigma, n_i):
    """(mu, t): the interface's transmittance t(μ) on MU_NODES cosines μ ∈ [0, 1]
    (`_transmittance_node`), combined linearly in log σ and n_i from the nodes around (σ, n_i)
    (facette.brdf._nodes), as the LI volume tables are (facette.brdf.volume_table_at): continuous in
    both for the fits' finite differences, and each node computed once. Read-only arrays, cached
    per (σ, n_i)."""
    t = sum(w * _transmittance_node(i, j) for i, j, w in nodes_around(sigma, check_n_i(n_i)))
    t = np.asarray(t, float)
    mu = np.linspace(0.0, 1.0, MU_NODES)
    mu.setflags(write=False)
    t.setflags(write=False)
    return mu, t


@functools.lru_cache(maxsize=1024)
def _transmittance_node(k, j):
    """t(μ) at the node (σ, n_i) = node_point(k, j) (facette.brdf._nodes; below its first σ the
    interface is taken as that rough: a mirror transmits 1 − F):
    t(i) = ∫ (1 − F(i·h)) D(h) G_1(i) G_1(t) (i·h) / (n·i) dω_h (t the refraction of i through the
    facet h), on the nodes of D(h) (n·h) that the volume quadrature uses
    (facette.brdf.microfacet_quadrature) and the lobe's Smith G_1."""
    from ._lobe_jit import lobe_transmittance_beckmann_smith     # numba: loaded with the first node
    return _on_node(lobe_transmittance_beckmann_smith, k, j)


def _on_node(kernel, k, j):
    """(MU_NODES,) `kernel`(mu, h, w, σ, n_i, out) of facette.brdf._lobe_jit at the node (σ, n_i) =
    node_point(k, j): on MU_NODES cosines, over the half-vectors and weights of D(h) (n·h) that the
    volume quadrature uses (facette.brdf.microfacet_quadrature)."""
    sigma, n = node_point(k, j)
    h, w = microfacet_quadrature(sigma, "beckmann", *HALF_VECTORS)
    mu = np.maximum(np.linspace(0.0, 1.0, MU_NODES), 1e-4)
    out = np.empty(MU_NODES)
    kernel(mu, np.ascontiguousarray(h, float), np.ascontiguousarray(w, float), sigma, float(n), out)
    return out


@functools.lru_cache(maxsize=512)
def coupled_internal_reflectance(sigma, n_i):
    """r_i of the rough interface seen from the substrate: 2 ∫ E(μ) μ dμ over the light the facets
    send back in (`_internal_node`), combined over the nodes around (σ, n_i) as
    `coupled_transmittance` is. A float in [0, 1); the smooth interface's r_i as σ → 0."""
    return float(sum(w * _internal_node(i, j) for i, j, w in nodes_around(sigma, check_n_i(n_i))))


@functools.lru_cache(maxsize=1024)
def _internal_node(k, j):
    """2 ∫ E(μ) μ dμ (trapezoid on MU_NODES cosines) at the node (σ, n_i) = node_point(k, j), E of
    facette.brdf._lobe_jit.lobe_internal_reflectance_beckmann_smith on the quadrature of `_transmittance_node`."""
    from ._lobe_jit import lobe_internal_reflectance_beckmann_smith
    e = _on_node(lobe_internal_reflectance_beckmann_smith, k, j)
    mu = np.maximum(np.linspace(0.0, 1.0, MU_NODES), 1e-4)
    return float(np.trapezoid(2.0 * e * mu, mu))


def diffuse_r_i(n_i, sigma=None, volume=None):
    """The internal reflectance r_i of κ = K_d / (π n_i² (1 − K_d r_i)) for a diffuse part: the rough
    interface's own for the coupled one (volume "coupled", which needs σ; module doc), the thesis's
    smooth-interface r_i (eq 3.13) for the LI substrate (any other volume)."""
    if volume != "coupled":
        return r_i_simonot2009(n_i)
    if sigma is None:
        raise ValueError("the coupled diffuse part's r_i is its rough interface's: give sigma")
    return coupled_internal_reflectance(float(sigma), float(n_i))


def _through(c_in, c_out, sigma, n_i):
    """t(θ_in) t(θ_out) from the cosines (broadcast), 0 where either is ≤ 0."""
    mu, t = coupled_transmittance(float(sigma), float(n_i))
    both = (c_in > 0) & (c_out > 0)
    return np.where(both, np.interp(np.clip(c_in, 0, 1), mu, t) * np.interp(np.clip(c_out, 0, 1), mu, t), 0.0)


def coupled_terms(cs, co, sigma, n_i):
    """B (N, m) float32 = (n·s) t(n·s) t(n·v), 0 where n·s ≤ 0 or n·v ≤ 0; cs (N, m) the
    cosines n·s, co (N,) n·v (`coupled_transmittance`)."""
    cs = np.asarray(cs, np.float32)
    return (np.clip(cs, 0, 1) * _through(cs, np.asarray(co, np.float32).reshape(-1, 1), sigma, n_i)).astype(np.float32)


def volume_integral_coupled(s, o, sigma, n_i, distribution="beckmann", masking="smith"):
    """The coupled diffuse part as a volume integral of the LI form (B = (n·s) I, κ as eq 3.15):
    I = t(θ_s) t(θ_o) for local-frame unit directions s, o (..., 3), z the normal; 0 below the
    surface. Beckmann and Smith only (the transmittance's quadrature)."""
    if distribution != "beckmann" or masking != "smith":
        raise ValueError(f"volume 'coupled' is computed for a Beckmann lobe with Smith masking, got "
                         f"{distribution!r} / {masking!r}: use volume='tables' or 'quadrature'")
    return _through(np.asarray(s, float)[..., 2], np.asarray(o, float)[..., 2], sigma, n_i)
