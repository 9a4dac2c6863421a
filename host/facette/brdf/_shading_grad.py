"""The derivatives of the LI shading terms in the model's (σ, n_i): what the shared (σ, n_i) fit's
analytic Jacobian reads (facette.fit._li_model.fit_li_per_pixel_kd).

    li_shading_derivatives(normals, lights, sigma, n_i, volume_model) -> (dA/dσ, dA/dn_i, dB/dσ, dB/dn_i)

A and B are those of `li_shading_terms` (E = A + B κ). The lobe A = F(s·h; n_i) D(n·h; σ)
G_1(n·s; σ) G_1(n·v; σ) / (4 n·v) (eq 3.10) has closed-form derivatives in σ (Beckmann D and Smith
G_1, eq 3.20); in n_i only F moves, whose derivative is a central difference of the closed-form
Fresnel factor (float64, step 1e-6: exact to ~1e-9, and not where the cost is). The volume parts
read tables that are combined linearly from node tables in log σ and n_i (facette.brdf._nodes):
their derivatives are the same combination with the weights' derivatives, evaluated by the same
interpolation (it is linear in the table's values). The derivative is the model's own, the
piecewise-linear node weights included (a finite difference inside a cell gives the same).
"""
import functools

import numpy as np
from scipy.special import erfc

from ._coupled import _transmittance_node
from ._fresnel import N_I_MAX, check_n_i, fresnel_dielectric
from ._microfacet import SIGMA_FLAT
from ._nodes import NODE_N_I_STEP, NODE_SIGMA_MIN, NODE_SIGMA_RATIO, _cell, node_point
from ._shading import _smith_g1_beckmann
from ._volume import NODE_QUADRATURE, NODE_STEP_DEG, VolumeTable, build_volume_table

__all__ = ["li_shading_derivatives"]

_SQRT_PI = np.sqrt(np.pi)
_FRESNEL_STEP = 1e-6


def node_weight_derivatives(sigma, n_i):
    """[(i, j, ∂w/∂σ, ∂w/∂n_i)] of the four nodes around (σ, n_i) (facette.brdf._nodes.nodes_around's
    bilinear weights in log σ and n_i; ∂/∂σ is 0 below the first σ node, where σ is clamped)."""
    ks, ws = _cell(np.log(max(float(sigma), NODE_SIGMA_MIN) / NODE_SIGMA_MIN), np.log(NODE_SIGMA_RATIO))
    kn, wn = _cell(float(n_i) - 1.0, NODE_N_I_STEP)
    dws = 1.0 / (float(sigma) * np.log(NODE_SIGMA_RATIO)) if sigma > NODE_SIGMA_MIN else 0.0
    dwn = 1.0 / NODE_N_I_STEP
    return [(i, j, si * dws * wj, wi * sj * dwn)
            for i, wi, si in ((ks, 1 - ws, -1.0), (ks + 1, ws, 1.0))
            for j, wj, sj in ((kn, 1 - wn, -1.0), (kn + 1, wn, 1.0))]


@functools.lru_cache(maxsize=64)
def _volume_table_derivatives(sigma, n_i):
    """(∂table/∂σ, ∂table/∂n_i) of facette.brdf.volume_table_at (Beckmann, Smith), as VolumeTables."""
    out = [0.0, 0.0]
    theta = None
    for i, j, d_s, d_n in node_weight_derivatives(sigma, n_i):
        if d_s == 0 and d_n == 0:
            continue
        node = build_volume_table(*node_point(i, j), "beckmann", "smith", NODE_STEP_DEG, *NODE_QUADRATURE)
        theta = np.degrees(node.theta) if theta is None else theta
        out[0] = out[0] + d_s * node.values
        out[1] = out[1] + d_n * node.values
    return tuple(VolumeTable(NODE_STEP_DEG, np.asarray(v, float), ("d", sigma, n_i), theta) for v in out)


def _coupled_derivatives(cs, co, sigma, n_i):
    """(∂B/∂σ, ∂B/∂n_i) of B = (n·s) t(n·s) t(n·v) (facette.brdf._coupled.coupled_terms)."""
    from ._coupled import coupled_transmittance
    mu, t = coupled_transmittance(float(sigma), float(n_i))
    dts = [0.0, 0.0]
    for i, j, d_s, d_n in node_weight_derivatives(sigma, n_i):
        if d_s or d_n:
            node = _transmittance_node(i, j)
            dts = [dts[0] + d_s * node, dts[1] + d_n * node]
    c_s, c_o = np.clip(cs, 0, 1), np.clip(np.asarray(co, np.float32).reshape(-1, 1), 0, 1)
    both = (cs > 0) & (co.reshape(-1, 1) > 0)
    t_s, t_o = np.interp(c_s, mu, t), np.interp(c_o, mu, t)
    return tuple(np.where(both, c_s * (np.interp(c_s, mu, dt) * t_o + t_s * np.interp(c_o, mu, dt)), 0)
                 .astype(np.float32) for dt in dts)


def _lobe_derivatives(cs, co, sv, lit, sigma, n_i):
    """(∂A/∂σ, ∂A/∂n_i) (N, m) of the lobe, on the pairs `_specular_into` evaluates it on."""
    d_sigma, d_n = np.zeros(cs.shape, np.float32), np.zeros(cs.shape, np.float32)
    if sigma < SIGMA_FLAT or n_i == 1.0:
        return d_sigma, d_n
    cs_c, co_c = np.clip(cs, 0, 1), np.clip(co, 0, 1)
    sh = np.sqrt(np.maximum((1 + sv) / 2, 1e-12))
    ch = np.clip((cs + co) / (2 * sh), 0, 1)
    ch2 = ch * ch
    near = lit & (1 - ch2 < np.float32(16 * sigma * sigma) * ch2)
    if not near.any():
        return d_sigma, d_n
    rows, cols = np.nonzero(near)
    chn = ch2[rows, cols].astype(np.float64)
    shn = (sh[0, cols] if sh.shape[0] == 1 else sh[rows, cols]).astype(np.float64)
    csn, con = cs_c[rows, cols].astype(np.float64), co_c[rows, 0].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        tan2 = (1 - chn) / chn
        d = np.exp(-tan2 / (sigma * sigma)) / (np.pi * sigma * sigma * chn * chn)
        d = np.where(np.isfinite(d), d, 0)
        g_s, g_o = (_smith_g1_beckmann(c, sigma).astype(np.float64) for c in (csn, con))
        fres = fresnel_dielectric(shn, n_i)
        lobe = d * g_s * g_o / (4 * con)
        # ∂ ln D/∂σ = 2 tan²θ_h / σ³ − 2 / σ; ∂ ln G_1/∂σ = −G_1 e^{−a²} / (2 a σ √π), a = c / (σ sin)
        dln = 2 * tan2 / sigma ** 3 - 2 / sigma + _dln_g1(csn, g_s, sigma) + _dln_g1(con, g_o, sigma)
        d_sigma[rows, cols] = np.where(np.isfinite(dln), fres * lobe * dln, 0)
        hi = min(n_i + _FRESNEL_STEP, N_I_MAX)
        lo = max(n_i - _FRESNEL_STEP, 1.0)
        d_n[rows, cols] = lobe * (fresnel_dielectric(shn, hi) - fresnel_dielectric(shn, lo)) / (hi - lo)
    return d_sigma, d_n


def _dln_g1(c, g, sigma):
    """∂ ln G_1(c; σ) / ∂σ of Smith's Beckmann G_1 (0 where c is at the normal or below the surface)."""
    sin = np.sqrt(np.maximum(1 - c * c, 0))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        a = c / (sigma * sin)
        out = -g * np.exp(-a * a) / (2 * a * sigma * _SQRT_PI)
    return np.where((c > 0) & (sin > 0) & np.isfinite(out), out, 0)


def li_shading_derivatives(normals, lights, sigma, n_i, volume_model):
    """(∂A/∂σ, ∂A/∂n_i, ∂B/∂σ, ∂B/∂n_i), each (N, m) float32, of `li_shading_terms(normals,
    lights, sigma, n_i, volume_model=volume_model)`; volume_model "tables", "coupled" or "lambert"
    (the approximate formula has none here: ValueError)."""
    n_i = check_n_i(n_i)
    sigma = float(sigma)
    nrm = np.asarray(normals, np.float32)
    s = np.asarray(lights, np.float32)
    co = nrm[:, 2:3]
    cs, sv = (nrm @ s.T, s[None, :, 2]) if s.ndim == 2 else (np.einsum("nj,nmj->nm", nrm, s), s[..., 2])
    lit = (cs > 0) & (co > 0)
    sig_v = max(sigma, 1e-6)
    if volume_model == "lambert":
        db = (np.zeros(cs.shape, np.float32),) * 2
    elif volume_model == "coupled":
        db = _coupled_derivatives(cs, co[:, 0], sig_v, n_i)
    elif volume_model == "tables":
        from ._volume_jit import volume_terms_tables
        db = []
        for table in _volume_table_derivatives(sig_v, n_i):
            out = np.empty(cs.shape, np.float32)
            volume_terms_tables(cs, co[:, 0], np.broadcast_to(sv, cs.shape), *table.kernel_arrays(), out)
            db.append(out)
    else:
        raise ValueError(f"volume_model = {volume_model!r}: derivatives for 'tables', 'coupled' or 'lambert' only")
    return (*_lobe_derivatives(cs, co, sv, lit, sigma, n_i), *db)
