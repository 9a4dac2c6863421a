"""Robust photometric stereo for real photographs: low-rank recovery and rank trimming.

`ps_rpca_wu2010` : Wu, Ganesh, Shi, Matsushita, Wang, Ma, "Robust photometric stereo via
    low-rank matrix completion and recovery", ACCV 2010. The lights x pixels matrix of a
    Lambertian scene has rank 3; shadows and saturated values are missing entries, highlights
    and other non-Lambertian effects a sparse error. RPCA by the inexact augmented Lagrange
    multiplier method (Lin, Chen, Ma 2009), then least squares against the known lights.
`ps_rank_trimmed` : per-pixel trimmed least squares. Each pixel keeps the middle of its own
    observations twice over: first the middle ranks of its intensities (the darkest are
    shadows or inter-reflection, the brightest highlights), then, with that normal, the middle
    ranks of its reflectance ratios E_i / (s_i . n) among the lit lights (a ratio is the BRDF
    value seen under light i: shadows push it down, a specular lobe up, the diffuse part sits
    in the middle). The idea of fitting only the low-frequency observations is that of Shi
    et al. (bi-polynomial reflectance, TPAMI 2014); here the fit is Lambertian. One ratio pass
    by default (more drift rather than converge, see `rounds`). Not a published method: its
    parameters were chosen on DiLiGenT leaving one object out (see `facette bench diligent`).

Same conventions and result type as `facette.recon._ps` (camera frame x right, y up, z
towards the camera; images linear, divided by each light's intensity; `PSResult`).
"""
import numpy as np

from facette._threads import run_blocks

from ._ps import (PSResult, _albedo, _check_inputs, _empty_result, _gather, _ls_normals,
                  _pixel_dirs, _scatter, _shading, _usable)

__all__ = ["ps_rpca_wu2010", "ps_rank_trimmed", "TRIM", "MIN_KEEP", "NOISE", "T_SHADOW_RPCA"]

TRIM = 0.3           # share of each pixel's observations dropped at each end (0.3: the middle 40 %
                     # kept); chosen by leave-one-object-out on five DiLiGenT objects, every fold
                     # picks 0.3 or 0.35 (see `facette bench diligent`)
MIN_KEEP = 6         # never fewer lights than twice the 3 unknowns of g (12 lights: the middle 6)
NOISE = 0.01         # relative noise of the rig's HDR values (1 %, as facette's simulator)
MIN_LIT = 0.1        # s.n below this (84 deg from the normal) counts as unlit in the ratio pass:
                     # grazing light, attached shadow
T_SHADOW_RPCA = 0.02  # values below this share of the pixel's brightest usable value are shadows
                      # (missing entries of the low-rank matrix), as Wu et al.'s shadow mask
SHADOW_BELOW = 0.5     # result maps only: a value below half the diffuse fit is a shadow,
SPECULAR_ABOVE = 1.5   # one left out above 1.5 x the fit a highlight
_CHUNK = 131072      # pixels per block (the rank passes hold a few (m, chunk) arrays)


def _trim_window(key, usable, trim, min_keep=3, tol=0.0):
    """(m, N) bool: usable entries whose value of `key` lies between the order statistics of
    ranks ceil(trim (u - 1)) and floor((1 - trim) (u - 1)) of the pixel's u usable values
    (ties with a bound are kept too, and so are values within `tol` x |bound| of it); the
    middle `min_keep` ranks (or every usable value, if fewer) when that window would hold fewer."""
    k = np.where(usable, key, np.inf)            # unusable entries rank above every usable one
    srt = np.sort(k.T, axis=1)                   # (N, m), pixel-major: short contiguous rows
    u = usable.sum(0)
    lo = np.ceil(trim * (u - 1) - 1e-9).astype(np.intp)
    hi = np.floor((1 - trim) * (u - 1) + 1e-9).astype(np.intp)
    want = np.minimum(u, min_keep)
    few = hi - lo + 1 < want
    lo = np.where(few, (u - want) // 2, lo)
    hi = np.where(few, lo + want - 1, hi)
    rows = np.arange(k.shape[1])
    v_lo = srt[rows, np.clip(lo, 0, k.shape[0] - 1)]
    v_hi = srt[rows, np.clip(hi, 0, k.shape[0] - 1)]
    if tol:    # values within tol (relative) of a bound are tied with it: kept together
        with np.errstate(invalid="ignore"):
            v_lo, v_hi = v_lo - tol * np.abs(v_lo), v_hi + tol * np.abs(v_hi)
    return usable & (u > 0) & (hi >= lo) & (k >= v_lo) & (k <= v_hi)


_PAIRS = ([0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2])   # upper triangle of a symmetric 3x3


def _wls(e, s, keep):
    """g = argmin sum_kept (E_i - s_i . g)^2 per pixel: (3, N) float32, NaN where fewer than 3
    lights are kept or they are (nearly) coplanar.

    e : (m, N) float32 with missing values set to 0; s : (m, 3) shared directions (matrix
    products and a closed-form 3x3 inverse) or (N, m, 3) per pixel (`_ls_normals`)."""
    if s.ndim != 2:
        return _ls_normals(e, s, keep)
    w = keep.astype(np.float32)
    s32 = s.astype(np.float32)
    a = ((s32[:, _PAIRS[0]] * s32[:, _PAIRS[1]]).T @ w).astype(np.float64)   # (6, N)
    b = (s32.T @ (w * e)).astype(np.float64)                                 # (3, N)
    xx, xy, xz, yy, yz, zz = a
    c00, c01, c02 = yy * zz - yz * yz, xz * yz - xy * zz, xy * yz - xz * yy
    c11, c12, c22 = xx * zz - xz * xz, xy * xz - xx * yz, xx * yy - xy * xy
    det = xx * c00 + xy * c01 + xz * c02
    # singular (fewer than 3 lights, or coplanar ones): relative to the scale of the matrix
    good = (w.sum(0) >= 3) & (np.abs(det) > 1e-9 * np.maximum(xx + yy + zz, 1e-30) ** 3)
    inv_det = np.where(good, 1.0 / np.where(good, det, 1.0), np.nan)
    g = np.empty((3,) + det.shape, np.float32)
    g[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) * inv_det
    g[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) * inv_det
    g[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) * inv_det
    return g


def _unit(g):
    norm = np.sqrt(np.sum(g * g, axis=0))
    found = np.isfinite(norm) & (norm > 1e-12)
    return np.where(found, g / np.where(found, norm, 1.0), np.float32(0)), found


def _rel_residual(e, s, g, keep):
    diff = np.where(keep, e - _shading(s, np.nan_to_num(g)), np.float32(0))
    e_norm = np.sqrt(np.sum(np.where(keep, e, np.float32(0)) ** 2, axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.sqrt(np.sum(diff * diff, axis=0)) / e_norm
    return np.where(np.isfinite(r), r, 0.0).astype(np.float32)


# cast-shadow floor of ps_rank_trimmed: 3 x the rig's relative noise (NOISE)
T_DARK = 0.03


def _rank_trimmed_arrays(e, ok, s, trim, min_keep, noise, t_dark, rounds, min_lit, normal, found, keep, resid,
                         changes, below, above):
    """`ps_rank_trimmed`'s passes on arrays, block by block on threads, into its outputs (the compiled
    loop, facette.recon._ps_robust_jit, does the same pixel by pixel)."""
    n_pix = e.shape[1]

    def block(a):
        sl = slice(a, a + _CHUNK)
        eb, okb = e[:, sl], ok[:, sl]
        # ranks count every usable value; a dark one (cast shadow) is never kept
        bright = okb if t_dark is None else okb & (eb > t_dark * eb.max(axis=0))
        sb = s if s.ndim == 2 else s[sl]
        kb = _trim_window(np.where(okb, eb, np.inf), okb, trim, min_keep, 3 * noise) & bright
        kb = np.where(kb.sum(0) >= 3, kb, bright)   # too few left: every bright value
        gb = _wls(eb, sb, kb)
        nb, fb = _unit(gb)
        for r in range(int(rounds)):
            sn = _shading(sb, nb)
            lit = okb & (sn > min_lit) & fb
            with np.errstate(divide="ignore", invalid="ignore"):
                q = eb / np.where(lit, sn, np.float32(1))
            kr = _trim_window(q, lit, trim, min_keep, 3 * noise) & bright
            enough = kr.sum(0) >= 3
            gr = _wls(eb, sb, kr)
            nr, fr = _unit(gr)
            take = enough & fr
            dots = np.clip(np.sum(nr * nb, axis=0), -1, 1)
            changes[r, sl] = np.where(take, np.degrees(np.arccos(dots)), 0)
            nb = np.where(take, nr, nb)
            kb = np.where(take, kr, kb)
            gb = np.where(take, gr, gb)
        # an all-black pixel gives g = 0: not found
        normal[:, sl], found[sl], keep[:, sl] = nb, fb, kb
        resid[sl] = _rel_residual(eb, sb, gb, kb)
        # maps for what follows (the reflectance samples leave `shadow` out); they do not steer
        # the normal: attached (s.n <= 0) or far below the diffuse fit = shadow, far above = specular
        sn = _shading(sb, nb)
        pred = _shading(sb, np.nan_to_num(gb))
        below[:, sl] = okb & ((sn <= 0) | (eb < SHADOW_BELOW * pred))
        above[:, sl] = okb & ~kb & (eb > SPECULAR_ABOVE * pred) & (sn > 0)

    run_blocks(block, range(0, n_pix, _CHUNK))


def ps_rank_trimmed(images, light_dirs, mask=None, channel=None, saturation=None, trim=TRIM,
                    rounds=1, min_lit=MIN_LIT, min_keep=MIN_KEEP, noise=NOISE, t_dark=T_DARK, engine="auto"):
    """Per-pixel trimmed least squares: middle intensity ranks, then middle reflectance ratios.

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel (near lights).
    mask : (H, W) bool (default all); channel : default green when C == 3.
    saturation : values >= this are missing, as are NaN and inf. A missing value still counts
        as one of the brightest in the ranking (a clipped value is at least that bright) but
        is never used.
    trim : share of each pixel's usable observations dropped at each end, in [0, 0.5);
        default 0.3 (the middle 40 % kept).
    noise : relative noise of the values (standard deviation / value), default 0.01 (the rig's
        HDR images). Each window's bounds widen by 3 x noise (relative), so that lights tied
        with a bound within the noise stay together: a flat surface under a symmetric ring of
        lights would otherwise have the ring split by noise, and its normal tilted (simulated
        satin plate, 12 rig lights: median 11.6 deg with no widening, 0.6 deg with it).
    t_dark : values at or below t_dark x the pixel's brightest usable value still take their
        ranks but are never kept (cast shadows: a pixel with more shadowed lights than the
        trimmed share). Default 0.03 (3 x noise): on the simulated rig scenes (sphere on a plane,
        12 lights) it takes the glossy scene's mean error from 0.90 to 0.13 deg (the hierarchy:
        0.27) and the plane's albedo spread from 7.7 % to 0.1 %, for 0.2 deg on DiLiGenT
        (96 lights: 8.77 against 8.57; 12 lights: 10.02 against 10.10). None: no such test.
    min_keep : when the window holds fewer lights, the middle min_keep are kept (default 6,
        twice the unknowns; with 12 lights the window is then ranks 3..8), or every usable
        one when fewer are usable; fewer than 3 usable leave the pixel invalid.
    rounds : ratio passes after the intensity pass (0: intensity ranks only). Default 1: on
        DiLiGenT (96 lights) the mean error is 8.95 deg with 0, 8.44 with 1, 8.48 with 3 and
        8.75 with 6 passes: the ratio window does not converge to a better set, it drifts.
    min_lit : lights with s.n below this are left out of the ratio pass (grazing, unlit).
    engine : "auto" (the compiled per-pixel loop, facette.recon._ps_robust_jit) or "arrays" (the
        array code: block by block, numpy).
    Returns a `PSResult`: normal, albedo (rho per channel on the kept lights), valid (False for
    black pixels, fewer than 3 usable values, or a degenerate kept set), shadow = usable lights
    with s.n <= 0 or a value below 0.5 x the diffuse fit s.g, specular = lights left out with a
    value above 1.5 x s.g (maps for the later stages; the normal does not use them), residual = relative least-squares
    residual on the kept lights; info holds the rounds run and the median normal change (deg)
    of each round.

    Notes: pass 0 keeps the ranks [trim, 1 - trim] of E_i (intensity); pass k keeps the same
    ranks of q_i = E_i / (s_i . n_{k-1}) among the lit usable lights, and solves least squares
    g = argmin sum_kept (E_i - s_i . g)^2, n = g / |g| (Woodham's equation on the kept lights).
    """
    if not 0 <= trim < 0.5:
        raise ValueError(f"trim must be in [0, 0.5) (share dropped at each end), got {trim}")
    if not 0 <= noise < 0.2:
        raise ValueError(f"noise is the relative noise of the values, in [0, 0.2); got {noise}")
    if t_dark is not None and not 0 <= t_dark < 1:
        raise ValueError(f"t_dark must be None or in [0, 1) (share of the pixel's brightest value), "
                         f"got {t_dark}")
    if rounds < 0 or int(rounds) != rounds:
        raise ValueError(f"rounds must be a whole number >= 0, got {rounds}")
    if engine not in ("auto", "arrays"):
        raise ValueError(f"engine must be 'auto' or 'arrays', got {engine!r}")
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    m, h, w, c = images.shape
    res = _empty_result(h, w, m, c, "rank_trimmed")
    idx, e_all, e, sub = _gather(images, mask, channel)
    res.info = {"pixels": int(idx.size), "rounds": int(rounds), "trim": float(trim),
                "noise": float(noise), "t_dark": t_dark}
    if idx.size == 0:
        res.info["median_change_deg"] = []
        return res
    s = _pixel_dirs(light_dirs, idx)
    ok = _usable(e, saturation)
    n_pix = idx.size
    normal = np.zeros((3, n_pix), np.float32)
    found = np.zeros(n_pix, bool)
    resid = np.zeros(n_pix, np.float32)
    changes = np.zeros((int(rounds), n_pix), np.float32)
    if engine == "auto":      # the compiled loop (`_ps_robust_jit`), lights per pixel (distant: a view)
        from ._ps_robust_jit import rank_trimmed_pixels
        s32 = s.astype(np.float32, copy=False)
        s3 = np.broadcast_to(s32, (n_pix,) + s.shape) if s.ndim == 2 else s32
        rho = np.empty((n_pix, c), np.float32)
        below, above = np.empty((n_pix, m), bool), np.empty((n_pix, m), bool)     # shadow, specular maps
        rank_trimmed_pixels(e, ok, s3, e_all, np.arange(n_pix) if sub is None else sub, trim, min_keep, 3 * noise,
                            -1.0 if t_dark is None else t_dark, int(rounds), min_lit, SHADOW_BELOW, SPECULAR_ABOVE,
                            normal, found, resid, changes, below, above, rho)
    else:
        keep = np.zeros((m, n_pix), bool)
        below, above = np.empty((m, n_pix), bool), np.empty((m, n_pix), bool)     # filled by block
        e = np.where(ok, e, np.float32(0))            # missing values never enter a sum
        _rank_trimmed_arrays(e, ok, s, trim, min_keep, noise, t_dark, int(rounds), min_lit, normal, found, keep,
                             resid, changes, below, above)
        rho = _albedo(e_all, s, normal, keep & ok, idx=sub)
        below, above = below.T, above.T
    _scatter(res, idx, "normal", normal.T)
    _scatter(res, idx, "albedo", np.where(found[:, None], rho, 0.0))
    _scatter(res, idx, "valid", found)
    _scatter(res, idx, "shadow", below & found[:, None])
    _scatter(res, idx, "specular", above & found[:, None])
    _scatter(res, idx, "residual", resid)
    res.info["median_change_deg"] = [float(np.median(ch[found])) if found.any() else 0.0
                                     for ch in changes]
    return res


# ----------------------------------------------------------------------------- RPCA

def _svt(x, tau):
    """Singular-value thresholding of a short, wide x (m, N), m << N, through its Gram matrix:
    x = U S V^T, returns U max(S - tau, 0) V^T = U diag(max(S - tau, 0) / S) U^T x, and the
    number of singular values kept (and above 1e-3 of the largest)."""
    gram = (x @ x.T).astype(np.float64)
    ev, u = np.linalg.eigh(gram)
    sv = np.sqrt(np.maximum(ev, 0))
    shrink = np.where(sv > tau, (sv - tau) / np.where(sv > 0, sv, 1), 0.0)
    proj = (u * shrink) @ u.T
    # rank counted above 1e-3 of the largest: float32 round-off leaves tiny singular values
    # above the shrinking threshold 1/mu late in the iterations
    return proj.astype(x.dtype) @ x, int(np.sum(sv > max(tau, 1e-3 * sv.max())))


def rpca_inexact_alm(d, observed, lam=None, tol=1e-6, max_iter=500, rho=1.5):
    """min ||A||_* + lam ||E||_1 subject to P_obs(D) = P_obs(A + E) (inexact ALM, Lin et al.
    2009, Alg. 5; the entries outside `observed` are free in E, Wu et al. 2010 eq. 6).

    d : (m, N) float32, observed (m, N) bool; lam : default 1 / sqrt(max(m, N)).
    Returns (A (m, N), info dict with iterations, final rank, relative constraint error)."""
    m, n = d.shape
    lam = 1.0 / np.sqrt(max(m, n)) if lam is None else float(lam)
    d = np.where(observed, d, np.float32(0)).astype(np.float32)
    d_norm = float(np.linalg.norm(d))
    if d_norm == 0:
        return np.zeros_like(d), {"iterations": 0, "rank": 0, "error": 0.0}
    two_norm = float(np.sqrt(np.linalg.eigvalsh((d @ d.T).astype(np.float64))[-1]))
    y = d / np.float32(max(two_norm, np.abs(d).max() / lam))   # dual start (Lin et al.'s J(D))
    mu = 1.25 / two_norm
    mu_max = mu * 1e7
    e = np.zeros_like(d)
    buf, tmp, z = np.empty_like(d), np.empty_like(d), np.empty_like(d)
    missing = ~observed
    err, it, rank = np.inf, 0, 0
    for it in range(1, max_iter + 1):       # in place: a dozen passes over (m, N) per iteration
        np.subtract(d, e, out=buf)
        buf += y * np.float32(1.0 / mu)              # D - E + Y / mu
        a, rank = _svt(buf, 1.0 / mu)
        buf += e
        buf -= a                                     # T = D - A + Y / mu
        th = np.float32(lam / mu)
        np.clip(buf, -th, th, out=tmp)
        np.subtract(buf, tmp, out=e)                 # soft threshold on the observed entries
        np.copyto(e, buf, where=missing)             # free where missing
        np.subtract(d, a, out=z)
        z -= e
        np.multiply(z, np.float32(mu), out=tmp)
        y += tmp
        mu = min(mu * rho, mu_max)
        err = float(np.linalg.norm(z)) / d_norm
        if err < tol:
            break
    return a, {"iterations": it, "rank": rank, "error": err}


def ps_rpca_wu2010(images, light_dirs, mask=None, channel=None, saturation=None,
                   t_shadow=T_SHADOW_RPCA, lam=None, tol=1e-6, max_iter=500):
    """Low-rank photometric stereo (Wu et al. 2010): RPCA of the lights x pixels matrix.

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors (distant lights: the rank-3 model needs one direction per
        light for every pixel; per-pixel directions raise ValueError).
    mask, channel, saturation : as `ps_woodham1980` (NaN, inf and values >= saturation missing).
    t_shadow : a value below t_shadow x the pixel's brightest usable value is a shadow, a
        missing entry (Wu et al. §3.2); in [0, 1).
    lam : weight of the sparse error (default 1 / sqrt(max(m, pixels)), Candes et al.).
    tol, max_iter : stop when ||D - A - E||_F / ||D||_F < tol or after max_iter iterations.
    Returns a `PSResult`: normals n = g / |g| with g = pinv(S) A (eq. 9), albedo fitted on the
    observed entries; shadow = entries left out as shadows; specular = observed entries the
    sparse error took more than 10 % of (a value above the low-rank one); residual = relative
    least-squares residual ||E - S g|| / ||E|| on the observed values. info: iterations, rank, constraint error.
    Pixels with fewer than 3 observed values or all black are not valid. Memory: about
    6 x m x pixels x 4 bytes (the whole matrix is solved at once).
    """
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    if light_dirs.ndim != 2:
        raise ValueError("ps_rpca_wu2010 needs distant lights, light_dirs (m, 3): with per-pixel "
                         "directions the lights x pixels matrix is not rank 3; use "
                         "ps_rank_trimmed or ps_woodham1980 for near lights")
    if not 0 <= t_shadow < 1:
        raise ValueError(f"t_shadow must be in [0, 1) (share of the pixel's brightest value), "
                         f"got {t_shadow}")
    m, h, w, c = images.shape
    res = _empty_result(h, w, m, c, "rpca_wu2010")
    idx, e_all, e, sub = _gather(images, mask, channel)
    res.info = {"pixels": int(idx.size)}
    if idx.size == 0:
        return res
    ok = _usable(e, saturation)
    e = np.where(ok, e, np.float32(0))
    peak = e.max(axis=0)
    lit = ok & (e > t_shadow * peak) & (e > 0)
    a, info = rpca_inexact_alm(e, lit, lam=lam, tol=tol, max_iter=max_iter)
    res.info.update(info)
    enough = lit.sum(0) >= 3
    g = np.linalg.pinv(light_dirs).astype(np.float32) @ a
    normal, found = _unit(g)
    found &= enough
    normal = np.where(found, normal, np.float32(0))
    rho = _albedo(e_all, light_dirs, normal, lit, idx=sub)
    sparse = lit & (e - a > 0.1 * np.maximum(a, 1e-12))
    _scatter(res, idx, "normal", normal.T)
    _scatter(res, idx, "albedo", np.where(found[:, None], rho, 0.0))
    _scatter(res, idx, "valid", found)
    _scatter(res, idx, "shadow", (ok & ~lit & found).T)
    _scatter(res, idx, "specular", (sparse & found).T)
    _scatter(res, idx, "residual", _rel_residual(e, light_dirs, g, lit) * found)
    return res
