"""The volume part of the interfaced Lambertian model (eq 3.15) and its four evaluations.

f_v(s, o) = K_d / (π n_i² (1 − K_d r_i)) · I(s, o; σ, n_i, D, G), with the K_d-free integral

    I(s, o) = ∫ T(s, m) T(o, m) D(m) G(s, o, m) (s·m)(o·m) / ((s·n)(o·n)) dω_m.

Everything that depends on K_d is the scalar factor in front, so I is what is integrated,
sampled, tabulated and approximated here: a table built once per (σ, n_i, D, G) serves every
K_d and every colour channel at the cost of one multiplication.

Methods: ``quadrature`` (deterministic, the reference), ``monte_carlo`` (importance sampling
eq 3.27), ``table`` (§3.2.2, trilinear in (θ_s, θ_o, |φ_o − φ_s|)), ``tables`` (node tables
on a (σ, n_i) grid, interpolated: continuous in both, for fits) and ``approx``
(eq 3.49–3.57, Beckmann or Gaussian constants of tables 3.3–3.5; 3–5 % off the integral at the
median, 13–45 % at the 99th percentile, 3.7 % even at σ → 0, n_i = 1, where I = 1).
"""
import functools

import numpy as np

from facette._registry import Registry

from ._coupled import volume_integral_coupled
from ._fresnel import check_n_i, fresnel_dielectric, r_e_molenaar1999
from ._nodes import node_point, nodes_around
from ._microfacet import (check_masking, check_sigma, masking_g, microfacet_quadrature,
                          sample_microfacet_normals, smith_g1)

__all__ = ["VOLUME_METHODS", "volume_integral", "volume_integral_quadrature", "volume_integral_monte_carlo",
           "volume_integral_table", "volume_integral_tables", "volume_integral_approx", "VolumeTable",
           "build_volume_table", "volume_table_at"]

_CHUNK_ELEMENTS = 400_000  # pairs × nodes per temporary array (keeps memory ~ tens of MB)


def check_volume_config(sigma, n_i, distribution, masking):
    sx, sy, iso = check_sigma(sigma, distribution)
    n = check_n_i(n_i)
    check_masking(masking)
    if distribution == "gaussian" and masking == "smith" and sx > 0:
        raise ValueError(
            "distribution='gaussian' with masking='smith': the Gaussian of table 3.1 has "
            "D ~ 1/cos θ_m at grazing facets, and with Smith's G (no cos θ_m factor, unlike the "
            "V-cavity) the volume integral eq 3.15 diverges logarithmically. Use masking='vcavity' "
            "(as the thesis pairs them) or distribution='beckmann'")
    return sx, sy, iso, n


def _integrand(s, o, m, sigma, n, distribution, masking):
    """h(m) with I = ∫ h(m) D(m)(m·n) dω: T T G (s·m)(o·m) / ((m·n)(s·n)(o·n)). s, o (P,1,3); m (K,3)."""
    sm = np.sum(s * m, axis=-1)
    om = np.sum(o * m, axis=-1)
    g = masking_g(s, o, m, sigma, distribution, masking)
    ts = 1.0 - fresnel_dielectric(sm, n)
    to = 1.0 - fresnel_dielectric(om, n)
    mz = m[..., 2]
    den = mz * s[..., 2] * o[..., 2]
    ok = (g > 0) & (den > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = ts * to * g * sm * om / np.where(ok, den, 1.0)
    return np.where(ok, h, 0.0)


def _flat_pairs(s, o):
    s, o = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(o, dtype=float))
    shape = s.shape[:-1]
    return s.reshape(-1, 3), o.reshape(-1, 3), shape


def volume_integral_quadrature(s, o, sigma, n_i, distribution="beckmann", masking="smith",
                               n_theta=48, n_phi=48):
    """I(s, o) by deterministic quadrature over m (the reference).

    Nodes: ``microfacet_quadrature`` (Gauss–Legendre in the CDF of D × uniform in φ_m),
    n_theta × n_phi of them. Its error shrinks fast with the node count until the kinks of
    G and of the visibility χ⁺ limit it (about 1e-4 relative at 48 × 48, 1e-5 at 128 × 128;
    see ``facette bench brdf``). s, o: (..., 3) unit vectors above the horizon; returns (...).
    """
    sx, sy, iso, n = check_volume_config(sigma, n_i, distribution, masking)
    sig = sx if iso else (sx, sy)
    m, w = microfacet_quadrature(sig, distribution, int(n_theta), int(n_phi))
    s2, o2, shape = _flat_pairs(s, o)
    out = np.zeros(len(s2))
    step = max(1, _CHUNK_ELEMENTS // len(w))
    for a in range(0, len(s2), step):
        h = _integrand(s2[a:a + step, None, :], o2[a:a + step, None, :], m[None], sig, n, distribution, masking)
        out[a:a + step] = h @ w
    return out.reshape(shape)


def volume_integral_monte_carlo(s, o, sigma, n_i, distribution="beckmann", masking="smith",
                                n_samples=256, rng=None):
    """I(s, o) by importance sampling of m with pdf D(m)(m·n) (eq 3.27, 3.33–3.36).

    Each (s, o) pair gets its own n_samples normals; the error is ∝ n_samples^-1/2.
    ``rng``: numpy Generator or seed (default seed 0: repeatable).
    """
    sx, sy, iso, n = check_volume_config(sigma, n_i, distribution, masking)
    sig = sx if iso else (sx, sy)
    rng = np.random.default_rng(0 if rng is None else rng)
    s2, o2, shape = _flat_pairs(s, o)
    out = np.zeros(len(s2))
    ns = int(n_samples)
    if ns < 1:
        raise ValueError(f"n_samples = {n_samples}: need at least 1 sample per evaluation")
    step = max(1, _CHUNK_ELEMENTS // ns)
    for a in range(0, len(s2), step):
        b = min(len(s2), a + step)
        m, wt = sample_microfacet_normals(rng.random((b - a, ns)), rng.random((b - a, ns)), sig, distribution)
        h = _integrand(s2[a:b, None, :], o2[a:b, None, :], m, sig, n, distribution, masking)
        out[a:b] = np.mean(h * wt, axis=-1)
    return out.reshape(shape)


def _angles(s, o):
    """θ_s, θ_o (rad) and Δφ = |φ_o − φ_s| folded into [0, π] (isotropy), plus cos Δφ."""
    ts = np.arccos(np.clip(s[..., 2], -1.0, 1.0))
    to = np.arccos(np.clip(o[..., 2], -1.0, 1.0))
    rs = np.hypot(s[..., 0], s[..., 1])
    ro = np.hypot(o[..., 0], o[..., 1])
    both = (rs > 1e-12) & (ro > 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        cphi = (s[..., 0] * o[..., 0] + s[..., 1] * o[..., 1]) / np.where(both, rs * ro, 1.0)
    cphi = np.where(both, np.clip(cphi, -1.0, 1.0), 1.0)  # φ undefined at the normal: any value works
    return ts, to, np.arccos(cphi), cphi


class VolumeTable:
    """I tabulated on a regular grid θ_s, θ_o ∈ [0°, 90°], Δφ ∈ [0°, 180°] (§3.2.2).

    ``values`` has shape (n_θ, n_θ, n_φ) and holds I · cos θ_s · cos θ_o; ``__call__(s, o)``
    interpolates it trilinearly (linear in θ_s of bilinear in (θ_o, Δφ), as figure 3.24) and
    divides by cos θ_s cos θ_o interpolated with the same weights (so a constant I, e.g.
    Lambert, comes back exactly). Why the cosines: with V-cavity masking I grows like
    1/cos θ when s and o both graze (as Oren–Nayar's tan β term), and a table of I itself
    spreads that into the last cell (errors of 1000 % at 80–89° with a 10° step); the weighted
    values go to 0 linearly at 90°, where linear interpolation is right. Isotropic only.
    """

    def __init__(self, step_deg, values, key, theta_deg=None):
        self.step_deg = float(step_deg)
        self.values = values
        self.key = key
        nt = values.shape[0]
        th = np.arange(nt) * self.step_deg if theta_deg is None else np.asarray(theta_deg, dtype=float)
        self.theta = np.radians(th)  # θ nodes (both θ_s and θ_o), last one 90°
        self._cos = np.cos(self.theta)
        self._cos[-1] = 0.0
        self._cast = {}

    def __call__(self, s, o):
        ts, to, dphi, _ = _angles(np.asarray(s, dtype=float), np.asarray(o, dtype=float))
        return self.at_angles(ts, to, dphi)

    def at_angles(self, ts, to, dphi):
        """I at θ_s, θ_o (rad) and Δφ ∈ [0, π] (arrays that broadcast together), computed in
        float32 when the angles are float32 (the per-pixel terms), else float64."""
        dt = np.float32 if np.asarray(ts).dtype == np.float32 else np.float64
        flat, th, inv, c = self._arrays(dt)
        nt, _, nph = self.values.shape

        def axis(x):      # cell index and weight of the upper node along θ; the cell's two cosines
            x = np.asarray(x, dt)
            i0 = np.clip(np.searchsorted(th, x, side="right") - 1, 0, nt - 2)
            f = np.clip((x - th[i0]) * inv[i0], 0, 1)
            return i0, f, (1 - f) * c[i0] + f * c[i0 + 1]

        i, fi, ci = axis(ts)
        j, fj, cj = axis(to)
        u = np.clip(np.asarray(dphi, dt) * dt(1 / np.radians(self.step_deg)), 0, nph - 1)
        k = np.minimum(u.astype(np.int64), nph - 2)
        fk = u - k
        base = (i * nt + j) * nph + k

        def along_phi(off):
            return flat[base + off] * (1 - fk) + flat[base + off + 1] * fk

        num = ((1 - fi) * ((1 - fj) * along_phi(0) + fj * along_phi(nph))
               + fi * ((1 - fj) * along_phi(nt * nph) + fj * along_phi(nt * nph + nph)))
        den = ci * cj     # the cosines' weights are separable: Σ w_i w_j c_i c_j = (Σ w_i c_i)(Σ w_j c_j)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1), 0).astype(dt, copy=False)

    def kernel_arrays(self):
        """(values raveled, θ nodes, 1 / cell widths, cos θ nodes, n_φ, 1 / Δφ step) in float64:
        what the compiled evaluation (facette.brdf._volume_jit) reads."""
        return (*self._arrays(np.float64), self.values.shape[2], 1 / np.radians(self.step_deg))

    def _arrays(self, dt):
        """(values raveled, θ nodes, 1 / cell widths, cos θ nodes) in dtype dt, made once."""
        key = np.dtype(dt).name
        got = self._cast.get(key)
        if got is None:
            th = self.theta.astype(dt)
            got = (np.ascontiguousarray(self.values, dt).ravel(), th,
                   (1 / np.diff(self.theta)).astype(dt), self._cos.astype(dt))
            self._cast[key] = got
        return got


def check_table_step(step_deg):
    step = float(step_deg)
    if not 0.5 <= step <= 30 or abs(90 / step - round(90 / step)) > 1e-9:
        raise ValueError(f"step_deg = {step_deg}: choose a step in [0.5°, 30°] that divides 90°")
    return step


def table_theta_nodes(step_deg, grazing_refine=1):
    """θ nodes (deg) of a table: every step_deg up to 90° − 3 step, then step/grazing_refine to 90°.

    The volume part changes fastest near grazing (Fresnel transmission and masking go to 0 there),
    where a uniform 5° grid leaves errors of 10–20 %; refining the last three cells costs little.
    """
    step = check_table_step(step_deg)
    r = int(grazing_refine)
    if r < 1:
        raise ValueError(f"grazing_refine = {grazing_refine}: use an integer ≥ 1 (1 = the uniform grid)")
    nt = int(round(90 / step))
    if r == 1 or nt < 4:
        return np.arange(nt + 1) * step
    knee = (nt - 3) * step
    return np.concatenate([np.arange(nt - 3) * step, knee + np.arange(3 * r + 1) * step / r])


def tabulate_isotropic(fn, step_deg, key=None, grazing_refine=1):
    """VolumeTable of fn(s, o) (K_d-free, isotropic) on θ_s, θ_o ∈ [0, 90°] (``table_theta_nodes``)
    × Δφ ∈ [0, 180°] every step_deg."""
    step = check_table_step(step_deg)
    th_deg = table_theta_nodes(step, grazing_refine)
    nt = len(th_deg)
    nphi = int(round(180 / step)) + 1
    th = np.radians(np.minimum(th_deg, 90.0 - 0.01))
    ph = np.radians(np.arange(nphi) * step)
    s = np.stack([np.sin(th), np.zeros(nt), np.cos(th)], axis=-1)[:, None, None, :]
    o = np.stack([np.sin(th)[:, None] * np.cos(ph)[None, :], np.sin(th)[:, None] * np.sin(ph)[None, :],
                  np.broadcast_to(np.cos(th)[:, None], (nt, nphi))], axis=-1)[None, :, :, :]
    values = np.asarray(fn(s, o), dtype=float).reshape(nt, nt, nphi)
    values = values * np.cos(th)[:, None, None] * np.cos(th)[None, :, None]
    values[-1, :, :] = 0.0  # the limit at θ = 90° (cos θ · I → 0)
    values[:, -1, :] = 0.0
    values.setflags(write=False)
    return VolumeTable(step, values, key, th_deg)


@functools.lru_cache(maxsize=128)
def build_volume_table(sigma, n_i, distribution="beckmann", masking="smith", step_deg=5.0,
                       n_theta=24, n_phi=32, grazing_refine=4):
    """Tabulate I every ``step_deg`` degrees by quadrature (cached per arguments).

    grazing_refine : the last three θ cells (75–90° at 5°) are split in this many (1 = the
    thesis's uniform grid). At 5° it takes the worst error from ~10–20 % to ~1.5–3 % for
    twice the build time (``facette bench brdf``).

    Cost: (90/step + 1)² (180/step + 1) quadratures with n_theta × n_phi nodes; reciprocity
    (I(s, o) = I(o, s)) is not exploited.
    """
    sx, sy, iso, n = check_volume_config(sigma, n_i, distribution, masking)
    if not iso:
        raise ValueError("volume='table' assumes an isotropic distribution (a table over θ_s, θ_o, "
                         "φ_o); use volume='quadrature' or 'monte_carlo' for an anisotropic sigma pair")
    if masking == "smith":
        def fn(s, o):   # every (s, o) of the grid: one matrix product (`_quadrature_all_pairs`)
            return _quadrature_all_pairs(s.reshape(-1, 3), o.reshape(-1, 3), sx, n, distribution,
                                         n_theta, n_phi).reshape(np.broadcast_shapes(s.shape, o.shape)[:-1])
    else:
        def fn(s, o):
            return volume_integral_quadrature(s, o, sx, n, distribution, masking, n_theta, n_phi)
    return tabulate_isotropic(fn, step_deg, (sx, n, distribution, masking), grazing_refine)


def _quadrature_all_pairs(s, o, sigma, n, distribution, n_theta, n_phi):
    """(P, Q) I of `volume_integral_quadrature` (Smith masking) for every s (P, 3) with every o (Q, 3).

    Smith's G = G_1(s) G_1(o) χ⁺(s·m) χ⁺(o·m) does not depend on m but through χ⁺, so the
    integrand factors: I = G_1(s) G_1(o) / (s_z o_z) Σ_k (w_k / m_z) [T(s·m) (s·m)⁺]_k [T(o·m) (o·m)⁺]_k,
    one matrix product over the nodes (the same sum, ~100× faster for a table)."""
    m, w = microfacet_quadrature(sigma, distribution, int(n_theta), int(n_phi))

    from ._volume_jit import transmitted_cosines     # numba loads only when a table is built

    def side(u):        # (1 − F(u·m)) (u·m)⁺ for every u and node m
        out = np.empty((len(u), len(m)))
        transmitted_cosines(np.ascontiguousarray(u, float), np.ascontiguousarray(m, float), (n - 1.0) * (n + 1.0), out)
        return out

    a, b = side(s), side(o)
    g_s = np.where(s[:, 2] > 0, smith_g1(s, sigma, distribution) / np.maximum(s[:, 2], 1e-300), 0.0)
    g_o = np.where(o[:, 2] > 0, smith_g1(o, sigma, distribution) / np.maximum(o[:, 2], 1e-300), 0.0)
    return g_s[:, None] * ((a * (w / m[:, 2])) @ b.T) * g_o[None, :]


def volume_integral_table(s, o, sigma, n_i, distribution="beckmann", masking="smith", step_deg=5.0,
                          grazing_refine=4):
    """I(s, o) from a cached table (built on first use for these σ, n_i, D, G, step, refinement)."""
    sx, sy, iso, n = check_volume_config(sigma, n_i, distribution, masking)
    return build_volume_table(sx if iso else (sx, sy), n, distribution, masking, float(step_deg), 24, 32,
                              int(grazing_refine))(s, o)


# Node tables of `volume_table_at`: eq 3.15 by quadrature every NODE_STEP_DEG (the last three
# θ cells split in two) on the grid of (σ, n_i) of facette.brdf._nodes. Measured on 4000 random
# pairs above 6° elevation (σ, n_i = 0.05-0.2, 1.26-1.5) against the 48 × 48 quadrature: 5° and
# 16 × 24 nodes builds in 0.03-0.05 s, 0.05 % off at the median and 1.3-1.7 % at the 99th percentile (10° and 16 × 16:
# 0.005 s, 0.1 % and 5 %; 5° and 24 × 32, refined by 4: 0.08-0.12 s, 0.03 % and 0.3-0.9 %),
# against 3-5 % and 13-45 % for the approximate formula eq 3.49-3.57
NODE_STEP_DEG = 5.0
NODE_QUADRATURE = (16, 24, 2)   # n_theta, n_phi of the quadrature; grazing refinement of θ


@functools.lru_cache(maxsize=256)
def volume_table_at(sigma, n_i, distribution="beckmann", masking="smith"):
    """VolumeTable of eq 3.15 at any (σ, n_i), for fits that move both continuously.

    The node tables around (σ, n_i) (quadrature, `build_volume_table`, cached) are combined
    linearly in log σ and in n_i: the result is continuous in both, so a finite-difference
    Jacobian sees the model and not the grid, and it costs one table evaluation (interpolation
    is linear in the table's values). Isotropic σ only."""
    sx, sy, iso, n = check_volume_config(sigma, n_i, distribution, masking)
    if not iso:
        raise ValueError("volume='tables' assumes an isotropic distribution; use 'quadrature' for a sigma pair")
    values, first = 0.0, None
    for i, j, w in nodes_around(sx, n):       # the node grid (facette.brdf._nodes)
        node = build_volume_table(*node_point(i, j), distribution, masking, NODE_STEP_DEG, *NODE_QUADRATURE)
        first = first or node
        values = values + w * node.values
    values = np.asarray(values, dtype=float)
    values.setflags(write=False)
    return VolumeTable(NODE_STEP_DEG, values, (sx, n, distribution, masking, "nodes"), np.degrees(first.theta))


def volume_integral_tables(s, o, sigma, n_i, distribution="beckmann", masking="smith"):
    """I(s, o) of eq 3.15 from the node tables around (σ, n_i) (`volume_table_at`)."""
    return volume_table_at(sigma, n_i, distribution, masking)(s, o)


# Tables 3.3 (Beckmann) and 3.4 (Gaussian): rational fractions in σ and n_i (eq 3.53–3.55).
_APPROX_ABC = {
    "beckmann": dict(a=(0.8835, 6.84, -2.821, 0.8821, 8.421, 29.312),
                     b=(-1.252, 203.341, -313.617, 57.04, 73.376, -252.889),
                     c=(0.2623, -50.2477, 379.377, -89.235, 146.273, -36.1669,
                        1.2746, -7.303, -19.669, 25.3924, -17.6218, -8.951)),
    "gaussian": dict(a=(12.006, -19.028, 7.571, 11.99, 31.336, -10.886),
                     b=(-6.378, 3113.067, -291.368, 698.885, 2083.959, 64.749),
                     c=(0.0162, 16.044, 88.159, -58.829, 79.44, -17.7189,
                        -1.159, -0.3348, -28.214, 1.164, 2.12, -3.298)),
}
# Table 3.5: constants A…M of the Beckmann rough-Lambertian term.
_T35 = dict(A=7.07944, B=8.66467, C=11.4317, D=8.34372, E=169.905, F=21.7364, G=179.001,
            H=222.806, I=13.7846, J=345.335, K=1024.89, L=1125.28, M=1623.54)


def approx_coefficients(sigma, n_i, distribution):
    """(a, b, c) of eq 3.53–3.55 for the Beckmann or Gaussian variant."""
    k = _APPROX_ABC[distribution]
    s = sigma
    a = (k["a"][0] + k["a"][1] * s + k["a"][2] * s * s) / (k["a"][3] + k["a"][4] * s + k["a"][5] * s * s)
    b = (k["b"][0] + k["b"][1] * s + k["b"][2] * s * s) / (k["b"][3] + k["b"][4] * s + k["b"][5] * s * s)
    c_ = k["c"]
    c = ((c_[0] + c_[1] * s + c_[2] * s * s) * (c_[3] + c_[4] * n_i + c_[5] * n_i * n_i)
         / ((c_[6] + c_[7] * s + c_[8] * s * s) * (c_[9] + c_[10] * n_i + c_[11] * n_i * n_i)))
    return a, b, c


def rough_lambert_terms(ts, to, cphi, sigma, distribution):
    """Bracket of eq 3.56, [C1 + C2 cos Δφ tan β + C3 (1 − |cos Δφ|) tan((α+β)/2)].

    Gaussian: eq 3.57 (Oren–Nayar 1994). Beckmann: the C^b of §3.2.3 (table 3.5), whose
    C2, C3 already carry tan β and tan((α+β)/2), so they are not multiplied again.
    θ are clipped at 89.9° so the tangents stay finite at grazing angles.
    """
    lim = np.radians(89.9)
    alpha = np.minimum(np.maximum(ts, to), lim)
    beta = np.minimum(np.minimum(ts, to), lim)
    s2 = sigma * sigma
    if distribution == "gaussian":
        c1 = 1.0 - 0.5 * s2 / (s2 + 0.33)
        c2 = 0.45 * s2 / (s2 + 0.99) * np.where(cphi >= 0, np.sin(alpha), np.sin(alpha) - (2 * beta / np.pi) ** 3)
        c3 = 0.125 * s2 / (s2 + 0.09) * (4 * alpha * beta / np.pi**2) ** 2
        return c1 + c2 * cphi * np.tan(beta) + c3 * (1.0 - np.abs(cphi)) * np.tan(0.5 * (alpha + beta))
    t = _T35
    s = sigma
    c1 = 1.0 - t["A"] * s2 / (t["B"] + t["C"] * s + t["D"] * s2)
    c4 = np.where(cphi >= 0, 0.0, 2 * beta**3 / np.pi)
    c2 = np.tan(beta) * t["E"] * s2 / (t["F"] + t["G"] * s + t["H"] * s2 + t["I"] * s2 * s) * (np.sin(alpha) - c4)
    c3 = np.tan(0.5 * (alpha + beta)) * t["J"] * s2 / (t["K"] + t["L"] * s + t["M"] * s2) * (4 * alpha * beta / np.pi**2) ** 2
    return c1 + c2 * cphi + c3 * (1.0 - np.abs(cphi))


def volume_integral_approx(s, o, sigma, n_i, distribution="beckmann"):
    """I(s, o) implied by the approximate formula eq 3.49–3.57 (K_d factored out).

    f_v ≈ T̄(s) T̄(o) F_a / (n_i² (1 − K_d r_i)) with T̄(u) = a T(u, n) + b (1 − r_e) and
    F_a = (1 + max[−1, c F'_a]) f_a*, F'_a = r_e (1 − s·n)² (1 − o·n)² min[0, cos Δφ]
    (eq 3.52 as printed, "F + (r_e − F)", reduces to r_e). Since f_a* = (K_d/π)[…],
    I = T̄(s) T̄(o) (1 + max[−1, c F'_a]) […]. Fitted for n_i ∈ [1, 1.5], σ ∈ [0.01, 0.6]
    with inter-reflections included (σ ≥ 0.2), for the Torrance–Sparrow GAF; outside that
    box it extrapolates. Gaussian and Beckmann only (GGX raises).
    """
    if distribution not in _APPROX_ABC:
        raise ValueError(f"volume='approx' exists for the Gaussian and Beckmann distributions "
                         f"(tables 3.3–3.5), not {distribution!r}; use volume='table' or 'quadrature'")
    sx, sy, iso = check_sigma(sigma, distribution)
    if not iso:
        raise ValueError("volume='approx' is isotropic only; use 'quadrature' for a sigma pair")
    n = check_n_i(n_i)
    s = np.asarray(s, dtype=float)
    o = np.asarray(o, dtype=float)
    ts, to, _, cphi = _angles(s, o)
    r_e = r_e_molenaar1999(n)
    a, b, c = approx_coefficients(sx, n, distribution)
    tbar_s = a * (1.0 - fresnel_dielectric(np.clip(s[..., 2], 0, 1), n)) + b * (1.0 - r_e)
    tbar_o = a * (1.0 - fresnel_dielectric(np.clip(o[..., 2], 0, 1), n)) + b * (1.0 - r_e)
    fpa = r_e * (1.0 - np.clip(s[..., 2], 0, 1)) ** 2 * (1.0 - np.clip(o[..., 2], 0, 1)) ** 2 * np.minimum(0.0, cphi)
    bracket = rough_lambert_terms(ts, to, cphi, sx, distribution)
    # Outside its fit box the formula can go negative (b < 0 for σ ≲ 0.006 makes T̄ < 0 at
    # grazing; the Gaussian bracket at σ ≈ 2): a BRDF cannot, so it is clipped at 0.
    return np.maximum(tbar_s * tbar_o * (1.0 + np.maximum(-1.0, c * fpa)) * bracket, 0.0)


def volume_integral(s, o, sigma, n_i, distribution="beckmann", masking="smith", method="quadrature", **options):
    """Dispatch to the ``volume_integral_<method>`` evaluations (see VOLUME_METHODS)."""
    return VOLUME_METHODS[method](s, o, sigma, n_i, distribution, masking, **options)


def _volume_integral_approx_any_masking(s, o, sigma, n_i, distribution="beckmann", masking="smith", **options):
    # The fitted approximation has its masking baked in: the argument is accepted and unused.
    return volume_integral_approx(s, o, sigma, n_i, distribution, **options)


VOLUME_METHODS = Registry("volume-integral method")
VOLUME_METHODS.add("quadrature", volume_integral_quadrature)
VOLUME_METHODS.add("monte_carlo", volume_integral_monte_carlo)
VOLUME_METHODS.add("tables", volume_integral_tables)
VOLUME_METHODS.add("table", volume_integral_table)
VOLUME_METHODS.add("approx", _volume_integral_approx_any_masking)
VOLUME_METHODS.add("coupled", volume_integral_coupled)
