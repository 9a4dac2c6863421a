"""Inter-reflections between interfaced Lambertian facets in V-cavities (thesis §3.2.1).

The single-bounce model (eq 3.14) misses light that bounces inside a cavity before leaving.
Here the second bounce of the volume (substrate) light is simulated by path sampling in
symmetric V-grooves: a groove of facet normals m and m' = (−m_x, −m_y, m_z) (the
Torrance–Sparrow cavity), m drawn with pdf D(m)(m·n); a point P uniform on facet m, lit
from s if the other facet does not shadow it; a direction w leaving P (cosine-weighted
about m); if w hits the other facet at Q and Q is seen from o, the path contributes

    π T(s·m)(s·m) T(w·m) · T(−w·m') T(o·m')(o·m') / ((m·n)(s·n)(o·n))

times κ² with κ = K_d / (π n_i² (1 − K_d r_i)) (per-facet volume BRDF of eq 3.11 twice).
So, like the single-bounce volume part, the simulated integral J(s, o) is K_d-free and a
K_d change costs one multiplication. The groove is invariant along its axis, so the
visibility tests are 2-D, in the plane spanned by the groove's azimuth and n.

The mixed two-bounce paths (specular on one facet, volume on the other) are linear in κ and
simulated the same way (``interreflection_mixed_integral_vcavity``): the term added to the
BRDF is κ² J + κ J_1. Left out: specular–specular double bounces (the thin mirror peak of
fig 3.22, a Dirac-like feature) and three or more bounces (fig 3.23: two bounces carry most
of the extra light for rough diffuse facets; at K_d = 1, n_i = 1 they return ~90 % of the
light single scattering loses at σ = 0.3).
"""
import functools

import numpy as np

from ._fresnel import check_n_i, fresnel_dielectric, r_i_simonot2009
from ._microfacet import check_sigma, sample_microfacet_normals
from ._volume import tabulate_isotropic

__all__ = ["interreflection_integral_vcavity", "interreflection_mixed_integral_vcavity", "interreflection_vcavity",
           "build_interreflection_table"]


def _hits_partner(px, pz, dx, dz, ct, st):
    """Does the ray P + t d (t > 0) in the groove section hit the partner facet v (cos θ, sin θ), v ∈ [0, 1]?"""
    det = -dx * st + ct * dz
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (px * st - ct * pz) / det
        v = (-dx * pz + dz * px) / det
    return (np.abs(det) > 1e-15) & (t > 1e-12) & (v >= 0.0) & (v <= 1.0), v


def interreflection_integral_vcavity(s, o, sigma, n_i, distribution="beckmann", n_paths=2048, rng=None):
    """J(s, o): the K_d-free two-bounce volume→volume integral (module doc). s, o (..., 3) -> (...).

    Monte Carlo with ``n_paths`` paths per (s, o) (seeded, default seed 0); error ∝ n_paths^-1/2.
    """
    return _two_bounce(s, o, sigma, n_i, distribution, n_paths, rng)[0]


def interreflection_mixed_integral_vcavity(s, o, sigma, n_i, distribution="beckmann", n_paths=2048, rng=None):
    """J_1(s, o): the K_d-free two-bounce integral of the mixed paths, specular then volume plus
    volume then specular (the second is the first with s and o swapped, by reciprocity).

    A specular bounce on facet m sends s to its mirror r = 2(s·m)m − s; if r hits the partner
    facet the path carries F(s·m)(s·m) T(−r·m') T(o·m')(o·m') / ((m·n)(s·n)(o·n)) times κ.
    """
    a = _two_bounce(s, o, sigma, n_i, distribution, n_paths, rng)[1]
    b = _two_bounce(o, s, sigma, n_i, distribution, n_paths, rng)[1]
    return a + b


def _two_bounce(s, o, sigma, n_i, distribution, n_paths, rng):
    """(J_vv, J_sv) for paths that enter through facet m (module doc)."""
    sx, sy, iso = check_sigma(sigma, distribution)
    n = check_n_i(n_i)
    rng = np.random.default_rng(0 if rng is None else rng)
    s, o = np.broadcast_arrays(np.asarray(s, float), np.asarray(o, float))
    shape = s.shape[:-1]
    s2 = s.reshape(-1, 1, 3)
    o2 = o.reshape(-1, 1, 3)
    out = np.zeros(len(s2))
    out_sv = np.zeros(len(s2))
    npaths = int(n_paths)
    if sx == 0.0 or sy == 0.0:
        return out.reshape(shape), out_sv.reshape(shape)  # a flat surface has no cavities
    step = max(1, 300_000 // npaths)
    sig = sx if iso else (sx, sy)
    for a in range(0, len(s2), step):
        b = min(len(s2), a + step)
        k = b - a
        m, wt = sample_microfacet_normals(rng.random((k, npaths)), rng.random((k, npaths)), sig, distribution)
        mp = m * np.array([-1.0, -1.0, 1.0])
        mz = m[..., 2]
        rxy = np.hypot(m[..., 0], m[..., 1])
        safe = rxy > 1e-12
        ex = np.where(safe, m[..., 0] / np.where(safe, rxy, 1), 1.0)
        ey = np.where(safe, m[..., 1] / np.where(safe, rxy, 1), 0.0)
        ct, st = mz, rxy  # cos θ_m, sin θ_m: facet A is u(−cos θ, sin θ), facet B v(cos θ, sin θ)
        u = rng.random((k, npaths))
        px, pz = -u * ct, u * st
        sa, oa = s2[a:b], o2[a:b]
        sm = np.sum(sa * m, axis=-1)
        omp = np.sum(oa * mp, axis=-1)
        # P lit from s: the ray towards s must not hit facet B.
        hit_s, _ = _hits_partner(px, pz, sa[..., 0] * ex + sa[..., 1] * ey, sa[..., 2], ct, st)
        # cosine-weighted w about m
        r1, r2 = rng.random((k, npaths)), rng.random((k, npaths))
        rad, ph = np.sqrt(r1), 2 * np.pi * r2
        lx, ly, lz = rad * np.cos(ph), rad * np.sin(ph), np.sqrt(np.maximum(0.0, 1.0 - r1))
        t1x = np.stack([-ey, ex, np.zeros_like(ex)], axis=-1)  # groove axis (⊥ m, horizontal)
        t2x = np.cross(m, t1x)
        w = lx[..., None] * t1x + ly[..., None] * t2x + lz[..., None] * m
        we = w[..., 0] * ex + w[..., 1] * ey
        hit_w, v = _hits_partner(px, pz, we, w[..., 2], ct, st)
        # Q = v (cos θ, sin θ) on B seen from o: mirror to facet A and test against B.
        oe = oa[..., 0] * ex + oa[..., 1] * ey
        hit_o, _ = _hits_partner(-v * ct, v * st, -oe, np.broadcast_to(oa[..., 2], oe.shape), ct, st)
        wmp = -np.sum(w * mp, axis=-1)
        ok = (sm > 0) & (omp > 0) & ~hit_s & hit_w & ~hit_o & (wmp > 0)
        contrib = (np.pi * (1 - fresnel_dielectric(sm, n)) * sm * (1 - fresnel_dielectric(lz, n))
                   * (1 - fresnel_dielectric(wmp, n)) * (1 - fresnel_dielectric(omp, n)) * omp)
        with np.errstate(divide="ignore", invalid="ignore"):
            val = contrib * wt / (mz * sa[..., 2] * oa[..., 2])
        out[a:b] = np.mean(np.where(ok, val, 0.0), axis=-1)
        # specular first: the mirror direction of s about m, from the same lit point P
        rr = 2.0 * sm[..., None] * m - sa
        hit_r, vr = _hits_partner(px, pz, rr[..., 0] * ex + rr[..., 1] * ey, rr[..., 2], ct, st)
        hit_or, _ = _hits_partner(-vr * ct, vr * st, -oe, np.broadcast_to(oa[..., 2], oe.shape), ct, st)
        rmp = -np.sum(rr * mp, axis=-1)
        ok_r = (sm > 0) & (omp > 0) & ~hit_s & hit_r & ~hit_or & (rmp > 0)
        contrib_r = (fresnel_dielectric(sm, n) * sm * (1 - fresnel_dielectric(rmp, n))
                     * (1 - fresnel_dielectric(omp, n)) * omp)
        with np.errstate(divide="ignore", invalid="ignore"):
            val_r = contrib_r * wt / (mz * sa[..., 2] * oa[..., 2])
        out_sv[a:b] = np.mean(np.where(ok_r, val_r, 0.0), axis=-1)
    up = (s[..., 2] > 0) & (o[..., 2] > 0)
    return np.where(up, out.reshape(shape), 0.0), np.where(up, out_sv.reshape(shape), 0.0)


@functools.lru_cache(maxsize=16)
def build_interreflection_table(sigma, n_i, distribution="beckmann", step_deg=5.0, n_paths=512, kind="volume"):
    """J (kind="volume") or J_1 (kind="mixed") tabulated like the volume part (K_d-free, so one
    table serves every K_d), by path sampling with ``n_paths`` paths per node (seeded).
    Isotropic σ only."""
    sx, sy, iso = check_sigma(sigma, distribution)
    if not iso:
        raise ValueError("a table of inter-reflections assumes an isotropic distribution")
    n = check_n_i(n_i)
    fn = {"volume": interreflection_integral_vcavity, "mixed": interreflection_mixed_integral_vcavity}.get(kind)
    if fn is None:
        raise ValueError(f"kind = {kind!r}: 'volume' or 'mixed'")
    return tabulate_isotropic(lambda s, o: fn(s, o, sx, n, distribution, n_paths, rng=7),
                              step_deg, (kind, sx, n, distribution))


def interreflection_vcavity(s, o, kd, sigma, n_i, distribution="beckmann", n_paths=2048, rng=None,
                            table_step_deg=None, mixed=True):
    """Two-bounce inter-reflection term κ² J(s, o) + κ J_1(s, o), (...) or (..., C) per K_d channel.

    mixed : include the specular↔volume paths J_1 (0 for n_i = 1).
    ``table_step_deg``: read J, J_1 from cached tables (built on first use) instead of simulating
    per call — what ``brdf_li(volume="table")`` does, for rendering-sized calls.
    """
    k = np.asarray(kd, dtype=float)
    n = check_n_i(n_i)
    kappa = k / (np.pi * n * n * (1.0 - k * r_i_simonot2009(n)))
    mixed = bool(mixed) and n > 1.0
    if table_step_deg:
        sg = float(check_sigma(sigma, distribution)[0])
        sa, oa = np.asarray(s, float), np.asarray(o, float)
        up = (sa[..., 2] > 0) & (oa[..., 2] > 0)
        j = np.where(up, build_interreflection_table(sg, n, distribution, float(table_step_deg))(sa, oa), 0.0)
        j1 = (np.where(up, build_interreflection_table(sg, n, distribution, float(table_step_deg), 512, "mixed")(sa, oa),
                       0.0) if mixed else 0.0 * j)
    else:
        j = interreflection_integral_vcavity(s, o, sigma, n, distribution, n_paths, rng)
        j1 = interreflection_mixed_integral_vcavity(s, o, sigma, n, distribution, n_paths, rng) if mixed else 0.0 * j
    if k.ndim == 1:
        return j[..., None] * kappa**2 + j1[..., None] * kappa
    return j * kappa**2 + j1 * kappa
