"""Photometric stereo: Woodham's least squares and Tautzia's hierarchical elimination.

Conventions (docs/conventions.md): camera frame x right, y up, z towards the camera; light
directions are unit vectors from the surface towards the light, in that frame.
Images are linear radiance already divided by each light's intensity, so that a
Lambertian surface of reflectance rho gives E_i = (rho / pi) s_i . n  (thesis eq 4.3).
"""
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from facette._threads import run_blocks
from facette.errors import InsufficientData

__all__ = ["PSResult", "ps_woodham1980", "ps_hierarchical_tautzia2016", "triplet_inverses",
           "near_light_directions"]

T_OMBRE = 1.5          # rad, thesis §4.2.1 ("slightly below pi/2")
T_SPEC = 0.25          # variance of the kept unit normals, thesis §4.2.1
T_SOURCE = 10.0        # max |entry| of S^-1; the thesis gives no value: 10 drops the 36
                       # near-collinear triplets of the 12-LED rig (entries 10.6-43) and keeps 184
T_RESIDUAL = 0.03      # relative least-squares residual under which a pixel skips the hierarchy
MAX_TRIPLETS = 2000    # best-conditioned triplets kept when there are more (many lights)
_CHUNK = 16384         # pixels per block in the hierarchical stage (~45 MB of float32 per block)


@dataclass
class PSResult:
    """Per-pixel photometric-stereo output, all at the image size (H, W).

    normal : (H, W, 3) float32 unit vectors, camera frame; (0, 0, 0) where not valid.
    albedo : (H, W, C) float32 Lambertian reflectance rho per channel (eq 4.3), 0 where not valid.
    valid : (H, W) bool, inside the mask and a normal was found.
    n_triplets : (H, W) int16, light triplets kept for the final mean (hierarchical; the
        number of conditioned triplets for pixels that skipped the hierarchy; 0 for least
        squares).
    shadow, specular : (H, W, m) bool, lights removed by the shadow test (T_ombre) and
        by the specular test (T_spec); all False for least squares.
    residual : (H, W) float32, relative least-squares residual ||E - S g|| / ||E||
        on the chosen channel (a confidence map: high means non-Lambertian or shadowed).
    skipped : (H, W) bool, pixels that least squares already explained (residual <
        t_residual, no light near grazing), so the hierarchy did not run on them.
    material : (H, W) int16, the BRDF-aware methods' material of each pixel (an index into
        info["materials"]; −1 where not valid), or None.
    """
    normal: np.ndarray
    albedo: np.ndarray
    valid: np.ndarray
    n_triplets: np.ndarray
    shadow: np.ndarray
    specular: np.ndarray
    residual: np.ndarray
    skipped: np.ndarray
    method: str = ""
    info: dict = field(default_factory=dict)
    material: np.ndarray = None


# ----------------------------------------------------------------------------- input checks

def _check_inputs(images, light_dirs, mask, channel):
    images = np.asarray(images)
    if images.ndim == 3:
        images = images[..., None]
    if images.ndim != 4:
        raise ValueError(f"images must have shape (m, H, W) or (m, H, W, C), got {images.shape}")
    m, h, w, c = images.shape
    if m < 4:
        raise InsufficientData(f"photometric stereo needs at least 4 lights here (3 to solve, one "
                               f"more to check the fit); got {m}", hint="capture with more lights")
    light_dirs = np.asarray(light_dirs)
    light_dirs = light_dirs.astype(np.float64 if light_dirs.ndim == 2 else np.float32)
    if light_dirs.shape == (m, 3):
        pass
    elif light_dirs.shape == (h, w, m, 3):
        pass
    else:
        raise ValueError(f"light_dirs must have shape ({m}, 3) or ({h}, {w}, {m}, 3) for {m} "
                         f"images of {h}x{w}, got {light_dirs.shape}")
    if not np.all(np.isfinite(light_dirs)):
        raise ValueError("light_dirs contains NaN or inf; check the calibration profile")
    norms = np.linalg.norm(light_dirs, axis=-1)
    if np.any(np.abs(norms - 1) > 1e-3):
        raise ValueError("light_dirs must be unit vectors (found norms from "
                         f"{norms.min():.4g} to {norms.max():.4g}); normalise them first")
    if mask is None:
        mask = np.ones((h, w), bool)
    mask = np.asarray(mask, bool)
    if mask.shape != (h, w):
        raise ValueError(f"mask has shape {mask.shape}, images are {h}x{w}")
    if channel is None:
        channel = 1 if c == 3 else 0  # the thesis uses the green channel (eq 4.7)
    if not 0 <= channel < c:
        raise ValueError(f"channel {channel} out of range for {c}-channel images")
    return images, light_dirs, mask, channel


def _usable(values, saturation):
    """(N, m) bool: finite and (when given) below the saturation level."""
    ok = np.isfinite(values)
    if saturation is not None:
        ok &= values < saturation
    return ok


def near_light_directions(positions_mm, shape, pixel_pitch_mm, heights_mm=None, rows=None):
    """Per-pixel light directions and 1/r^2 fall-off for lights at finite distance.

    positions_mm : (m, 3) light positions in the camera frame (origin on the optical axis
        in the object plane z = 0, which passes through the image centre).
    shape : (H, W); pixel_pitch_mm : object-side size of one pixel (mm).
    heights_mm : optional surface heights (default: the plane z = 0); rows : optional (r0, r1), those rows only.
    Returns (dirs (H, W, m, 3) unit vectors towards each light, falloff (H, W, m)):
    falloff = |P|^2 / |P - X|^2, the irradiance relative to the one at the origin, so
    that intensities calibrated at the origin stay valid (divide images by it).
    """
    positions_mm = np.asarray(positions_mm, dtype=np.float64)
    if positions_mm.ndim != 2 or positions_mm.shape[1] != 3:
        raise ValueError(f"positions_mm must have shape (m, 3), got {positions_mm.shape}")
    h, w = shape
    x = (np.arange(w) - (w - 1) / 2) * pixel_pitch_mm
    y = -(np.arange(*(rows or (0, h))) - (h - 1) / 2) * pixel_pitch_mm      # row 0 is the top, y points up
    pts = np.zeros((y.size, w, 3))
    pts[..., 0] = x[None, :]
    pts[..., 1] = y[:, None]
    if heights_mm is not None:
        pts[..., 2] = heights_mm
    d = positions_mm[None, None, :, :] - pts[:, :, None, :]
    r2 = np.sum(d * d, axis=-1)
    dirs = d / np.sqrt(r2)[..., None]
    falloff = np.sum(positions_mm ** 2, axis=-1)[None, None, :] / r2
    return dirs.astype(np.float32), falloff.astype(np.float32)


# ----------------------------------------------------------------------------- least squares

def _ls_normals(e, s, ok):
    """Least squares g = argmin ||W (E - S g)|| per pixel (light-major layout).

    e : (m, N) float32 values; s : (m, 3) or (N, m, 3); ok : (m, N) bool weights.
    Returns g (3, N) float32 (rho/pi times the normal); NaN where fewer than 3 usable lights.
    """
    n = e.shape[1]
    e0 = np.where(ok, e, np.float32(0))
    if s.ndim == 2 and ok.all():
        return np.linalg.pinv(s).astype(np.float32) @ e0
    # Weighted normal equations, batched 3x3 (per-pixel lights or missing values).
    g = np.full((3, n), np.nan, np.float32)
    w = ok.astype(np.float32)
    if s.ndim == 2:
        a = np.einsum("mn,mi,mj->nij", w, s, s)
        b = np.einsum("mn,mi->ni", w * e0, s)
    else:
        a = np.einsum("mn,nmi,nmj->nij", w, s, s)
        b = np.einsum("mn,nmi->ni", w * e0, s)
    good = ok.sum(0) >= 3
    good &= np.abs(np.linalg.det(a)) > 1e-9
    if good.any():
        g[:, good] = np.linalg.solve(a[good].astype(np.float64),
                                     b[good][..., None].astype(np.float64))[..., 0].T
    return g


def _shading(s, n):
    """s.n as (m, N): s (m, 3) or (N, m, 3), n (3, N)."""
    return (s.astype(np.float32) @ n) if s.ndim == 2 else np.einsum("nmi,in->mn", s, n)


def _albedo(e_all, s, n, keep, chunk=262144, idx=None):
    """rho per channel for fixed unit normals: rho = pi * sum(E s.n) / sum((s.n)^2) over kept lights
    whose value in that channel is finite (0 where none is).

    e_all : (m, N, C), or with idx (N,) the whole (m, H*W, C) images whose pixels idx are
    gathered block by block (no copy of every pixel); s : (m, 3) or (N, m, 3); n : (3, N);
    keep : (m, N) bool. Returns (N, C).
    """
    m, c = e_all.shape[0], e_all.shape[2]
    out = np.zeros((n.shape[1], c), np.float32)
    if idx is not None:   # each pixel's C floats as one opaque item: a gather 4x faster
        src = np.ascontiguousarray(e_all, dtype=np.float32)
        rows = src.view(np.dtype((np.void, 4 * c))).reshape(m, -1)

    def block(a):
        sl = slice(a, a + chunk)
        if idx is None:
            eb = e_all[:, sl]
        else:
            eb = np.take(rows, idx[sl], axis=1).view(np.float32).reshape(m, -1, c)
        sn = _shading(s if s.ndim == 2 else s[sl], n[:, sl])
        w = keep[:, sl] & (sn > 0)
        sn_w = np.where(w, sn, np.float32(0))
        for ch in range(c):
            # a light kept on the test channel may be missing in this one (saturated in red
            # alone: DiLiGenT reading's highlights): each channel sums its own usable lights
            fin = np.isfinite(eb[:, :, ch])
            sn_c = np.where(fin, sn_w, np.float32(0))
            den = np.sum(sn_c * sn_c, axis=0)
            good = den > 1e-12
            num = np.sum(np.where(w & fin, eb[:, :, ch], np.float32(0)) * sn_c, axis=0)
            out[sl, ch] = np.where(good, np.pi * num / np.where(good, den, 1.0), 0.0)

    run_blocks(block, range(0, n.shape[1], chunk))
    return out


def _gather(images, mask, channel):
    """Pixels of the mask, light-major: idx (N,), e_all, e (m, N) float32, sub.

    sub None: e_all is (m, N, C) float32 (every pixel); otherwise e_all is the whole
    (m, H*W, C) images and sub = idx, for `_albedo` to gather block by block (a copy of
    all the masked pixels' colours costs more than the albedo itself)."""
    m, h, w, c = images.shape
    flat = images.reshape(m, h * w, c)
    if mask.all():
        idx = np.arange(h * w)
        e_all = flat if flat.dtype == np.float32 else flat.astype(np.float32)
        return idx, e_all, np.ascontiguousarray(e_all[:, :, channel]), None
    idx = np.flatnonzero(mask.ravel())
    return idx, flat, flat[:, idx, channel].astype(np.float32, copy=False), idx


def _empty_result(h, w, m, c, method):
    return PSResult(normal=np.zeros((h, w, 3), np.float32), albedo=np.zeros((h, w, c), np.float32),
                    valid=np.zeros((h, w), bool), n_triplets=np.zeros((h, w), np.int16),
                    shadow=np.zeros((h, w, m), bool), specular=np.zeros((h, w, m), bool),
                    residual=np.zeros((h, w), np.float32), skipped=np.zeros((h, w), bool),
                    method=method)


def _scatter(res, idx, name, values):
    arr = getattr(res, name)
    flat = arr.reshape((-1,) + arr.shape[2:])
    if len(idx) == len(flat):      # every pixel (idx from `_gather`: sorted, distinct): a copy, no fancy index
        flat[...] = values
    else:
        flat[idx] = values


def _pixel_dirs(light_dirs, idx):
    if light_dirs.ndim == 2:
        return light_dirs
    h, w, m, _ = light_dirs.shape
    return light_dirs.reshape(h * w, m, 3)[idx].astype(np.float32)


def _ls_stage(e, s, ok, chunk=262144):
    """Least squares on the chosen channel: unit normals (3, N), found (N,), relative residual (N,)."""
    n_pix = e.shape[1]
    n = np.zeros((3, n_pix), np.float32)
    found = np.zeros(n_pix, bool)
    resid = np.zeros(n_pix, np.float32)

    def block(a):
        sl = slice(a, a + chunk)
        eb, okb = e[:, sl], ok[:, sl]
        sb = s if s.ndim == 2 else s[sl]
        g = _ls_normals(eb, sb, okb)
        norm = np.sqrt(np.sum(g * g, axis=0))
        fb = np.isfinite(norm) & (norm > 1e-12)
        n[:, sl] = np.where(fb, g / np.where(fb, norm, 1.0), np.float32(0))
        diff = np.where(okb, eb - _shading(sb, np.nan_to_num(g)), np.float32(0))
        e_norm = np.sqrt(np.sum(np.where(okb, eb, np.float32(0)) ** 2, axis=0))
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.sqrt(np.sum(diff * diff, axis=0)) / e_norm
        resid[sl] = np.where(fb & (e_norm > 0), r, np.inf)
        found[sl] = fb

    run_blocks(block, range(0, n_pix, chunk))
    return n, found, resid


def ps_woodham1980(images, light_dirs, mask=None, channel=None, saturation=None):
    """Least-squares photometric stereo (Woodham 1980), the baseline.

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights (camera frame), or (H, W, m, 3) per pixel
        (near lights, see `near_light_directions`).
    mask : (H, W) bool, pixels to solve (default all).
    channel : channel used for the normal (default green when C == 3, as the thesis).
    saturation : values >= this are treated as missing (like NaN); None: no limit.
    Returns a `PSResult`. Pixels with fewer than 3 usable values, or all black, are not valid.

    Notes: g = argmin ||E - S g||, n = g / ||g||, rho = pi ||g|| fitted per channel (eq 4.3).
    """
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    m, h, w, c = images.shape
    res = _empty_result(h, w, m, c, "woodham1980")
    idx, e_all, e, sub = _gather(images, mask, channel)
    if idx.size == 0:
        return res
    s = _pixel_dirs(light_dirs, idx)
    ok = _usable(e, saturation)
    n, found, resid = _ls_stage(e, s, ok)
    rho = _albedo(e_all, s, n, ok, idx=sub)
    _scatter(res, idx, "normal", n.T)
    _scatter(res, idx, "albedo", np.where(found[:, None], rho, 0.0))
    _scatter(res, idx, "valid", found)
    _scatter(res, idx, "residual", np.where(np.isfinite(resid), resid, 0.0))
    res.info = {"pixels": int(idx.size)}
    return res


# ----------------------------------------------------------------------------- hierarchical

def triplet_inverses(light_dirs, t_source=T_SOURCE, max_triplets=None):
    """The global step of thesis §4.2.1: all C(m,3) triplets and their inverses.

    light_dirs : (m, 3) unit vectors. Returns (triplets (K, 3) int, inverses (K, 3, 3),
    kept (K,) bool) where kept = |det S| > 1e-6 and max |S^-1| <= t_source; with
    max_triplets, only that many of the best-conditioned ones are kept (ties kept).
    """
    light_dirs = np.asarray(light_dirs, dtype=np.float64)
    trip = np.array(list(combinations(range(len(light_dirs)), 3)), dtype=np.intp)
    s = light_dirs[trip]                                   # (K, 3, 3), rows = lights
    det = np.linalg.det(s)
    kept = np.abs(det) > 1e-6
    inv = np.zeros_like(s)
    inv[kept] = np.linalg.inv(s[kept])
    worst = np.where(kept, np.abs(inv).max(axis=(1, 2)), np.inf)
    kept &= worst <= t_source
    if max_triplets is not None and kept.sum() > max_triplets:
        # many lights: keep the best-conditioned triplets only (cost grows as C(m, 3))
        kept &= worst <= np.sort(worst[kept])[max_triplets - 1]
    return trip, inv, kept


def _triplet_matrices(trip, inv):
    """(m, 3K) float32 M such that (E @ M)[j*K + k] = (S_k^-1 E_k)[j] (eq 4.7): one product
    gives every triplet's three components."""
    m = int(trip.max()) + 1 if trip.size else 0
    k = len(trip)
    big = np.zeros((m, 3, k), np.float32)
    for a in range(3):
        for j in range(3):
            big[trip[:, a], j, np.arange(k)] += inv[:, j, a]
    return big.reshape(m, 3 * k)


def _triplet_normals_local(e, s, trip, t_source):
    """Per-pixel triplets (near lights) by Cramer's rule: g = sum_a E_a (s_b x s_c) / det.

    e : (N, m); s : (N, m, 3). Returns g (N, 3, K) and conditioned (N, K) bool.
    """
    s1, s2, s3 = s[:, trip[:, 0]], s[:, trip[:, 1]], s[:, trip[:, 2]]   # (N, K, 3)
    c1, c2, c3 = np.cross(s2, s3), np.cross(s3, s1), np.cross(s1, s2)
    det = np.sum(s1 * c1, axis=-1)
    good = np.abs(det) > 1e-6
    safe = np.where(good, det, 1.0)[..., None]
    e1, e2, e3 = (e[:, trip[:, a]][..., None] for a in range(3))
    g = ((e1 * c1 + e2 * c2 + e3 * c3) / safe).astype(np.float32)
    # the columns of S^-1 are the cofactor vectors divided by det
    cof = np.maximum(np.abs(c1).max(-1), np.maximum(np.abs(c2).max(-1), np.abs(c3).max(-1)))
    good &= cof / np.abs(safe[..., 0]) <= t_source
    return np.ascontiguousarray(np.transpose(g, (0, 2, 1))), good


def _hierarchy_block(e, s, ok, trip, mats, t_ombre, t_spec, t_source):
    """The local step of thesis §4.2.1 on a block of N pixels. The triplet normals are held
    as one (N, 3, K) array so that each reduction over triplets is one matrix product.

    e : (N, m); s : (m, 3) or (N, m, 3); ok : (N, m) usable values; trip : (K, 3) the
    triplets in play; mats : `_triplet_matrices` for global lights, None for per-pixel.
    Returns normal (N, 3), n_kept (N,), shadow (N, m), specular (N, m), found (N,).
    """
    n_pix, m = e.shape
    k = len(trip)
    e0 = np.where(ok, e, 0.0).astype(np.float32)
    if mats is not None:
        g = (e0 @ mats).reshape(n_pix, 3, k)
        tvalid = None
    else:
        g, tvalid = _triplet_normals_local(e0, s, trip, t_source)
    norm = np.sqrt(np.einsum("njk,njk->nk", g, g))
    good = norm > 1e-12
    tvalid = good if tvalid is None else tvalid & good
    inv_norm = np.where(tvalid, 1.0 / np.where(good, norm, 1.0), 0.0).astype(np.float32)
    nh = np.multiply(g, inv_norm[:, None, :], out=g)         # unit normals, 0 where invalid (in place)
    uses = np.zeros((len(trip), m), np.float32)              # triplet k uses light l
    uses[np.arange(len(trip))[:, None], trip] = 1.0

    def alive_triplets(alive, rows=slice(None)):
        dead = (~alive).astype(np.float32) @ uses.T          # dead lights in each triplet
        return (dead == 0) & tvalid[rows]

    alive = ok.copy()
    all_ok = bool(ok.all())
    # with every light usable the alive triplets are the valid ones, and nh is already 0
    # elsewhere: no mask product needed (the common case)
    ta = tvalid.copy() if all_ok else alive_triplets(alive)
    # Shadows: per light, the mean of the normals of the triplets using it; its angle to the light.
    w = nh if all_ok else nh * ta[:, None, :]
    mean_l = (w.reshape(3 * n_pix, k) @ uses).reshape(n_pix, 3, m)
    sl = s.astype(np.float32)
    dot = np.einsum("njl,lj->nl", mean_l, sl) if s.ndim == 2 else np.einsum("njl,nlj->nl", mean_l, sl)
    ml = np.sqrt(np.einsum("njl,njl->nl", mean_l, mean_l))
    shadow = alive & (ml > 0) & (dot < np.cos(t_ombre) * ml)
    alive &= ~shadow
    rows = np.flatnonzero(shadow.any(axis=1))                # only these lose triplets
    if rows.size:
        ta[rows] = alive_triplets(alive[rows], rows)
    # Specularities: while the variance of the kept normals exceeds T_spec and more than one
    # triplet is left, drop the brightest remaining light and every triplet using it.
    specular = np.zeros_like(shadow)
    todo = None                                              # None: every pixel of the block
    for _ in range(m):
        if todo is not None and todo.size == 0:
            break
        tat = (ta if todo is None else ta[todo]).astype(np.float32)
        cnt = tat.sum(1)
        inv_cnt = 1.0 / np.maximum(cnt, 1)
        mean = np.einsum("nk,njk->nj", tat, nh if todo is None else nh[todo]) * inv_cnt[:, None]
        var = 1.0 - np.sum(mean * mean, axis=1)              # total variance of unit vectors
        act = (cnt > 1) & (var > t_spec)
        todo = np.flatnonzero(act) if todo is None else todo[act]
        if todo.size == 0:
            break
        used = (tat[act] @ uses) > 0                          # lights still in a kept triplet
        brightest = np.argmax(np.where(used, e0[todo], -np.inf), axis=1)
        alive[todo, brightest] = False
        specular[todo, brightest] = True
        ta[todo] = alive_triplets(alive[todo], todo)
    taf = ta.astype(np.float32)
    cnt = ta.sum(1)
    mean = np.einsum("nk,njk->nj", taf, nh)
    mn = np.linalg.norm(mean, axis=1)
    found = (cnt > 0) & (mn > 1e-12)
    normal = np.where(found[:, None], mean / np.where(found, mn, 1.0)[:, None], 0.0)
    return normal, cnt, shadow, specular, found


def ps_hierarchical_tautzia2016(images, light_dirs, mask=None, channel=None, saturation=None,
                                t_ombre=T_OMBRE, t_spec=T_SPEC, t_source=T_SOURCE,
                                t_residual=T_RESIDUAL, max_triplets=MAX_TRIPLETS, chunk=_CHUNK):
    """Photometric stereo with hierarchical elimination of shadows and specularities.

    images : (m, H, W) or (m, H, W, C) float, linear, divided by each light's intensity, m >= 4.
    light_dirs : (m, 3) unit vectors towards the lights, or (H, W, m, 3) per pixel.
    mask : (H, W) bool (default all); channel : default green when C == 3 (thesis).
    saturation : values >= this are treated as missing, as are NaN values.
    t_ombre : shadow angle threshold (rad), default 1.5. t_spec : threshold on the variance
        of the kept unit normals, 1 - ||mean||^2 in [0, 1], default 0.25.
    t_source : triplets whose inverse has an entry above this are dropped (default 10).
    t_residual : pixels whose least-squares relative residual is below this, with every
        light usable and none at grazing incidence (angle < t_ombre), keep the least-squares
        normal and skip the hierarchy (0 disables the shortcut).
    max_triplets : at most this many triplets, the best-conditioned (default 2000: no effect
        with the rig's 12 lights, 184 triplets; 96 DiLiGenT lights would give 142880).
        None: all of them, as the thesis (cost per pixel grows as C(m, 3)).
    Returns a `PSResult`; `info` holds the triplet counts and the share of skipped pixels.

    Notes: thesis §4.2.1. Global step: all C(m,3) triplets, inverses, T_source test.
    Local step per pixel: n_k = S_k^-1 E_k / ||S_k^-1 E_k|| (eq 4.7, green channel); a light
    whose mean triplet normal makes an angle > T_ombre with it is a shadow, and every triplet
    using it is dropped; then while the variance of the kept normals > T_spec and more than
    one triplet remains, the brightest remaining light is dropped; final normal = mean of the
    kept normals. Eq 4.7 is printed with [p q 1]^T on the left, which is not a unit vector:
    the right-hand side is the unit normal n, and (p, q) = (-n_x/n_z, -n_y/n_z).
    """
    images, light_dirs, mask, channel = _check_inputs(images, light_dirs, mask, channel)
    m, h, w, c = images.shape
    res = _empty_result(h, w, m, c, "hierarchical_tautzia2016")
    trip, inv, kept = (triplet_inverses(light_dirs, t_source, max_triplets) if light_dirs.ndim == 2
                       else (np.array(list(combinations(range(m), 3))), None, None))
    if kept is not None and not kept.any():
        raise ValueError(f"no light triplet passes T_source = {t_source} (all inverses have larger "
                         "entries): the lights are nearly coplanar; raise t_source or check directions")
    idx, e_all, e, sub = _gather(images, mask, channel)
    res.info = {"pixels": int(idx.size), "triplets": len(trip),
                "triplets_conditioned": int(kept.sum()) if kept is not None else None}
    if idx.size == 0:
        res.info["skipped_fraction"] = 0.0
        return res
    s = _pixel_dirs(light_dirs, idx)
    ok = _usable(e, saturation)
    n_ls, found_ls, resid = _ls_stage(e, s, ok)
    if t_residual > 0:
        sn = _shading(s, n_ls)
        skip = (found_ls & ok.all(0) & (resid < t_residual) & np.all(sn > np.cos(t_ombre), axis=0))
    else:
        skip = np.zeros(idx.size, bool)
    normal = np.where(skip, n_ls, np.float32(0))                  # (3, N)
    found = skip.copy()
    n_trip = np.zeros(idx.size, np.int16)
    n_trip[skip] = int(kept.sum()) if kept is not None else len(trip)
    shadow = np.zeros((idx.size, m), bool)
    specular = np.zeros((idx.size, m), bool)
    rest = np.flatnonzero(~skip)
    if kept is not None:
        trip_used, mats = trip[kept], _triplet_matrices(trip[kept], inv[kept])
    else:
        trip_used, mats = trip, None
    # many lights mean many triplets (96 lights: 142880): keep each (pixels, triplets) array
    # near 2^24 elements
    chunk = int(min(chunk, max(16, 2 ** 24 // max(len(trip_used), 1))))
    def block(a):
        sel = rest[a:a + chunk]
        s_blk = s if s.ndim == 2 else s[sel]
        nb, cb, shb, spb, fb = _hierarchy_block(e[:, sel].T, s_blk, ok[:, sel].T, trip_used, mats,
                                                t_ombre, t_spec, t_source)
        normal[:, sel], n_trip[sel], shadow[sel], specular[sel], found[sel] = nb.T, cb, shb, spb, fb

    run_blocks(block, range(0, rest.size, chunk))
    keep = ok & ~shadow.T & ~specular.T
    rho = _albedo(e_all, s, normal, keep, idx=sub)
    _scatter(res, idx, "normal", normal.T)
    _scatter(res, idx, "albedo", np.where(found[:, None], rho, 0.0))
    _scatter(res, idx, "valid", found)
    _scatter(res, idx, "n_triplets", n_trip)
    _scatter(res, idx, "shadow", shadow)
    _scatter(res, idx, "specular", specular)
    _scatter(res, idx, "residual", np.where(np.isfinite(resid), resid, 0.0))
    _scatter(res, idx, "skipped", skip)
    res.info["skipped_fraction"] = float(skip.mean())
    return res
