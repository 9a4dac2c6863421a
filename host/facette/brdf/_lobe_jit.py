"""The specular lobe's pieces (eq 3.10) as compiled scalar functions (numba), for the per-pixel and
per-pair kernels that evaluate it inside their loops: facette.fit._normals_li_jit (the per-pixel
solve) and facette.recon._interreflect_jit (the glossy gather), and the lobe's albedo for the coupled
diffuse part (facette.brdf._coupled). The array forms are
facette.brdf._shading (`li_shading_terms`) and facette.brdf._fresnel (`fresnel_dielectric`).

Loaded only with those kernels (numba is imported here). numba's cache keys a kernel on its own
file: after editing this one, clear the kernels' __pycache__/*.nbc so that they recompile with it.
"""
import math

import numpy as np
from numba import njit

__all__ = ["G1_ONE_ABOVE", "SMITH_G1_TABLE", "smith_g1_beckmann", "smith_g1_dlog_tabulated", "smith_g1_dlog_scaled", "beckmann_d",
           "fresnel_dielectric_scalar", "li_specular_beckmann_smith",
           "lobe_transmittance_beckmann_smith", "lobe_internal_reflectance_beckmann_smith"]

_SQRT_PI = math.sqrt(math.pi)
# Smith's Λ(a) < e^(−a²) / (2√π a) < 1e-17 above a = 6, so G_1 = 1 / (1 + Λ) is 1.0 to the last bit
# of a float64 (and d ln G_1 / dc below 1e-16): exp and erfc are skipped there. That is most
# lights at σ ≤ 0.3 (a = cot θ / σ); the per-pixel solve: 0.86× its time, the same normals to the bit
G1_ONE_ABOVE = 6.0


@njit(cache=True)
def smith_g1_beckmann(c, sigma):
    """Smith G_1 for Beckmann (eq 3.20) at cosine c to the normal: 0 at c ≤ 0, 1 at the normal."""
    if c <= 0.0:
        return 0.0
    if c > 1.0:
        c = 1.0
    sn = math.sqrt(max(1.0 - c * c, 0.0))
    if sn <= 0.0:
        return 1.0
    a = c / (sigma * sn)
    if a > G1_ONE_ABOVE:
        return 1.0
    lam = 0.5 * (math.exp(-a * a) / (a * _SQRT_PI) - math.erfc(a))
    return 1.0 / (1.0 + lam)


SMITH_G1_TABLE_SIZE = 16385     # points of `SMITH_G1_TABLE` over a ∈ [0, G1_ONE_ABOVE]


def smith_g1_table(size=SMITH_G1_TABLE_SIZE):
    """(size,): G_1 / a at a = c / (σ sin θ) evenly over [0, G1_ONE_ABOVE] (Smith's Beckmann G_1
    depends on a alone; G_1 / a is smooth and → 2√π at a = 0, where G_1 itself bends)."""
    a = np.linspace(0.0, G1_ONE_ABOVE, size)
    tab = np.empty(size)
    tab[0] = 2.0 * _SQRT_PI
    for j in range(1, size):
        tab[j] = 1.0 / (a[j] * (1.0 + 0.5 * (math.exp(-a[j] * a[j]) / (a[j] * _SQRT_PI) - math.erfc(a[j]))))
    return tab


SMITH_G1_TABLE = smith_g1_table()


@njit(cache=True)
def smith_g1_dlog_tabulated(c, sigma, g1tab):
    """(G_1, d ln G_1 / dc) at cosine c, G_1 linear in a between the points of `smith_g1_table`
    (within 1e-7 of `smith_g1_beckmann`; exp and erfc per light were a fifth of the per-pixel
    solve's time). The derivative is the tabulated G_1's own, so that a Jacobian built on it is
    that of the values compared: d(a T)/da = T + a T', da/dc = a / (c sin² θ)."""
    if c <= 0.0:
        return 0.0, 0.0
    if c > 1.0:
        c = 1.0
    sn = math.sqrt(max(1.0 - c * c, 0.0))
    if sn <= 0.0:
        return 1.0, 0.0
    a = c / (sigma * sn)
    if a >= G1_ONE_ABOVE:
        return 1.0, 0.0
    step = G1_ONE_ABOVE / (g1tab.shape[0] - 1)
    j = int(a / step)
    w = a / step - j
    slope = (g1tab[j + 1] - g1tab[j]) / step
    t = g1tab[j] + w * (g1tab[j + 1] - g1tab[j])
    return a * t, (t + a * slope) / (t * c * sn * sn)


SMITH_G1_INV_STEP = (SMITH_G1_TABLE_SIZE - 1) / G1_ONE_ABOVE     # 1 / the spacing of `SMITH_G1_TABLE`'s points


@njit(cache=True)
def smith_g1_dlog_scaled(c, inv_sigma, g1tab):
    """`smith_g1_dlog_tabulated` with 1 / σ given and `SMITH_G1_TABLE`'s spacing (g1tab must be that
    table's size): two divisions fewer per call, for the per-pixel solve's loop over lights."""
    if c <= 0.0:
        return 0.0, 0.0
    if c > 1.0:
        c = 1.0
    sn = math.sqrt(max(1.0 - c * c, 0.0))
    if sn <= 0.0:
        return 1.0, 0.0
    a = c * inv_sigma / sn
    if a >= G1_ONE_ABOVE:
        return 1.0, 0.0
    x = a * SMITH_G1_INV_STEP
    j = int(x)
    w = x - j
    slope = (g1tab[j + 1] - g1tab[j]) * SMITH_G1_INV_STEP
    t = g1tab[j] + w * (g1tab[j + 1] - g1tab[j])
    return a * t, (t + a * slope) / (t * c * sn * sn)


@njit(cache=True)
def beckmann_d(ch2, s2):
    """Beckmann D (table 3.1) from cos² θ_h (> 0) and σ²."""
    tan2 = (1.0 - ch2) / ch2
    return math.exp(-tan2 / s2) / (math.pi * s2 * ch2 * ch2)


@njit(cache=True)
def fresnel_dielectric_scalar(c, eta):
    """`facette.brdf.fresnel_dielectric` for one cosine c ∈ [0, 1], with eta = n_i² − 1."""
    if eta == 0.0:
        return 0.0
    g = math.sqrt(eta + c * c)
    gpc = g + c
    gmc = eta / gpc
    a = gmc / gpc
    return 0.5 * a * a * (1.0 + ((c * gpc - 1.0) / (c * gmc + 1.0)) ** 2)


@njit(cache=True, nogil=True)
def li_specular_beckmann_smith(s, o, sigma, eta, out):
    """`facette.brdf.li_specular` (eq 3.10) for Beckmann D and Smith G (eq 3.18, 3.20), isotropic
    σ > 0, over the rows of s, o (N, 3) unit vectors; eta = n_i² − 1; out (N,). One pass with no
    temporaries: the BRDF fit evaluates it on every sample and cell direction at each step."""
    for i in range(s.shape[0]):
        out[i] = 0.0
        sz, oz = s[i, 2], o[i, 2]
        if sz <= 0.0 or oz <= 0.0:
            continue
        hx, hy, hz = s[i, 0] + o[i, 0], s[i, 1] + o[i, 1], sz + oz
        hn = math.sqrt(hx * hx + hy * hy + hz * hz)
        sm = (s[i, 0] * hx + s[i, 1] * hy + sz * hz) / hn
        om = (o[i, 0] * hx + o[i, 1] * hy + oz * hz) / hn
        if sm <= 0.0 or om <= 0.0:
            continue
        out[i] = li_specular_half(sz, oz, hz / hn, sm, sigma, eta)


@njit(cache=True, nogil=True)
def li_specular_half(cs, co, ch, sh, sigma, eta):
    """`li_specular_beckmann_smith` of one pair from its cosines: cs = n·s > 0, co = n·o > 0,
    ch = n·h, sh = s·h > 0 (h the half-vector); 0 where D underflows."""
    d = beckmann_d(ch * ch, sigma * sigma)
    if not d > 0.0:
        return 0.0
    g = smith_g1_beckmann(cs, sigma) * smith_g1_beckmann(co, sigma)
    return fresnel_dielectric_scalar(min(sh, 1.0), eta) * d * g / (4.0 * cs * co)


@njit(cache=True, nogil=True)
def lobe_transmittance_beckmann_smith(mu, h, w, sigma, n_i, out):
    """The share of light the rough interface transmits into the substrate,
    T(μ) = Σ_h w (1 − F(i·h)) G_1(i) G_1(t) (i·h) / (μ h_z), at each cosine μ of `mu` (K,),
    i = (√(1 − μ²), 0, μ), t the refraction of i through the facet h (into the medium of index n_i,
    Snell), over the half-vectors h (S, 3) with weights w (S,) (D(h) h_z folded in: the visible facets' distribution
    D(h) G_1(i) (i·h) / μ, Walter et al. 2007) of facette.brdf._coupled._transmittance_node. Single
    scattering: the light the facets mask after a reflection is not counted as transmitted (1 − E,
    E the lobe's directional albedo, does count it). Into out (K,), one pass, no temporaries.
    n_i = 1 is no interface: everything gets through (the nodes above it interpolate towards it)."""
    if n_i <= 1.0:
        out[:] = 1.0
        return
    _interface_share(mu, h, w, sigma, n_i, False, out)


@njit(cache=True, nogil=True)
def lobe_internal_reflectance_beckmann_smith(mu, h, w, sigma, n_i, out):
    """The share of the substrate's light the rough interface sends back into it,
    E(μ) = Σ_h w F_in(i·h) G_1(i) G_1(o) (i·h) / (μ h_z), at each cosine μ of `mu` (K,), the light
    meeting the interface from inside (i = (√(1 − μ²), 0, μ) in the frame whose z points into the
    substrate), o the mirror of i about the facet h, F_in Fresnel from index n_i into air (1 beyond
    the critical angle); h, w as `lobe_transmittance_beckmann_smith`. Single scattering, as that
    transmittance: what the facets mask is lost, not reflected. Into out (K,). n_i = 1: nothing."""
    if n_i <= 1.0:
        out[:] = 0.0
        return
    _interface_share(mu, h, w, sigma, n_i, True, out)


@njit(cache=True, nogil=True)
def _interface_share(mu, h, w, sigma, n_i, inside, out):
    """Σ_h w S G_1(i) (i·h) / (μ h_z) at each cosine μ of `mu`, i = (√(1 − μ²), 0, μ), over the
    half-vectors h with weights w: S = (1 − F(i·h)) G_1(t), t the refraction of i into the medium
    of index n_i (inside False: `lobe_transmittance_beckmann_smith`), or S = F_in(i·h) G_1(o), o the
    mirror of i about h and F_in Fresnel from the medium into air, 1 beyond the critical angle
    (inside True: `lobe_internal_reflectance_beckmann_smith`). Clipped to [0, 1], into out."""
    eta = 1.0 / (n_i * n_i) - 1.0 if inside else n_i * n_i - 1.0    # fresnel_dielectric_scalar's n² − 1
    for k in range(mu.shape[0]):
        m = mu[k]
        sx = math.sqrt(max(1.0 - m * m, 0.0))
        gi = smith_g1_beckmann(m, sigma)
        tot = 0.0
        for j in range(h.shape[0]):
            ih = sx * h[j, 0] + m * h[j, 2]
            if ih <= 0.0:
                continue
            c = min(ih, 1.0)
            if inside:
                oz = 2.0 * ih * h[j, 2] - m
                if oz <= 0.0:
                    continue
                f = 1.0 if eta + c * c <= 0.0 else fresnel_dielectric_scalar(c, eta)
                share = f * smith_g1_beckmann(oz, sigma)
            else:
                # refracted t = −i / n + (c / n − √(1 − (1 − c²) / n²)) h; its z (< 0: into the substrate)
                root = math.sqrt(max(1.0 - (1.0 - ih * ih) / (n_i * n_i), 0.0))
                tz = -m / n_i + (ih / n_i - root) * h[j, 2]
                if tz >= 0.0:
                    continue
                share = (1.0 - fresnel_dielectric_scalar(c, eta)) * smith_g1_beckmann(-tz, sigma)
            tot += w[j] * share * gi * ih / (m * h[j, 2])
        out[k] = min(max(tot, 0.0), 1.0)
