"""Reflectance transformation imaging: per-pixel relighting functions fitted to the HDR images.

Two bases, the two that RTIViewer reads:

- `ptm_basis`: the biquadratic polynomial of Malzbender, Gelb & Wolters 2001 (eq. 2),
  L(lu, lv) = a0 lu² + a1 lv² + a2 lu lv + a3 lu + a4 lv + a5, where (lu, lv) is the unit
  light vector projected on the image plane (camera x right, y up).
- `hsh_basis`: hemispherical harmonics (Gautron, Krivanek, Pattanaik & Bouatouch 2004), in
  the order and sign convention RTIViewer evaluates them (see the function).

`fit_ptm_lrgb` and `fit_hsh` solve one weighted least-squares problem per pixel, all pixels
of a block at once (batched normal equations), with far lights (m, 3) or per-pixel near-light
directions (H, W, m, 3). Missing values (NaN) and lights at or below the horizon are left out.
Terms the lights cannot tell apart get (nearly) the minimum-norm solution (Tikhonov, `_RCOND`).
"""
from dataclasses import dataclass, replace
from math import factorial, pi, sqrt

import numpy as np

from facette._threads import run_blocks
from facette.io.ptm import ptm_weights

__all__ = ["ptm_basis", "hsh_basis", "PTMFit", "HSHFit", "fit_ptm_lrgb", "fit_hsh",
           "relight_ptm", "relight_hsh", "relight_error", "fit_relight_error", "relight_error_parts",
           "HSH_ORDERS", "RTI_ENCODINGS", "srgb_encode", "srgb_decode", "display_ptm", "display_hsh"]

# How the fitted values are encoded: "srgb", the display values RTIViewer shows as they are
# (RTIBuilder fits sRGB photographs), or "linear": values proportional to the radiance
RTI_ENCODINGS = ("srgb", "linear")

HSH_ORDERS = (2, 3)     # 4 and 9 terms: the orders whose RTIViewer convention is pinned by a test
# Tikhonov term, relative to trace(AᵀA): directions of AᵀA with eigenvalues far below it are
# damped to zero (close to a truncated pseudo-inverse, at the cost of one solve): a light set that cannot tell some terms apart (the rig's two rings at 15° and 30° give only
# two elevations for HSH order 3's three zonal terms) gets the minimum-norm fit, not ±500
# coefficients that cancel on the photographs and explode between them
_RCOND = 1e-6
_BLOCK = 8192          # pixels per batched solve (memory ~ block * m * terms * 8 bytes)


def _check_encoding(encoding):
    if encoding not in RTI_ENCODINGS:
        raise ValueError(f"RTI encoding must be one of {RTI_ENCODINGS}, got {encoding!r}")


def srgb_encode(x, out=None):
    """The sRGB transfer function (IEC 61966-2-1) of linear values, clipped to [0, 1] first;
    NaN stays NaN. In place when out is x."""
    x = np.clip(x, 0.0, 1.0, out=out)
    low = x <= 0.0031308
    hi = np.power(x, x.dtype.type(1 / 2.4) if x.dtype.kind == "f" else 1 / 2.4)
    hi *= 1.055
    hi -= 0.055
    x *= 12.92
    return np.where(low, x, hi) if out is None else np.copyto(out, hi, where=~low) or out


def srgb_decode(y):
    """Linear values of sRGB-encoded ones (clipped to [0, 1] first)."""
    y = np.clip(y, 0.0, 1.0)
    return np.where(y <= 0.04045, y / 12.92, np.power((y + 0.055) / 1.055, 2.4))


def ptm_basis(light_dirs):
    """PTM basis (Malzbender et al. 2001, eq. 2) of unit light vectors (..., 3) -> (..., 6):
    [lu², lv², lu·lv, lu, lv, 1] with lu = x, lv = y of the light direction (camera frame)."""
    d = np.asarray(light_dirs, dtype=np.float64)
    if d.shape[-1] != 3:
        raise ValueError(f"light directions must have shape (..., 3), got {d.shape}")
    return ptm_weights(d)


def _legendre_no_cs(l_max, x, sq):
    """Associated Legendre P_l^m(x) without the Condon-Shortley phase, 0 <= m <= l < l_max,
    by the standard recurrences; sq = √(1 - x²). Returns {(l, m): array}."""
    p = {(0, 0): np.ones_like(x)}
    for m in range(l_max):
        if m > 0:
            p[(m, m)] = (2 * m - 1) * sq * p[(m - 1, m - 1)]     # P_m^m = (2m-1)!! (1-x²)^(m/2)
        if m + 1 < l_max:
            p[(m + 1, m)] = (2 * m + 1) * x * p[(m, m)]
        for l in range(m + 2, l_max):
            p[(l, m)] = ((2 * l - 1) * x * p[(l - 1, m)] - (l + m - 1) * p[(l - 2, m)]) / (l - m)
    return p


def hsh_basis(light_dirs, order=3):
    """Hemispherical harmonics of unit light vectors (..., 3) -> (..., order²).

    H_l^m(θ, φ) = K_l^m P_l^|m|(2 cos θ - 1) · {cos(|m| φ) for m < 0, 1 for m = 0, sin(m φ)
    for m > 0} · √2 (m ≠ 0), K_l^m = √((2l + 1)(l - |m|)! / (2π (l + |m|)!)) (Gautron et al.
    2004, eq. 6), l = 0..order-1 and m = -l..l in that order, θ = acos z, φ = atan2(y, x).
    Signs as RTIViewer's (no Condon-Shortley phase, |m| = 2 terms negated). cos θ is clamped
    to [0, 1]: below the horizon the basis is the one at grazing light.
    """
    if order not in HSH_ORDERS:
        raise ValueError(f"HSH order must be one of {HSH_ORDERS} (4 or 9 terms), got {order}")
    d = np.asarray(light_dirs, dtype=np.float64)
    if d.shape[-1] != 3:
        raise ValueError(f"light directions must have shape (..., 3), got {d.shape}")
    r = np.maximum(np.sqrt((d * d).sum(axis=-1)), 1e-300)
    cos_t = np.clip(d[..., 2] / r, 0.0, 1.0)
    rho = np.hypot(d[..., 0], d[..., 1])
    flat = rho <= 1e-300                                # φ undefined at the pole: take φ = 0
    cos_p = np.where(flat, 1.0, d[..., 0] / np.where(flat, 1.0, rho))
    sin_p = np.where(flat, 0.0, d[..., 1] / np.where(flat, 1.0, rho))
    x = 2.0 * cos_t - 1.0
    p = _legendre_no_cs(order, x, 2.0 * np.sqrt(np.maximum(cos_t - cos_t * cos_t, 0.0)))
    cos_m, sin_m = [np.ones_like(x)], [np.zeros_like(x)]       # cos(mφ), sin(mφ) by recurrence
    for _ in range(1, order):
        c, s_ = cos_m[-1], sin_m[-1]
        cos_m.append(c * cos_p - s_ * sin_p)
        sin_m.append(s_ * cos_p + c * sin_p)
    out = np.empty(d.shape[:-1] + (order * order,))
    k = 0
    for l in range(order):
        for m in range(-l, l + 1):
            a = abs(m)
            norm = sqrt((2 * l + 1) * factorial(l - a) / (2 * pi * factorial(l + a)))
            if a == 0:
                out[..., k] = norm * p[(l, 0)]
            else:
                sign = -1.0 if a == 2 else 1.0
                out[..., k] = (sign * sqrt(2.0) * norm) * p[(l, a)] * (cos_m[a] if m < 0 else sin_m[a])
            k += 1
    return out


@dataclass
class PTMFit:
    """A luminance PTM (LRGB): displayed colour (H, W, 3) = L(l) · rgb, in [0, 1] as shown;
    the image value it stands for is white · that (encoding "linear") or white · sRGB⁻¹(that)
    (encoding "srgb").

    coeffs (H, W, 6) float32, the L polynomial's a0..a5 (`ptm_basis` order), L ~ [0, 1];
    rgb (H, W, 3) in [0, 1], the per-pixel colour (max channel 1 where lit), encoded;
    white : the image value shown at full brightness (same unit as the fitted images);
    valid (H, W) bool: pixels with at least 6 usable lights (others are zero);
    encoding : "srgb" or "linear" (`RTI_ENCODINGS`).
    """
    coeffs: np.ndarray
    rgb: np.ndarray
    white: float
    valid: np.ndarray
    encoding: str = "linear"

    def basis(self, d):            # (..., 3) -> (..., 6), the L polynomial's terms
        return ptm_basis(d)


@dataclass
class HSHFit:
    """RGB hemispherical harmonics: displayed colour (H, W, 3) = Σ_k coeffs[..., c, k] H_k(l),
    the image value as in `PTMFit` (white, encoding).

    coeffs (H, W, 3, order²) float32 (values ~ [0, 1]); order; white; valid; encoding."""
    coeffs: np.ndarray
    order: int
    white: float
    valid: np.ndarray
    encoding: str = "linear"
    CONSTANT = 0                  # the term of the basis that is constant over the lights

    def basis(self, d):
        return hsh_basis(d, self.order)


def _check(images, light_dirs):
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3 or 0 in images.shape:
        raise ValueError(f"images must have shape (m, H, W, 3), got {images.shape}")
    m, h, w, _ = images.shape
    d = np.asarray(light_dirs, dtype=np.float64)
    if d.shape not in ((m, 3), (h, w, m, 3)):
        raise ValueError(f"light directions must have shape ({m}, 3) or ({h}, {w}, {m}, 3) for "
                         f"{m} images of {w}x{h}, got {d.shape}")
    return images, d


def _ridge_solve(ata, atb, n_terms, rcond=_RCOND):
    """Batched (AᵀA + rcond·trace·I) x = Aᵀb: ata (n, T, T), atb (n, k, T) -> (n, k, T)."""
    ridge = rcond * np.maximum(np.trace(ata, axis1=1, axis2=2), 1e-300)
    ata += ridge[:, None, None] * np.eye(n_terms)
    return np.linalg.solve(ata, np.swapaxes(atb, 1, 2)).swapaxes(1, 2)


def _solve_blocks(images, dirs, basis, n_terms, values, workers=2, rcond=_RCOND, out=None):
    """Per-pixel weighted least squares, light-major: values(e (m, n, c)) -> (y (m, n, c),
    w (m, n)), e float32 for far lights (the pixels with every light known share one float32
    product; the others are solved in float64), float64 for per-pixel directions.
    Returns (coeffs (H*W, c, n_terms) float32, valid (H*W,)); coeffs in `out` if given (C-contiguous float32,
    every value written: a full-size array filled band by band, pipeline._rti_bands). Blocks of pixels run
    on `workers` threads (numpy's products and solves release the GIL)."""
    m, h, w, c = images.shape
    flat = images.reshape(m, h * w, c)
    far = dirs.ndim == 2
    if far:
        b_far = basis(dirs)                                  # (m, T)
        above = dirs[:, 2] > 0
        outer = (b_far[:, :, None] * b_far[:, None, :]).reshape(m, -1)
        # the pixels whose every light is known share one matrix A = Σ_above b bᵀ (+ ridge):
        # their solution is one matrix product with proj = (above · B) A⁻¹, (m, T)
        a_full = (above.astype(np.float64) @ outer).reshape(1, n_terms, n_terms)
        proj_t = _ridge_solve(a_full, (b_far * above[:, None])[None], n_terms, rcond)[0].T.copy()
        # the shared solve in float32, as the coefficients are stored: half the memory
        # traffic of the largest product (12 MP HSH fit: 3.4 -> 3.0 CPU s)
        proj_t32 = proj_t.astype(np.float32)
    # float32 storage (and the shared far-light product above): the files quantise to 8 bits
    # (PTM) and 8 bits per term (RTI), 2^-24 relative is far below either; 12 MP HSH
    # coefficients take 330 MB instead of 660. Pixels with unknown lights are solved in float64.
    coeffs = np.zeros((h * w, c, n_terms), np.float32) if out is None else out.reshape(h * w, c, n_terms)
    valid = np.zeros(h * w, bool)

    def block(a):
        sl = slice(a, a + _BLOCK)
        y, wt = values(flat[:, sl].astype(np.float32 if far else np.float64))   # (m, n, c), (m, n)
        n = wt.shape[1]
        if far:   # one design matrix: the normal equations are matrix products
            wt = wt * above[:, None]
            full = (wt == above[:, None]).all(axis=0)
            # every light known: y as it is (proj is 0 for the lights below the horizon)
            if full.all():
                sol = (proj_t32 @ y.reshape(m, -1)).reshape(n_terms, n, c).transpose(1, 2, 0)
            else:
                y = np.where(wt[..., None] > 0, y, np.float32(0))
                sol = np.empty((n, c, n_terms), np.float32)
                sol[full] = (proj_t32 @ y[:, full].reshape(m, -1)).reshape(n_terms, -1, c).transpose(1, 2, 0)
            part = ~full
            if part.any():
                wp, yp = wt[:, part].T, y[:, part].transpose(1, 0, 2)   # (np, m), (np, m, c)
                ata = (wp @ outer).reshape(-1, n_terms, n_terms)
                atb = np.einsum("nmk,mi->nki", yp * wp[..., None], b_far, optimize=True)
                sol[part] = _ridge_solve(ata, atb, n_terms, rcond)
        else:
            d = dirs.reshape(h * w, m, 3)[sl]
            b = basis(d)
            wt = wt.T * (d[..., 2] > 0)                                 # (n, m)
            y = np.where(wt[..., None] > 0, y.transpose(1, 0, 2), 0.0)  # (n, m, c)
            ata = np.einsum("nm,nmi,nmj->nij", wt, b, b, optimize=True)
            atb = np.einsum("nm,nmi,nmk->nki", wt, b, y, optimize=True)
            sol = _ridge_solve(ata, atb, n_terms, rcond)                 # (n, k, T)
            wt = wt.T
        ok = wt.sum(axis=0) >= n_terms
        coeffs[sl] = sol
        if not ok.all():
            coeffs[sl][~ok] = 0.0
        valid[sl] = ok

    run_blocks(block, range(0, h * w, _BLOCK), workers)
    return coeffs, valid


def _all3(a):
    """a[..., 0] & a[..., 1] & a[..., 2]: `.all(axis=-1)` over 3 channels, ~5x faster."""
    return a[..., 0] & a[..., 1] & a[..., 2]


def _top_percentile(select, starts, percentile, stride=37):
    """np.percentile (linear) of the values select(a) (1-D) of every block start a, the same
    number, holding only the top few % of them: a first pass counts them and keeps every
    `stride`-th as a sample, whose percentile one point lower bounds the two order statistics
    needed; a second pass keeps the values above that bound and counts those below. The full
    set is used when the bound does not hold (never seen: the sample has ~1e5 values).
    1.0 when there is no value."""
    first = run_blocks(lambda a: (lambda v: (v.size, v[::stride].copy()))(select(a)), starts)
    n = sum(k for k, _ in first)
    if n == 0:
        return 1.0
    sample = np.concatenate([v for _, v in first])
    q = np.true_divide(percentile, 100)
    vi = q * (n - 1)                                   # numpy's linear method (alpha = beta = 1)
    lo = int(np.floor(vi))
    hi = min(lo + 1, n - 1)
    bound = np.percentile(sample, max(percentile - 1.0, 0.0)) if sample.size > 1000 else -np.inf
    second = run_blocks(lambda a: (lambda v: (int((v < bound).sum()), v[v >= bound]))(select(a)), starts)
    below = sum(k for k, _ in second)
    if below > lo:                                      # the bound was too high: every value
        return float(np.percentile(np.concatenate([select(a) for a in starts]), percentile))
    top = np.concatenate([v for _, v in second])
    part = np.partition(top, [lo - below, hi - below])
    pair = np.array([part[lo - below], part[hi - below]])
    return float(np.quantile(pair, float(vi - lo)))      # numpy's own interpolation, its dtype


def fit_ptm_lrgb(images, light_dirs, mask=None, white=None, white_percentile=99.0, encoding="linear",
                 photographed=False, out=None):
    """Fit a luminance PTM (LRGB, Malzbender et al. 2001 §3.2) to every pixel.

    images : (m, H, W, 3) linear values (NaN = unknown); light_dirs : (m, 3) or (H, W, m, 3)
    unit vectors towards the lights; mask : (H, W) bool, the pixels that set the white level
    (default: all). white : the value mapped to L = 1 (default: the `white_percentile` of the
    luminance over the masked pixels and all lights).
    Per pixel, rgb is the colour of the summed samples scaled to max channel 1, and each
    sample's L is its projection on rgb (least squares), divided by `white`.
    encoding "srgb": rgb is sRGB-encoded and L fitted to the projections of the sRGB-encoded
    samples (images / white, clipped to [0, 1]) on it: L · rgb is what a viewer shows.
    photographed=True: the samples as photographed, colour and all (`recon._rti_photo`); out:
    (H, W, 6) float32 for the coefficients (`_solve_blocks`), or None. Returns a `PTMFit`."""
    from facette.recon._rti_jit import ptm_colour_block     # numba loads only when this runs
    _check_encoding(encoding)
    images, dirs = _check(images, light_dirs)
    m, h, w, _ = images.shape
    flat = images.reshape(m, h * w, 3)                    # light-major
    rgb = np.empty((h * w, 3))
    peak = np.empty(h * w)
    lum = np.empty((m, h * w))                            # NaN where the value is unknown
    if photographed:
        from facette.recon._rti_photo import fit_ptm_displayed
        return fit_ptm_displayed(images, dirs, mask, white, white_percentile, encoding, rgb, peak, lum, out)

    def colour(a):     # a block of pixels, compiled: one pass instead of numpy's ten
        ptm_colour_block(flat[:, a:a + _BLOCK], rgb, peak, lum, a)

    def known_lum(a):      # the values that set the white level: finite, > 0, masked
        lb = lum[:, a:a + _BLOCK]
        with np.errstate(invalid="ignore"):
            ok = lb > 0                                   # NaN (unknown) is not
        return lb[ok if sel is None else ok & sel[None, a:a + _BLOCK]]

    sel = None if mask is None else np.asarray(mask, bool).reshape(-1)
    run_blocks(colour, range(0, h * w, _BLOCK))
    if white is None:
        white = _top_percentile(known_lum, range(0, h * w, _BLOCK), white_percentile)
    if not white > 0:
        raise ValueError(f"white level must be > 0, got {white}")
    scale = 1.0 / white
    if encoding == "srgb":       # the display colour, and each sample's projection on it
        from facette.recon._rti_jit import srgb_lum_block, srgb_table
        rgb = srgb_encode(rgb)
        scale, lut = 1.0, srgb_table()
        run_blocks(lambda a: srgb_lum_block(flat[:, a:a + _BLOCK], rgb, lum, a, 1.0 / white, lut),
                   range(0, h * w, _BLOCK))
    lum_img = lum.reshape(m, h, w, 1)

    def values(e):                          # e: a copy of its own, changed in place
        ok = np.isfinite(e[..., 0])
        e = np.nan_to_num(e, copy=False)
        e *= scale
        return e, ok.astype(np.float64)

    coeffs, valid = _solve_blocks(lum_img, dirs, ptm_basis, 6, values, out=out)
    valid &= peak > 0
    return PTMFit(coeffs[:, 0].reshape(h, w, 6), rgb.reshape(h, w, 3), float(white),
                  valid.reshape(h, w), encoding)


def fit_hsh(images, light_dirs, order=3, mask=None, white=None, white_percentile=99.0, encoding="linear",
            photographed=False, out=None):
    """Fit RGB hemispherical harmonics of `order` (2: 4 terms, 3: 9 terms) to every pixel.

    Same inputs as `fit_ptm_lrgb`; each colour channel gets its own coefficients, fitted to
    images / white (white: the `white_percentile` of the masked values by default); encoding
    "srgb": to their sRGB encoding (images / white clipped to [0, 1]), what a viewer shows.
    photographed=True: the samples as photographed (`recon._rti_photo`); out: (H, W, 3, order²)
    float32 for the coefficients, or None. Returns an `HSHFit`."""
    _check_encoding(encoding)
    images, dirs = _check(images, light_dirs)
    m, h, w, _ = images.shape
    n_terms = order * order
    hsh_basis(np.array([0.0, 0.0, 1.0]), order)                 # validates `order`
    if white is None:
        from facette.recon._rti_photo import brightest_white
        white = brightest_white(images, mask, white_percentile)
    if not white > 0:
        raise ValueError(f"white level must be > 0, got {white}")
    if photographed:
        from facette.recon._rti_photo import fit_hsh_displayed
        return fit_hsh_displayed(images, dirs, order, white, encoding, out)

    if encoding == "srgb":
        from facette.recon._rti_jit import srgb_scale_inplace, srgb_table
        lut = srgb_table()

    def values(e):                          # e: a copy of its own, changed in place
        ok = _all3(np.isfinite(e))
        e = np.nan_to_num(e, copy=False)
        if encoding == "srgb":          # e is a contiguous copy (the blocks' astype)
            srgb_scale_inplace(e, 1.0 / white, lut)
        else:
            e /= e.dtype.type(white)
        return e, ok.astype(np.float64)

    coeffs, valid = _solve_blocks(images, dirs, lambda d: hsh_basis(d, order), n_terms, values, out=out)
    return HSHFit(coeffs.reshape(h, w, 3, n_terms), order, float(white), valid.reshape(h, w), encoding)


def _shown_ptm(fit, light_dir):
    """L · rgb (H, W, 3) of a `PTMFit` under one light (3,) or (H, W, 3), L clipped to >= 0."""
    b = ptm_basis(np.asarray(light_dir, float))
    lum = fit.coeffs @ b if b.ndim == 1 else np.einsum("hwt,hwt->hw", fit.coeffs, b)
    return np.clip(lum, 0, None)[..., None] * fit.rgb


def _shown_hsh(fit, light_dir):
    """Σ_k coeffs H_k(l) (H, W, 3) of an `HSHFit` (or per-channel PTM) under one light (3,) or (H, W, 3), >= 0."""
    b = fit.basis(np.asarray(light_dir, float))
    val = fit.coeffs @ b if b.ndim == 1 else np.einsum("hwct,hwt->hwc", fit.coeffs, b)
    return np.clip(val, 0, None)


def display_ptm(fit, light_dir):
    """The colour (H, W, 3) a viewer shows for a `PTMFit` under a far light (3,) or per-pixel
    directions (H, W, 3): L · rgb, clipped to [0, 1], in the fit's encoding."""
    return np.clip(_shown_ptm(fit, light_dir), 0, 1)


def display_hsh(fit, light_dir):
    return np.clip(_shown_hsh(fit, light_dir), 0, 1)      # an `HSHFit`'s, as `display_ptm`


def _to_images(fit, shown):     # displayed values (≥ 0) -> the fitted images' unit (sRGB decoded when so)
    return fit.white * (srgb_decode(shown) if fit.encoding == "srgb" else shown)


def relight_ptm(fit, light_dir):
    """Colour (H, W, 3) of a `PTMFit` under a far light (3,) or per-pixel directions (H, W, 3), in the
    fitted images' unit (linear; not clipped at white when the encoding is linear)."""
    return _to_images(fit, _shown_ptm(fit, light_dir))


def relight_hsh(fit, light_dir):
    return _to_images(fit, _shown_hsh(fit, light_dir))     # an `HSHFit`'s, as `relight_ptm`


def _error_sums(render, images, d_all, mask):
    num = den = 0.0
    for img, d in zip(images, d_all):
        sel = (mask & _all3(np.isfinite(img)))[..., None]
        diff = render(d) - img
        num += float(np.sum(diff * diff, where=sel))
        x = img.astype(np.float64)
        den += float(np.sum(x * x, where=sel))
    return num, den


def relight_error(render, images, light_dirs, mask):
    """Relative RMS error sqrt(Σ |render - image|² / Σ |image|²) (0 = exact) of a relighting function
    render(light_dir (3,) or (H, W, 3)) -> (H, W, 3) against the images (m, H, W, 3) it was fitted to
    under light_dirs (m, 3) or (H, W, m, 3), over the masked pixels (H, W) and finite values."""
    d_all = np.asarray(light_dirs, float)
    d_all = d_all if d_all.ndim == 2 else np.moveaxis(d_all, 2, 0)
    num, den = _error_sums(render, images, d_all, mask)
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


# Values (pixels × lights) the relighting error sums at most (`fit_relight_error`). 2144×1424 px, 12
# lights: every 6th pair of rows, PTM 0.1165 / HSH 0.0921 against 0.1153 / 0.0912 from every row, 0.5
# CPU s instead of 3.7 each; DiLiGenT pot2, 96 lights: every other pair, within 0.2 %, 0.5 s less.
RELIGHT_ERROR_VALUES = 12 << 19


def relight_error_step(h, w, m, rows=2, max_pixels="auto"):
    """Rows between `fit_relight_error`'s blocks of `rows` rows of an h × w map: the smallest multiple
    of `rows` keeping ≤ max_pixels pixels ("auto": RELIGHT_ERROR_VALUES / m lights; None: every row)."""
    max_pixels = max(1, RELIGHT_ERROR_VALUES // max(int(m), 1)) if max_pixels == "auto" else max_pixels
    return rows if max_pixels is None else rows * max(1, -(-h * w // max_pixels))


def fit_relight_error(fit, images, light_dirs, mask, rows=2, workers=2, max_pixels="auto"):
    """`relight_error` of a `PTMFit` or `HSHFit`, its sums taken `rows` image rows at a time on
    `workers` threads (a block's coefficients stay in the cache for every light); maps of more
    than `max_pixels` pixels summed over every k-th block of rows (the smallest k that keeps
    ≤ max_pixels: an even sample of the whole map; `relight_error_step`)."""
    h, w = np.shape(mask)[:2]
    step = relight_error_step(h, w, len(images), rows, max_pixels)
    num, den = (sum(x) for x in zip(*relight_error_parts(fit, images, light_dirs, mask, range(0, h, step), rows,
                                                         workers)))
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def relight_error_parts(fit, images, light_dirs, mask, starts, rows=2, workers=2):
    """[(Σ |render - image|², Σ |image|²) of image rows a..a+rows for a in starts], the sums
    `fit_relight_error` adds up (in that order), here of arrays that may be a band of rows."""
    ptm = isinstance(fit, PTMFit)
    d_all = np.asarray(light_dirs, float)
    images, mask = np.asarray(images), np.asarray(mask, bool)
    basis = fit.basis(d_all) if d_all.ndim == 2 else None                   # far: (m, T)

    def part(r):
        sl = slice(r, r + rows)
        if d_all.ndim == 2:
            # the masked pixels only (the 16-bit DiLiGenT ball's object is 5 % of its image)
            m, n_terms, px = *basis.shape, np.flatnonzero(mask[sl])
            img = images[:, sl].reshape(m, -1, 3)[:, px]                      # (m, k, 3)
            coeffs = fit.coeffs[sl].reshape(mask[sl].size, -1)[px]            # (k, 6) or (k, 3·T)
            pred = np.clip(basis @ coeffs.reshape(-1, n_terms).T, 0, None)   # (m, k[·3])
            if ptm:
                pred = pred[..., None] * fit.rgb[sl].reshape(-1, 3)[px][None]
            pred = _to_images(fit, pred).reshape(img.shape)
            sel = _all3(np.isfinite(img))[..., None]
            diff = np.where(sel, pred - img, 0.0).ravel()
            x = np.where(sel, img, np.zeros((), img.dtype)).astype(np.float64).ravel()
            return float(diff @ diff), float(x @ x)
        arrays = {k: getattr(fit, k)[sl] for k in ("coeffs", "valid", "rgb") if hasattr(fit, k)}
        sub = replace(fit, **arrays)
        relight = relight_ptm if ptm else relight_hsh
        return _error_sums(lambda q: relight(sub, q), images[:, sl], np.moveaxis(d_all[sl], 2, 0), mask[sl])

    return run_blocks(part, starts, workers)
