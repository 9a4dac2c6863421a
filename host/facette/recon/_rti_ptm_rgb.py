"""A per-channel PTM (PTM_FORMAT_RGB: Malzbender & Gelb, "Polynomial Texture Map (.ptm) File Format"
1.2, §2.4): each colour channel its own biquadratic polynomial of the light, fitted to the samples as
photographed (`recon._rti_photo`: lut(clip(value / white, 0, 1)), plain least squares with its small
ridge), the fit RTIBuilder's per-channel PTM makes.

The LRGB PTM (`fit_ptm_lrgb`) shares one luminance polynomial between the three channels, times a fixed
colour: a pixel whose colour changes with the light (a highlight whiter than the body colour, a
coloured inter-reflection) is fitted in the luminance only. Held out, that cost 0.2-0.5 dB against a
plain per-channel PTM on 3 of 6 real captures (facette bench rti, section 5); this fit has the plain
fit's model, and its file twice the LRGB's bytes (18 per pixel instead of 9).

`ptm_loo_parts` measures, on the pixels the relighting error samples, each model's leave-one-light-out
error (exact for a linear least-squares fit: the residual over 1 - the hat matrix's diagonal, the
same design for every pixel under far lights), so that the file's format is chosen per capture on
lights each fit did not see.
"""
from dataclasses import dataclass

import numpy as np

from facette.recon._rti import HSHFit, _solve_blocks, ptm_basis

__all__ = ["PTMRGBFit", "fit_ptm_rgb", "ptm_loo_parts"]


@dataclass
class PTMRGBFit(HSHFit):
    """A per-channel PTM: displayed colour (H, W, 3) = Σ_k coeffs[..., c, k] P_k(l), P = `ptm_basis`;
    the image value as in `PTMFit` (white, encoding). coeffs (H, W, 3, 6) float32; order None."""
    CONSTANT = 5

    def basis(self, d):
        return ptm_basis(d)


def fit_ptm_rgb(images, dirs, white, encoding, out=None):
    """The per-channel PTM of images (m, H, W, 3) under dirs (m, 3) or (H, W, m, 3), as
    photographed with `white` known (`fit_hsh(..., photographed=True)`'s fit in the PTM's basis;
    out: (H, W, 3, 6) float32 for the coefficients, or None)."""
    from facette.recon._rti_jit import display_inplace
    from facette.recon._rti_photo import PHOTO_RCOND, _display_table
    m, h, w, _ = images.shape
    lut = _display_table(encoding)
    ones = np.ones((m, 1), np.float64)

    def shown(e):                       # every sample known: clipped ones are at the top
        display_inplace(e, 1.0 / white, lut)
        return e, np.broadcast_to(ones, e.shape[:2])

    coeffs, valid = _solve_blocks(images, dirs, ptm_basis, 6, shown, rcond=PHOTO_RCOND, out=out)
    return PTMRGBFit(coeffs.reshape(h, w, 3, 6), None, float(white), valid.reshape(h, w), encoding)


def _hat_diagonal(dirs):
    """diag(A (AᵀA + ridge)⁻¹ Aᵀ) (m,) of the PTM design under far lights, with the photographed fits'
    ridge (`_rti._ridge_solve`'s rule): lights at or below the horizon 0 (not fitted)."""
    from facette.recon._rti_photo import PHOTO_RCOND
    a = ptm_basis(dirs) * (dirs[:, 2] > 0)[:, None]
    ata = a.T @ a
    ata += PHOTO_RCOND * max(np.trace(ata), 1e-300) * np.eye(6)
    return np.einsum("mi,mi->m", a, np.linalg.solve(ata, a.T).T)


def ptm_loo_parts(lrgb, rgb, images, dirs, mask, starts, rows=2):
    """[(Σ LRGB, Σ RGB squared leave-one-light-out errors, samples)] in display values over the masked
    pixels of image rows a..a+rows for a in starts (`relight_error_parts`' rows), far lights only
    (None with per-pixel directions). lrgb: a photographed `PTMFit`, rgb: a `PTMRGBFit` of the same
    images (m, h, W, 3) (a band). The LRGB's colour is kept as fitted from every light (its
    luminance is left out): a little in its favour."""
    from facette.recon._rti_jit import display_inplace
    from facette.recon._rti_photo import _display_table
    d = np.asarray(dirs, float)
    if d.ndim != 2:
        return None
    up = d[:, 2] > 0
    lever = 1.0 / np.maximum(1.0 - _hat_diagonal(d), 1e-6)        # residual -> left-out residual
    basis, lut = ptm_basis(d), _display_table(rgb.encoding)
    out = []
    for a in starts:
        px = np.flatnonzero(np.asarray(mask[a:a + rows], bool))
        if px.size == 0:
            out.append((0.0, 0.0, 0))
            continue
        m = images.shape[0]
        y = np.ascontiguousarray(images[:, a:a + rows].reshape(m, -1, 3)[:, px], np.float32)
        display_inplace(y, 1.0 / rgb.white, lut)                          # (m, k, 3) as fitted
        y = y[up].astype(np.float64)
        b = basis[up]
        c = rgb.coeffs[a:a + rows].reshape(-1, 3, 6)[px].astype(np.float64)          # (k, 3, 6)
        # each left-out prediction as a viewer shows it (clipped to [0, 1])
        res_rgb = y - np.clip(y - (y - np.einsum("mt,kct->mkc", b, c)) * lever[up, None, None], 0, 1)
        col = lrgb.rgb[a:a + rows].reshape(-1, 3)[px].astype(np.float64)             # (k, 3)
        lum = (y * col).sum(-1) / np.maximum((col * col).sum(-1), 1e-12)             # each sample's L
        fit_l = b @ lrgb.coeffs[a:a + rows].reshape(-1, 6)[px].astype(np.float64).T  # (m, k)
        held = lum - (lum - fit_l) * lever[up, None]                                 # L without the sample
        res_lrgb = y - np.clip(held[..., None] * col, 0, 1)
        out.append((float((res_lrgb ** 2).sum()), float((res_rgb ** 2).sum()), int(res_rgb.size)))
    return out

