"""`facette.recon._rti`'s fits as photographed (`fit_ptm_lrgb`, `fit_hsh` with photographed=True): every
sample as the photograph shows it, lut(clip(value / white, 0, 1)) with lut the sRGB encoding or the
identity, a value above the top of the range (NaN: unknown to photometric stereo) at full brightness,
fitted by plain least squares (RTIBuilder's way) with a small ridge (PHOTO_RCOND) that keeps the
coefficients within what 8-bit files carry."""
import numpy as np

from facette._threads import run_blocks
from facette.recon._rti import _BLOCK, HSHFit, PTMFit, _all3, _solve_blocks, _top_percentile, hsh_basis, ptm_basis

__all__ = ["brightest_white", "fit_ptm_displayed", "fit_hsh_displayed", "PHOTO_RCOND"]

# These fits go to files of 8 bits per coefficient, each term's range set by its extreme
# pixel: under lights in a cone (DiLiGenT's, within ~45° of the axis) HSH's constant and zonal terms
# cancel each other in ±8 pairs, which the bytes cannot carry. A ridge of 1e-4 keeps them within ±1.
# Chosen on renders (a sphere on a plane, 8-bit sRGB, lights in a 45° cone / 60° cone / 83° dome,
# every 6th held out, files quantised): held-out PSNR 26.88 -> 26.95 dB (matte) and 26.42 -> 26.59
# (glossy) in the cone, the same in the dome, the captured lights within 0.15 dB of the float fit;
# 1e-3 costs 0.4 dB at the captured lights.
PHOTO_RCOND = 1e-4


def brightest_white(images, mask=None, percentile=99.0):
    """The `percentile` of the brightest channel of the finite, positive values of images (m, H, W, 3)
    over the masked pixels (mask (H, W) bool or None: all) and every light."""
    m, h, w, _ = np.shape(images)
    flat = np.asarray(images).reshape(m, h * w, 3)
    sel = None if mask is None else np.asarray(mask, bool).reshape(-1)

    def brightest(a):    # the brightest channel of the finite (masked) values, by blocks
        sl = slice(a, a + _BLOCK)
        e = flat[:, sl]
        ok = _all3(np.isfinite(e)) if sel is None else _all3(np.isfinite(e)) & sel[None, sl]
        top = np.maximum(np.maximum(e[..., 0], e[..., 1]), e[..., 2])
        return top[ok & (top > 0)]

    return _top_percentile(brightest, range(0, h * w, _BLOCK), percentile)


def _display_table(encoding):
    from facette.recon._rti_jit import linear_table, srgb_table
    return srgb_table() if encoding == "srgb" else linear_table()


def fit_ptm_displayed(images, dirs, mask, white, white_percentile, encoding, rgb, peak, lum, out=None):
    """`fit_ptm_lrgb`'s photographed=True: the LRGB split of the displayed samples, then their fit."""
    from facette.recon._rti_jit import display_colour_lum_block
    m, h, w, _ = images.shape
    flat = images.reshape(m, h * w, 3)
    if white is None:
        white = brightest_white(images, mask, white_percentile)
    if not white > 0:
        raise ValueError(f"white level must be > 0, got {white}")
    lut = _display_table(encoding)
    run_blocks(lambda a: display_colour_lum_block(flat[:, a:a + _BLOCK], rgb, peak, lum, a, 1.0 / white, lut),
               range(0, h * w, _BLOCK))
    ones = np.ones((m, 1), np.float64)

    def values(e):                          # every sample known: clipped ones are at the top
        return e, np.broadcast_to(ones, e.shape[:2])

    coeffs, valid = _solve_blocks(lum.reshape(m, h, w, 1), dirs, ptm_basis, 6, values, rcond=PHOTO_RCOND, out=out)
    return PTMFit(coeffs[:, 0].reshape(h, w, 6), rgb.reshape(h, w, 3), float(white), valid.reshape(h, w), encoding)


def fit_hsh_displayed(images, dirs, order, white, encoding, out=None):
    """`fit_hsh`'s photographed=True, white known (out: `fit_hsh`'s)."""
    from facette.recon._rti_jit import display_inplace
    m, h, w, _ = images.shape
    n_terms = order * order
    lut = _display_table(encoding)
    ones = np.ones((m, 1), np.float64)

    def shown(e):                       # every sample known: clipped ones are at the top
        display_inplace(e, 1.0 / white, lut)
        return e, np.broadcast_to(ones, e.shape[:2])

    coeffs, valid = _solve_blocks(images, dirs, lambda d: hsh_basis(d, order), n_terms, shown, rcond=PHOTO_RCOND,
                                  out=out)
    return HSHFit(coeffs.reshape(h, w, 3, n_terms), order, float(white), valid.reshape(h, w), encoding)
