"""Published photometric-stereo methods for general isotropic BRDFs, written here from their papers.

`ps_bipolynomial_shi2014` : Shi, Tan, Matsushita, Ikeuchi, "Bi-polynomial modeling of
    low-frequency reflectances", TPAMI 36(6) 2014 (ST14 in DiLiGenT). The paper's method section
    could not be read (../shared/reference/PEERS.md §2: its abstract, and the steps third parties
    used, IA14 and CNN-PS re-implementing it); it is written from those steps, so no equation
    numbers are given. Per pixel: 1. shadows out (values below ST14_T_SHADOW of the pixel's
    brightest); 2. the low-frequency part kept: the darkest ST14_T_LOW share of the lit values
    (third parties: "T_low"); 3. the Lambertian normal on them, the start (IA14: the fit depends
    strongly on it); 4. the normal minimising the residual of E_i = (n·l_i) ρ(cos θ_h, cos θ_d),
    ρ = Σ_ab α_ab cos^a θ_h cos^b θ_d (θ_h = angle(n, h_i), θ_d = angle(l_i, h_i)), the α solved for
    each trial normal (variable projection), Levenberg-Marquardt on two tangent angles. Ours, not
    read: α >= 0 (ρ never falls towards the specular direction; unconstrained, a falling ρ takes the
    photographs' dark floor of stray light for reflectance: 16-bit ball 2.33°, its 8-bit crop 6.29°
    and cat 12.8° against 2.13°, 4.07°, 7.40° with α >= 0), and the constants chosen on renders
    (ST14_T_SHADOW, ST14_T_LOW, ST14_DEGREES). Through `process` (`facette bench peers`): the 16-bit
    ball 2.11° [paper 1.74], the five 8-bit crops 9.64° [8.17]; the ball cut to 8 bits 4.06°.
`ps_bivariate_ikehata2014` : Ikehata, Aizawa, "Photometric stereo using constrained bivariate
    regression for general isotropic surfaces", CVPR 2014 (IA14). By default (form="paper") as the
    paper states it, step by step with its constants (`facette.recon._ia14_paper`, from
    ../shared/reference/PEERS.md §1: orders (1, 5), the retro-reflection test): DiLiGenT's 16-bit
    ball 3.15° against the paper's 3.34°, the five 8-bit crops 9.94° against 8.70° (cat 6.64/6.74,
    pot2 8.96/8.77; buddha and reading 2.9° and 4.3° worse). form="variant", this module's first reading: Seen from the fixed view v,
    n·v is constant per pixel, so n·h_i = (n·l_i + n·v) / (2 l_i·h_i) and an isotropic
    (sum-of-lobes) pixel's value is a function of (n·l_i, l_i·v) alone, increasing in n·l_i;
    its inverse representation n·l_i = Ψ(E_i, l_i·v) separates the normal from the reflectance.
    Ψ is a bivariate Bernstein polynomial, Ψ(0, ·) = 0, so n·l_i - Σ_k c_k B_k(E_i, l_i·v) = 0
    is linear in (n, c) jointly: per pixel, n is the eigenvector of the smallest eigenvalue of
    the 3x3 matrix L^T (I - P_B) L (c projected out), |n| = 1.

How far IA14's variant follows its paper: its parameters are ours: Bernstein degrees (5 in E, 0 in
l·v) and the shadow threshold T_SHADOW (degrees chosen on our own synthetic spheres, see
IA14_DEGREES); its constraints a QP of our own form (Ψ(0) = 0 and increasing in E through
non-negative increments of its Bernstein coefficients, its scale fixed by their sum: a QP on
the simplex, `_ia14_qp`); `constrained=False` gives the unconstrained minimiser (an
eigenvector), with `info["non_monotone"]` the share of pixels whose Ψ is not increasing.
`facette bench peers` prints every peer beside the papers' DiLiGenT figures.

Conventions of `facette.recon._ps`: camera frame x right, y up, z towards the camera (the view
v = (0, 0, 1), orthographic); images linear, divided by each light's intensity; `PSResult`.
Both need distant lights, light_dirs (m, 3).
"""
from itertools import combinations
from math import comb

import numpy as np

from facette._threads import run_blocks

from ._ia14_paper import IA14_ORDERS, ia14_paper_normals
from ._ps import _albedo, _check_inputs, _empty_result, _gather, _scatter, _usable
from ._ps_robust import _unit, _wls

__all__ = ["ps_bipolynomial_shi2014", "ps_bivariate_ikehata2014", "T_SHADOW", "ST14_T_SHADOW", "ST14_T_LOW"]

T_SHADOW = 0.02       # values below this share of the pixel's brightest usable value are shadows
ST14_T_SHADOW = 0.1   # ST14: values below this share of the pixel's brightest are shadows
ST14_T_LOW = 0.5      # ST14: share of the lit values kept, darkest first (the low-frequency part)
ST14_DEGREES = (2, 0) # bi-polynomial degrees in cos θ_h and cos θ_d (the previous helper's choice on
                      # Blinn-Phong spheres: 1.66° against 2.01 for (1, 0), 3.5-4.2 with a θ_d term).
                      # T_SHADOW, T_LOW chosen on 12 rendered spheres (`facette bench peers
                      # --st14-choice`: Blinn-Phong, satin, glossy; 16 and 8 bits; with and without a
                      # 2 % stray-light floor), never on DiLiGenT: mean 0.53° for (0.1, 0.5) and
                      # (0.02, 0.5), 0.62-0.82 for (0.02|0.1, 0.25|0.75); 0.1 taken for its lead on
                      # the 16-bit renders with stray light (0.83-0.94° against 0.94-1.03°; at 8 bits
                      # the floor is under a grey level), as every photograph has some. PEERS.md's
                      # third-party T_low 0.25: 0.75 / 0.62°
IA14_DEGREES = (5, 0)   # Bernstein degrees of Ψ in E (normalised) and in l·v, with the monotone QP;
                        # chosen on the same spheres among (5..12, 0..2): mean 2.10° against 2.14 for
                        # (8, 1), 2.29-2.77 for the others (unconstrained (3, 2): 1.99, but Ψ is not
                        # increasing in 72 % of the pixels, so not the paper's method). With k_v = 0
                        # Ψ depends on E alone: the l·v term did not help on those spheres
RIDGE = 1e-6          # relative Tikhonov weight of the per-pixel coefficient solves (conditioning)
_CHUNK = 8192         # pixels per block: (chunk, m, p) float64 arrays
VIEW = np.array([0.0, 0.0, 1.0])


def _check_distant(light_dirs, name):
    if light_dirs.ndim != 2:
        raise ValueError(f"{name} needs distant lights, light_dirs (m, 3): its reflectance is a "
                         "function of the light's angles to the view, one per light; use "
                         "ps_rank_trimmed or ps_woodham1980 for near lights")


def _distant_start(images, light_dirs, mask, channel, name):
    """The checked inputs of the method `name` (distant lights only), its empty result and the
    gathered pixels: (images, light_dirs, res, idx, e_all, e, sub), as `_gather`."""
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    _check_distant(light_dirs, name)
    m, h, w, c = images.shape
    res = _empty_result(h, w, m, c, name.removeprefix("ps_"))
    return (images, light_dirs, res) + tuple(_gather(images, mask, channel))


def _fill(res, idx, normal, rho, found, ok, lit, resid):
    """The found pixels' results scattered into `res`: normal (3, N), albedo, valid, the usable
    unlit lights as shadows, residual."""
    _scatter(res, idx, "normal", normal.T)
    _scatter(res, idx, "albedo", np.where(found[:, None], rho, 0.0))
    _scatter(res, idx, "valid", found)
    _scatter(res, idx, "shadow", (ok & ~lit & found).T)
    _scatter(res, idx, "residual", resid)


def _lit_values(e, saturation, t_shadow):
    """(ok, e, lit): the usable values, e with the others set to 0, and `_lit_mask`."""
    ok = _usable(e, saturation)
    e = np.where(ok, e, np.float32(0))
    return ok, e, _lit_mask(e, ok, t_shadow)


def _lit_mask(e, ok, t_shadow):
    """(m, N) bool: usable values above t_shadow x the pixel's brightest usable value."""
    peak = np.where(ok, e, 0).max(axis=0)
    return ok & (e > t_shadow * peak) & (e > 0)


def _projected_lstsq(a, y, w, ridge=RIDGE):
    """Per pixel min_c ||W^(1/2) (y - A c)||²: returns (c (N, p), residual vector (N, m)).

    a : (N, m, p), y : (N, m), w : (N, m) 0/1 weights. A small ridge relative to the trace keeps
    the solve defined where the kept lights do not span every basis function."""
    aw = a * w[..., None]
    g = np.matmul(aw.transpose(0, 2, 1), a)                       # (N, p, p)
    p = g.shape[-1]
    tr = np.trace(g, axis1=1, axis2=2) / p
    g += (ridge * np.maximum(tr, 1e-30))[:, None, None] * np.eye(p)
    rhs = np.einsum("nmp,nm->np", aw, y)
    c = np.linalg.solve(g, rhs[..., None])[..., 0]
    r = (y - np.einsum("nmp,np->nm", a, c)) * w
    return c, r


# ----------------------------------------------------------------------------- ST14

def _nonneg_lstsq(a, y, w, ridge=RIDGE):
    """Per pixel min_c ||W^(1/2) (y - A c)||² with c >= 0 (a reflectance that does not fall towards
    the specular direction): the normal equations solved on every support of c (p <= 6: at most 63
    small solves of the Gram's sub-blocks), the feasible one of least cost kept. a : (N, m, p),
    y, w : (N, m). Returns (c (N, p), residual vector (N, m)); the ridge as `_projected_lstsq`'s."""
    n_pix, _, p = a.shape
    aw = a * w[..., None]
    g = np.matmul(aw.transpose(0, 2, 1), a)                       # (N, p, p)
    g += (ridge * np.maximum(np.trace(g, axis1=1, axis2=2) / p, 1e-30))[:, None, None] * np.eye(p)
    rhs = np.einsum("nmp,nm->np", aw, y)
    best_c, best = np.zeros((n_pix, p)), np.zeros(n_pix)          # c = 0: cost y'Wy, taken as 0 here
    for k in range(1, p + 1):
        for sup in combinations(range(p), k):
            s = list(sup)
            gs = g[:, s][:, :, s]
            c = np.linalg.solve(gs, rhs[:, s, None])[..., 0]
            cost = np.einsum("nk,nkj,nj->n", c, gs, c) - 2 * np.einsum("nk,nk->n", c, rhs[:, s])
            b = np.all(c >= 0, axis=1) & (cost < best)           # cost relative to y'Wy
            best[b] = cost[b]
            best_c[b] = 0.0
            best_c[np.ix_(b, s)] = c[b]
    return best_c, (y - np.einsum("nmp,np->nm", a, best_c)) * w


def _st14_basis(n, lights, halves, ld, degrees):
    """(N, m, p) columns (n·l)_+ (n·h)^a (l·h)^b of the bi-polynomial model for normals n (N, 3)."""
    kh, kd = degrees
    nl = np.maximum(n @ lights.T, 0.0)                            # (N, m)
    nh = np.clip(n @ halves.T, 0.0, 1.0)
    return np.stack([nl * nh ** a * ld[None, :] ** b for a in range(kh + 1) for b in range(kd + 1)], axis=-1)


def _tangent_frame(n):
    """Two unit vectors (N, 3) orthogonal to n (N, 3) and to each other."""
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    t1 = np.cross(n, ref)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def _rotate(n, t1, t2, d):
    """n moved by the tangent step d (N, 2) (radians), renormalised."""
    out = n + d[:, :1] * t1 + d[:, 1:] * t2
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _st14_block(e, w, n0, geometry, degrees, iterations, tol):
    """Levenberg-Marquardt on two tangent angles of each pixel's normal, the bi-polynomial's
    coefficients solved (c >= 0) for each trial normal; e, w (N, m), n0 (N, 3)."""
    def resid(n, ea, wa):
        return _nonneg_lstsq(_st14_basis(n, *geometry, degrees), ea, wa)[1]

    n = n0.copy()
    r = resid(n, e, w)
    cost = np.sum(r * r, axis=1)
    mu = np.full(len(n), 1e-3)
    active = np.ones(len(n), bool)
    h = 1e-4                                                      # finite-difference step (rad)
    it = 0
    for it in range(1, iterations + 1):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        na, ra, ea, wa = n[idx], r[idx], e[idx], w[idx]
        t1, t2 = _tangent_frame(na)
        jac = np.empty(ra.shape + (2,))
        for k, t in enumerate((t1, t2)):
            jac[..., k] = (resid(_rotate(na, t1, t2, h * np.eye(2)[k][None]), ea, wa) - ra) / h
        jtj = np.einsum("nmi,nmj->nij", jac, jac)
        jtr = np.einsum("nmi,nm->ni", jac, ra)
        damp = jtj + (mu[idx] * np.maximum(np.trace(jtj, axis1=1, axis2=2), 1e-30))[:, None, None] * np.eye(2)
        step = -np.linalg.solve(damp, jtr[..., None])[..., 0]
        big = np.linalg.norm(step, axis=1)
        step *= np.minimum(1.0, np.radians(5.0) / np.maximum(big, 1e-30))[:, None]   # at most 5° a step
        n_try = _rotate(na, t1, t2, step)
        r_try = resid(n_try, ea, wa)
        c_try = np.sum(r_try * r_try, axis=1)
        better = c_try < cost[idx]
        take = idx[better]
        n[take], r[take], cost[take] = n_try[better], r_try[better], c_try[better]
        mu[idx] = np.where(better, mu[idx] * 0.3, mu[idx] * 10.0)
        done = (better & (np.linalg.norm(step, axis=1) < tol)) | (mu[idx] > 1e6)
        active[idx[done]] = False
    return n, cost, it


def _low_frequency(e, lit, t_low):
    """(m, N) bool: each pixel's darkest ceil(t_low x its lit count) lit values (ST14's
    low-frequency observations; ties with the last one kept)."""
    m = e.shape[0]
    n_keep = np.ceil(t_low * lit.sum(0)).astype(np.intp)
    srt = np.sort(np.where(lit, e, np.inf), axis=0)               # ascending per pixel
    cut = srt[np.clip(n_keep - 1, 0, m - 1), np.arange(e.shape[1])]
    return lit & (e <= cut)


def ps_bipolynomial_shi2014(images, light_dirs, mask=None, channel=None, saturation=None,
                            degrees=ST14_DEGREES, t_shadow=ST14_T_SHADOW, t_low=ST14_T_LOW,
                            iterations=20, tol_deg=0.01):
    """Bi-polynomial photometric stereo (Shi, Tan, Matsushita, Ikeuchi, TPAMI 2014; ST14).

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights (distant lights only).
    mask, channel, saturation : as `ps_woodham1980` (NaN, inf, values >= saturation are missing).
    degrees : (k_h, k_d) polynomial degrees in cos θ_h and cos θ_d, (k_h+1)(k_d+1) <= 6 (default (2, 0)).
    t_shadow : values below t_shadow x the pixel's brightest usable value are shadows, in [0, 1).
    t_low : share of each pixel's lit values kept, darkest first (the low-frequency part), in (0, 1].
    iterations, tol_deg : Levenberg-Marquardt iterations at most, and the step (deg) under
        which a pixel stops.
    Returns a `PSResult`: normal; albedo (Lambertian ρ per channel on the kept lights, for the
    later stages); valid (False where fewer kept lights than the model's unknowns + 2, or all
    black); shadow = usable lights below t_shadow; specular = lit lights above the low-frequency
    share; residual = relative residual of the bi-polynomial fit. info: iterations, pixels.

    Steps (module doc): 1. shadows out; 2. the darkest t_low of the rest kept; 3. the Lambertian
    normal on them as the start; 4. n minimising the residual of E_i = (n·l_i) Σ α_ab (n·h_i)^a
    (l_i·h_i)^b over the kept lights, α >= 0 solved for each trial normal (variable projection).
    """
    if not 0 <= t_shadow < 1:
        raise ValueError(f"t_shadow must be in [0, 1) (share of the pixel's brightest value), got {t_shadow}")
    if not 0 < t_low <= 1:
        raise ValueError(f"t_low must be in (0, 1] (share of the lit values kept, darkest first), got {t_low}")
    kh, kd = (int(x) for x in degrees)
    if kh < 0 or kd < 0 or (kh + 1) * (kd + 1) > 6:
        raise ValueError(f"degrees must be two whole numbers >= 0 with (k_h+1)(k_d+1) <= 6, got {degrees}")
    images, light_dirs, res, idx, e_all, e, sub = _distant_start(images, light_dirs, mask, channel,
                                                                 "ps_bipolynomial_shi2014")
    res.info = {"pixels": int(idx.size), "degrees": (kh, kd)}
    if idx.size == 0:
        return res
    lights = light_dirs.astype(np.float64)
    halves = lights + VIEW
    halves /= np.linalg.norm(halves, axis=1, keepdims=True)
    geometry = (lights, halves, np.sum(lights * halves, axis=1))  # cos θ_d per light
    p = (kh + 1) * (kd + 1)
    ok, e, lit = _lit_values(e, saturation, t_shadow)
    keep = _low_frequency(e, lit, t_low)
    n_pix = idx.size
    normal = np.zeros((3, n_pix), np.float32)
    found = np.zeros(n_pix, bool)
    resid = np.zeros(n_pix, np.float32)
    iters = []

    def block(a):
        sl = slice(a, a + _CHUNK)
        eb, kb = e[:, sl], keep[:, sl]
        n0, f0 = _unit(_wls(eb, light_dirs, kb))
        f0 &= kb.sum(0) >= p + 2
        sel = np.flatnonzero(f0)
        if sel.size == 0:
            return
        n0 = n0[:, sel].T.astype(np.float64)
        n0[:, 2] = np.maximum(n0[:, 2], 1e-3)                     # facing the camera
        n0 /= np.linalg.norm(n0, axis=1, keepdims=True)
        y = eb[:, sel].T.astype(np.float64)
        wt = kb[:, sel].T.astype(np.float64)
        y /= np.maximum(y.max(axis=1, keepdims=True), 1e-30)      # residuals relative to the pixel
        nn, cost, it = _st14_block(y, wt, n0, geometry, (kh, kd), iterations, np.radians(tol_deg))
        iters.append(it)
        cols = a + sel
        normal[:, cols] = nn.T
        found[cols] = np.all(np.isfinite(nn), axis=1)
        resid[cols] = np.sqrt(cost) / np.maximum(np.sqrt(np.sum(y * y * wt, axis=1)), 1e-30)

    run_blocks(block, range(0, n_pix, _CHUNK))
    normal = np.where(found, normal, np.float32(0))
    rho = _albedo(e_all, light_dirs, normal, keep & ok, idx=sub)
    _fill(res, idx, normal, rho, found, ok, lit, resid)
    _scatter(res, idx, "specular", (lit & ~keep & found).T)
    res.info["iterations"] = int(max(iters)) if iters else 0
    return res


# ----------------------------------------------------------------------------- IA14

def _bernstein(x, k):
    """(..., k + 1) Bernstein basis of degree k at x in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.stack([comb(k, j) * x ** j * (1 - x) ** (k - j) for j in range(k + 1)], axis=-1)


def _ia14_eigen(basis, wb, lights, ll, ll_safe, p):
    """Unconstrained: n = eigenvector of the smallest eigenvalue of L^T W (I - P_B) W L."""
    bw = basis * wb[..., None]
    g = np.matmul(bw.transpose(0, 2, 1), basis)
    tr = np.trace(g, axis1=1, axis2=2) / p
    g += (RIDGE * np.maximum(tr, 1e-30))[:, None, None] * np.eye(p)
    bl = np.einsum("nmp,mi->npi", bw, lights)                     # B^T W L  (N, p, 3)
    sol = np.linalg.solve(g, bl)                                  # G^-1 B^T W L
    mat = ll - np.matmul(bl.transpose(0, 2, 1), sol)
    mat = 0.5 * (mat + mat.transpose(0, 2, 1))
    ev, vec = np.linalg.eigh(np.where(np.isfinite(mat), mat, 0) + 0 * ll_safe)
    nb = vec[:, :, 0]
    nb *= np.where(nb[:, 2] < 0, -1.0, 1.0)[:, None]
    return nb, np.einsum("npq,nq->np", sol, nb), ev[:, 0]


def _project_simplex(v):
    """Euclidean projection of each row of v (N, p) onto {d >= 0, sum d = 1}."""
    u = -np.sort(-v, axis=1)
    css = np.cumsum(u, axis=1) - 1.0
    k = np.arange(1, v.shape[1] + 1)
    cond = u - css / k > 0
    r = v.shape[1] - 1 - np.argmax(cond[:, ::-1], axis=1)        # last index where cond holds
    theta = css[np.arange(len(v)), r] / (r + 1)
    return np.maximum(v - theta[:, None], 0.0)


def _ia14_qp(basis, wb, lights, ll_safe, ke, kv, iterations):
    """Monotone Ψ: c_ab = Σ_{a' <= a} d_a'b with d >= 0 (Ψ(0) = 0, increasing in E), the scale
    fixed by Σ d = 1 (Ψ's mean at the brightest value). n eliminated in closed form,
    n = (L^T W L)^-1 L^T W B' d, leaves min d^T Q d on the simplex: a QP, solved by accelerated
    projected gradient (FISTA). Returns unit n (N, 3), c (N, p), the residual d^T Q d / |n|^2."""
    n_pix, m, p = basis.shape
    cum = np.flip(np.cumsum(np.flip(basis.reshape(n_pix, m, ke, kv + 1), axis=2), axis=2), axis=2)
    bp = cum.reshape(n_pix, m, p)                                 # B'_a'b = Σ_{a >= a'} B_a B_b
    bw = bp * wb[..., None]
    g = np.matmul(bw.transpose(0, 2, 1), bp)                      # B'^T W B'
    bl = np.einsum("nmp,mi->npi", bw, lights)                     # B'^T W L
    sol = np.linalg.solve(ll_safe, bl.transpose(0, 2, 1))         # (L^T W L)^-1 L^T W B'  (N, 3, p)
    q = g - np.matmul(bl, sol)
    q = 0.5 * (q + q.transpose(0, 2, 1))
    lmax = np.maximum(np.linalg.eigvalsh(q)[:, -1], 1e-30)
    step = (1.0 / lmax)[:, None]
    d = np.full((n_pix, p), 1.0 / p)
    z, t = d.copy(), 1.0
    for _ in range(iterations):
        d_new = _project_simplex(z - step * np.einsum("npq,nq->np", q, z))
        t_new = 0.5 * (1 + np.sqrt(1 + 4 * t * t))
        z = d_new + ((t - 1) / t_new) * (d_new - d)
        if np.max(np.abs(d_new - d)) < 1e-7:
            d = d_new
            break
        d, t = d_new, t_new
    n = np.einsum("nip,np->ni", sol, d)
    scale = np.linalg.norm(n, axis=1)
    ok = scale > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, scale, 1.0), 0.0)
    coef = np.cumsum(d.reshape(n_pix, ke, kv + 1), axis=1).reshape(n_pix, p) * inv[:, None]
    cost = np.einsum("np,npq,nq->n", d, q, d) * inv ** 2
    return n * inv[:, None], coef, cost


def ps_bivariate_ikehata2014(images, light_dirs, mask=None, channel=None, saturation=None,
                             degrees=IA14_DEGREES, t_shadow=T_SHADOW, constrained=True,
                             qp_iterations=300, form="paper"):
    """Constrained bivariate regression (Ikehata, Aizawa, CVPR 2014; IA14).

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights (distant lights only).
    mask, channel, saturation : as `ps_woodham1980`.
    degrees : (k_e, k_v) Bernstein degrees of Ψ in the value (E / the pixel's brightest) and in
        l·v (rescaled to [0, 1] over the lights); k_v is 0 when every light has the same l·v.
        Default (5, 0) (see IA14_DEGREES).
    constrained : Ψ(0, ·) = 0 and increasing in E (a QP, the paper's); False: unconstrained.
    qp_iterations : iterations of the QP (ADMM for "paper", accelerated projected gradient at most
        for "variant").
    form : "paper" (default): the paper's QP over [n; β] with its orders (N_y, N_z) = (1, 5) in l·v
        and E / max E, monotone in both, Σ x = 1, and its retro-reflection test
        (`facette.recon._ia14_paper`; `degrees` and `constrained` unused); "variant": the form below
        (Ψ of E alone, the normal eliminated, a QP on the simplex), this module's first version.
    t_shadow : values below t_shadow x the pixel's brightest usable value are shadows (left out).
    Returns a `PSResult`: normal (facing the camera); albedo (Lambertian ρ per channel on the lit
    lights); valid (False where fewer lit lights than the unknowns + 3, or all black); shadow =
    usable lights left out as shadows; specular all False; residual = the fit's squared residual
    relative to trace(L^T W L) (how far n·l_i is from a function of (E_i, l_i·v)).
    info: pixels, degrees, non_monotone (share of valid pixels whose fitted Ψ decreases in E
    somewhere on its control net: 0 when constrained).

    Notes: n·l_i = Ψ(E_i, l_i·v) = Σ_{1≤a≤k_e, 0≤b≤k_v} c_ab B_a(E_i) B_b(l_i·v). Constrained:
    c_ab = Σ_{a'≤a} d_a'b, d ≥ 0, Σ d = 1; n = (L^T W L)^-1 L^T W B' d eliminated, the QP
    min d^T Q d on the simplex, then n normalised. Unconstrained: for a unit n the best c is the
    projection, so n minimises n^T L^T (I - P_B) L n (the eigenvector of the smallest
    eigenvalue), its sign chosen so that n·v > 0.
    """
    if not 0 <= t_shadow < 1:
        raise ValueError(f"t_shadow must be in [0, 1) (share of the pixel's brightest value), got {t_shadow}")
    if form not in ("paper", "variant"):
        raise ValueError(f"form must be 'paper' or 'variant', got {form!r}")
    ke, kv = (int(x) for x in degrees)
    if ke < 1 or kv < 0:
        raise ValueError(f"degrees must be (k_e >= 1, k_v >= 0), got {degrees}")
    images, light_dirs, res, idx, e_all, e, sub = _distant_start(images, light_dirs, mask, channel,
                                                                 "ps_bivariate_ikehata2014")
    m = images.shape[0]
    # the paper's orders need 16 lit values a pixel: under fewer lights, the variant's smaller form
    paper_short = form == "paper" and m < 3 + (IA14_ORDERS[0] + 1) * IA14_ORDERS[1] + 3
    form = "variant" if paper_short else form
    lights = light_dirs.astype(np.float64)
    lv = lights @ VIEW
    span = lv.max() - lv.min()
    if span < 1e-3:
        kv = 0
    yv = (lv - lv.min()) / span if span >= 1e-3 else np.zeros(m)
    bv = _bernstein(yv, kv)                                       # (m, kv + 1)
    p = ke * (kv + 1)
    res.info = {"pixels": int(idx.size), "degrees": IA14_ORDERS if form == "paper" else (ke, kv),
                "non_monotone": 0.0, "form": form, "paper_form_needs_16_lights": paper_short}
    if idx.size == 0:
        return res
    ok, e, lit = _lit_values(e, saturation, t_shadow)
    n_pix = idx.size
    normal = np.zeros((3, n_pix), np.float32)
    found = np.zeros(n_pix, bool)
    resid = np.zeros(n_pix, np.float32)
    non_mono = np.zeros(n_pix, bool)

    def block(a):
        sl = slice(a, a + _CHUNK)
        eb, wb = e[:, sl].T.astype(np.float64), lit[:, sl].T.astype(np.float64)
        peak = np.maximum(np.max(eb * wb, axis=1, keepdims=True), 1e-30)
        be = _bernstein(eb / peak, ke)[..., 1:]                   # (N, m, ke): Ψ(0, ·) = 0
        basis = (be[..., :, None] * bv[None, :, None, :]).reshape(eb.shape[0], m, p)
        good = wb.sum(1) >= p + 3
        ll = np.einsum("nm,mi,mj->nij", wb, lights, lights)       # L^T W L  (N, 3, 3)
        ll_safe = np.where(good[:, None, None], ll, np.eye(3))
        if form == "paper":
            good = wb.sum(1) >= 3 + (IA14_ORDERS[0] + 1) * IA14_ORDERS[1] + 3
            nb, cost = ia14_paper_normals(eb * wb, wb, lights, IA14_ORDERS, True, qp_iterations)
            coef = np.zeros((len(nb), ke * (kv + 1)))
        elif constrained:
            nb, coef, cost = _ia14_qp(basis, wb, lights, ll_safe, ke, kv, qp_iterations)
        else:
            nb, coef, cost = _ia14_eigen(basis, wb, lights, ll, ll_safe, p)
        coef = coef.reshape(-1, ke, kv + 1)
        dec = np.any(np.diff(coef, axis=1) < -1e-6, axis=(1, 2)) | np.any(coef[:, 0] < -1e-6, axis=1)
        fin = good & np.all(np.isfinite(nb), axis=1) & (np.linalg.norm(nb, axis=1) > 0.5)
        normal[:, sl] = np.where(fin[:, None], nb, 0).T
        found[sl] = fin
        resid[sl] = np.where(fin, cost / np.maximum(np.trace(ll, axis1=1, axis2=2), 1e-30), 0)
        non_mono[sl] = dec & fin

    run_blocks(block, range(0, n_pix, _CHUNK))
    rho = _albedo(e_all, light_dirs, normal, lit, idx=sub)
    _fill(res, idx, normal, rho, found, ok, lit, resid)
    res.info["non_monotone"] = float(non_mono.sum() / max(found.sum(), 1))
    return res

