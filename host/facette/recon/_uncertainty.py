"""How far each normal may be off: an angular uncertainty (degrees) from the data and the solution.

`normal_uncertainty(images, light_dirs, normals, mask)` is a post-pass over any method's normals
(it reads neither the solver's internals nor its model): per pixel the observations are
explained by a flexible isotropic reflectance around the given normal n,

    E_i ≈ (n·l_i)_+ Σ_{a ≤ DEGREE} α_a (n·h_i)^a,     h_i = (l_i + v) / |l_i + v|,

the α linear least squares for that n (variable projection); the residual r(n) (m,) that
remains is a function of the normal's two tangent angles θ. Its Jacobian J (m, 2) at n (finite
differences) gives the curvature of the cost, and the Gauss-Newton step δ = -(JᵀJ)⁻¹Jᵀr how
far the data's own best normal lies from n. The uncertainty combines both (radians²):

    u² = tr[(JᵀJ)⁻¹ Jᵀ diag(r²) J (JᵀJ)⁻¹] + |δ|²

the first term the sandwich (heteroscedastic) covariance of the normal, which grows with the
misfit and with a poor spread of the lights that carried the pixel (few lights, all on one
side, near grazing); the second the disagreement between the solution and the data.

What a local fit cannot see: inter-reflections, cast shadows and a wrong reflectance leave data a
smooth reflectance explains well at the wrong normal. Their errors are not a surface's: the normal
field's curl (`curl_angle`, the slopes' loop sum round each 2x2 plaquette, as an angle, gathered over
CURL_SIGMA pixels) is ~0 for any height field and grows where such errors bend the normals. The map
written is the radius of the 90 % band, in degrees,

    band = sqrt((BAND_SCALE u)² + (K_CURL curl)²)

BAND_SCALE chosen on renders so that 90 % of their normals lie within the local fit's band, K_CURL on
the path-traced renders (`facette bench uncertainty`); DiLiGenT's photographs only confirm them (the
figures are in the constants' comments and the bench). Noise alone also has a curl: on noise-only
renders the band over-covers (≈ 1.0) and ranks worse than the local fit's alone.

Lights carry a pixel where their value is usable (finite, below saturation) and above
T_DARK × the pixel's brightest (a dark value is a shadow the model does not describe); the
brightest DROP_BRIGHT share is left out of the fit (the sharp specular peak a low degree does
not follow), as in ST14. Fewer than MIN_LIGHTS left: the uncertainty is 90° (nothing known).
"""
import numpy as np
from scipy.ndimage import gaussian_filter, grey_dilation

from facette._memory import masked_values
from facette._threads import run_blocks

__all__ = ["normal_uncertainty", "uncertainty_summary", "curl_angle", "BAND_SCALE", "K_CURL", "CURL_SIGMA", "T_DARK",
           "DROP_BRIGHT", "DEGREE"]

DEGREE = 2            # polynomial degree in n·h of the local reflectance
T_DARK = 0.05         # values below this share of the pixel's brightest are shadows
DROP_BRIGHT = 0.1     # share of the brightest lit values left out (the specular peak)
MIN_LIGHTS = DEGREE + 4
BAND_SCALE = 1.2      # 90 % band radius / u: the 90th percentile of error / u over the renders of
                      # `facette bench uncertainty` (12 synthetic spheres, 4 Mitsuba scenes; li_alternating):
                      # 1.20 (rank_trimmed's normals: 1.23); never chosen on DiLiGenT
K_CURL = 7.0         # band (deg) per degree of the field's curl (`curl_angle`): the smallest at which every group
                     # of the path-traced renders of `facette bench uncertainty` holds 90 % of its normals. The short
                     # one was the concave plaster scenes under 96 lights: 0.81 at 4, 0.85 at 5, 0.87 at 6, 0.90 at 7
                     # (under 12 rig lights 0.98-0.99; the Mitsuba scenes 1.00). Their Spearman is flat from 4 to 8
                     # (concave 0.87 and 0.90, Mitsuba 0.61 -> 0.62; the noise-only spheres 0.25 -> 0.24); never
                     # chosen on DiLiGenT
CURL_SIGMA = 1.0     # pixels the curl is gathered over (Gaussian), on the same renders: the synthetic spheres'
                     # Spearman 0.24 at 1, 0.18 at 1.5, 0.07 at 3; the path-traced ones' equal (0.61 / 0.88) from 1 to 3
MAX_DEG = 90.0
MAX_VALUES = 3_000_000   # pixels x lights computed at most (12 lights: 250 000 pixels, a 12 MP scan every
                         # 7th row and column; DiLiGenT's 96: 31 000, a 45 000-pixel crop every 2nd): 512x512 px,
                         # 12 lights took 13 s on 2 busy cores, a 12 MP map in full would take minutes
_FD = 1e-3            # finite-difference step of the tangent angles (rad)
_CHUNK = 8192
VIEW = np.array([0.0, 0.0, 1.0])


def _basis(n, lights, halves):
    """(N, m, p) columns (n·l)_+ (n·h)^a; lights, halves (m, 3) or per pixel (N, m, 3)."""
    dot = (lambda d: n @ d.T) if lights.ndim == 2 else (lambda d: np.einsum("ni,nmi->nm", n, d))
    nl = np.maximum(dot(lights), 0.0)
    nh = np.clip(dot(halves), 0.0, 1.0)
    return np.stack([nl * nh ** a for a in range(DEGREE + 1)], axis=-1)


def _residual(n, e, w, lights, halves):
    """Per pixel the weighted residual (N, m) of the best α for normals n (N, 3)."""
    a = _basis(n, lights, halves) * w[..., None]
    g = np.matmul(a.transpose(0, 2, 1), a)
    p = g.shape[-1]
    tr = np.trace(g, axis1=1, axis2=2) / p
    g += (1e-6 * np.maximum(tr, 1e-30))[:, None, None] * np.eye(p)
    c = np.linalg.solve(g, np.einsum("nmp,nm->np", a, e * w)[..., None])[..., 0]
    return (e - np.einsum("nmp,np->nm", a, c)) * w


def _tangents(n):
    ref = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    t1 = np.cross(n, ref)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(n, t1)


def _carrying(e, ok):
    """(N, m) weights 0/1 of the lights that carry each pixel (see the module's notes)."""
    peak = np.max(np.where(ok, e, 0.0), axis=1, keepdims=True)
    lit = ok & (e > T_DARK * peak) & (e > 0)
    n_drop = np.floor(DROP_BRIGHT * lit.sum(1)).astype(np.intp)
    srt = -np.sort(-np.where(lit, e, -np.inf), axis=1)
    cut = srt[np.arange(len(e)), np.clip(n_drop, 0, e.shape[1] - 1)]
    return (lit & (e <= cut[:, None])).astype(np.float64)


def _block(e, ok, n, lights, halves):
    """u (radians) for pixels e, ok (N, m), unit normals n (N, 3)."""
    w = _carrying(e, ok)
    scale = np.maximum(np.max(e * w, axis=1, keepdims=True), 1e-30)
    e = e / scale
    r = _residual(n, e, w, lights, halves)
    t1, t2 = _tangents(n)
    jac = np.empty(r.shape + (2,))
    for k, t in enumerate((t1, t2)):
        nk = n + _FD * t
        nk /= np.linalg.norm(nk, axis=1, keepdims=True)
        jac[..., k] = (_residual(nk, e, w, lights, halves) - r) / _FD
    jtj = np.einsum("nmi,nmj->nij", jac, jac)
    tr = np.trace(jtj, axis1=1, axis2=2)
    jtj += (1e-9 * np.maximum(tr, 1e-30))[:, None, None] * np.eye(2)
    inv = np.linalg.inv(jtj)
    meat = np.einsum("nmi,nm,nmj->nij", jac, r * r, jac)
    cov = inv @ meat @ inv
    step = -np.einsum("nij,nj->ni", inv, np.einsum("nmi,nm->ni", jac, r))
    u2 = np.trace(cov, axis1=1, axis2=2) + np.sum(step * step, axis=1)
    u = np.sqrt(np.maximum(u2, 0.0))
    few = (w > 0).sum(1) < MIN_LIGHTS
    return np.where(few | ~np.isfinite(u), np.inf, u)


def normal_uncertainty(images, light_dirs, normals, mask=None, saturation=None, channel=None,
                       max_values=MAX_VALUES):
    """The radius (deg) of each normal's 90 % band: (H, W) float32, 0 outside the mask.

    images : (m, H, W) or (m, H, W, C) linear, divided by each light's intensity (as the solve
        saw them; the mean of the channels unless `channel`). light_dirs : (m, 3) distant
        lights, or (H, W, m, 3) per pixel (near lights, as photometric_stereo takes them).
        normals : (H, W, 3) the solution (zero where there is none: not rated). mask : (H, W) bool (default: where the normal
        is not zero). saturation : values at or above it are not used.
    The band is sqrt((BAND_SCALE u)^2 + (K_CURL c)^2): u the local fit's (module doc), c the
    normal field's own non-integrability around the pixel (`curl_angle`, over every pixel with a normal).
    Pixels with fewer than MIN_LIGHTS carrying lights, or no normal, get MAX_DEG (90°).
    max_values : above this many mask pixels x lights the local fit is computed on every s-th row and
        column (s the smallest stride that brings them under it), each pixel taking its cell's value;
        the curl is always computed on every pixel.
    """
    images = np.asarray(images)
    if images.ndim == 3:
        images = images[..., None]
    if images.ndim != 4:
        raise ValueError(f"images must be (m, H, W) or (m, H, W, C), got shape {images.shape}")
    m, h, w, _ = images.shape
    normals = np.asarray(normals, np.float64)
    if normals.shape != (h, w, 3):
        raise ValueError(f"normals must be (H, W, 3) = ({h}, {w}, 3), got {normals.shape}")
    light_dirs = np.asarray(light_dirs)
    if light_dirs.shape not in ((m, 3), (h, w, m, 3)):
        raise ValueError(f"light_dirs must be (m, 3) or (H, W, m, 3) = ({h}, {w}, {m}, 3) for {m} images, "
                         f"got {light_dirs.shape}")
    has_n = np.linalg.norm(normals, axis=2) > 0.5
    mask = has_n if mask is None else (np.asarray(mask, bool) & has_n)
    band = _fit_band(images, light_dirs, normals, mask, saturation, channel, max_values)
    if K_CURL > 0 and mask.any():
        curl = np.degrees(K_CURL * curl_angle(normals, has_n))
        band = np.where(mask, np.minimum(np.hypot(band, curl), MAX_DEG), 0).astype(np.float32)
    return band


def fit_stride(values, max_values):
    """The local fit's stride for `values` mask pixels x lights: the smallest that brings them under
    `max_values` (1 when they are already)."""
    return int(np.ceil(np.sqrt(values / max_values))) if values > max_values else 1


def _fit_band(images, light_dirs, normals, mask, saturation, channel, max_values):
    """BAND_SCALE x u (deg) of the local fit, MAX_DEG where it has too few lights; 0 off the mask."""
    m, h, w, _ = images.shape
    stride = fit_stride(mask.sum() * m, max_values)
    if stride > 1:        # a cell's pixels take its corner's value (or its neighbours' at the edge)
        ld = light_dirs if light_dirs.ndim == 2 else light_dirs[::stride, ::stride]
        coarse = _fit_band(images[:, ::stride, ::stride], ld, normals[::stride, ::stride],
                           mask[::stride, ::stride], saturation, channel, max_values=np.inf)
        coarse = np.where(mask[::stride, ::stride], coarse, grey_dilation(coarse, size=3))
        up = np.repeat(np.repeat(coarse, stride, axis=0), stride, axis=1)[:h, :w]
        return np.where(mask, up, np.float32(0)).astype(np.float32)
    out = np.zeros((h, w), np.float32)
    idx = np.flatnonzero(mask.ravel())
    if idx.size == 0:
        return out
    flat = images.reshape(m, h * w, -1)
    nflat = normals.reshape(-1, 3)
    u_all = np.full(idx.size, np.inf)

    def block(a):
        sl = idx[a:a + _CHUNK]
        vals = flat[:, sl].astype(np.float64)
        e = (vals.mean(axis=2) if channel is None else vals[:, :, channel]).T      # (N, m)
        ok = np.isfinite(e) & (True if saturation is None else np.all(vals < saturation, axis=2).T)
        e = np.where(ok, e, 0.0)
        n = nflat[sl] / np.linalg.norm(nflat[sl], axis=1, keepdims=True)
        ld = light_dirs.astype(np.float64) if light_dirs.ndim == 2 else \
            light_dirs.reshape(h * w, m, 3)[sl].astype(np.float64)                 # near lights: (N, m, 3)
        u_all[a:a + _CHUNK] = _block(e, ok, n, ld, _halves(ld))

    run_blocks(block, range(0, idx.size, _CHUNK))
    deg = np.minimum(BAND_SCALE * np.degrees(u_all), MAX_DEG)
    out.reshape(-1)[idx] = np.where(np.isfinite(deg), deg, MAX_DEG)
    return out


def curl_angle(normals, mask, sigma=CURL_SIGMA):
    """(H, W) radians: how far the normal field around each pixel is from any surface's.

    The slopes g = (-n_x/n_z, n_y/n_z) (per column, per row) of a surface's normals sum to zero
    round every 2x2 plaquette of pixels (the curl of a gradient); each plaquette's loop sum, over
    1 + |g|² (a slope's change as an angle), is an angle no surface explains. A pixel takes the
    root mean square over its plaquettes whose corners all lie in the mask, then over the mask's
    pixels within `sigma` (Gaussian). Inter-reflections, cast shadows and a wrong reflectance bend normals in ways no
    height field has; noise alone leaves a small curl."""
    n = np.asarray(normals, np.float32)
    mask = np.asarray(mask, bool)
    nz = np.maximum(n[..., 2], np.float32(1e-3))
    p = np.clip(-n[..., 0] / nz, -50, 50)
    q = np.clip(n[..., 1] / nz, -50, 50)
    ok = mask[:-1, :-1] & mask[:-1, 1:] & mask[1:, :-1] & mask[1:, 1:]
    loop = 0.5 * (p[:-1, :-1] + p[:-1, 1:] - p[1:, :-1] - p[1:, 1:] + q[:-1, 1:] + q[1:, 1:] - q[:-1, :-1] - q[1:, :-1])
    g2 = p * p + q * q
    g2 = 0.25 * (g2[:-1, :-1] + g2[:-1, 1:] + g2[1:, :-1] + g2[1:, 1:])
    c2 = np.where(ok, (loop / (1 + g2)) ** 2, np.float32(0))
    acc = np.zeros(mask.shape, np.float32)
    cnt = np.zeros(mask.shape, np.float32)
    for a in (0, 1):          # each plaquette to its four corner pixels
        for b in (0, 1):
            acc[a:a + c2.shape[0], b:b + c2.shape[1]] += c2
            cnt[a:a + c2.shape[0], b:b + c2.shape[1]] += ok
    own = np.where(mask, acc / np.maximum(cnt, 1), np.float32(0))       # each pixel's mean square
    spread = gaussian_filter(own, sigma) / np.maximum(gaussian_filter(mask.astype(np.float32), sigma), 1e-6)
    return np.where(mask, np.sqrt(spread), 0).astype(np.float32)


def _halves(lights):
    h = lights + VIEW
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


# What the band is not: an error common to the whole object (the lights' calibration, a bias of the reflectance
# model or of the truth) leaves every pixel alike, so nothing per pixel ranks it (`facette bench uncertainty`:
# DiLiGenT's 16-bit ball is 1.1-2.7 deg off everywhere, p10-p90; every measure tried ranks it at -0.43 to +0.03,
# and the best rotation of the whole object removes 0.05 of its 1.98 deg).
GLOBAL_NOTE = ("errors common to the whole object (the lights' calibration, a bias of the reflectance model) are "
               "not in the band: nothing per pixel shows them (DiLiGenT's 16-bit ball: 1.1-2.7 deg off everywhere, "
               "59 % within its band)")


def uncertainty_summary(uncertainty, mask):
    """{"median_deg", "p90_deg", "band": "90 %", "not_in_band": GLOBAL_NOTE} of the map over the mask (None
    when empty)."""
    vals = masked_values(uncertainty, np.asarray(mask, bool))     # a band at a time; a copy, partitioned in place
    if vals.size == 0:
        return None
    return {"median_deg": round(float(np.median(vals, overwrite_input=True)), 3),
            "p90_deg": round(float(np.percentile(vals, 90, overwrite_input=True)), 3),
            "band": "uncertainty_deg is each normal's 90 % band: it held 88-100 % of the errors on path-traced "
                    "renders, 59-96 % on DiLiGenT's photographs (per object; 88 % of their pixels pooled)",
            "not_in_band": GLOBAL_NOTE}
