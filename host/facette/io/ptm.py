"""Polynomial texture maps, PTM_FORMAT_LRGB (Malzbender & Gelb, "Polynomial Texture Map (.ptm)
File Format", HP Labs, version 1.2, 2001), the format RTIViewer and the HP PTM viewer open.

Layout (§2 of that document): the ASCII lines ``PTM_1.2``, ``PTM_FORMAT_LRGB``, the width,
the height, six scale floats, six bias integers, then the binary data: the six luminance
coefficients a0..a5 of every pixel as bytes, then the R, G, B bytes of every pixel, both in
"simple reversed scanline order" (the bottom row first, left to right). A coefficient is
recovered as a = (byte - bias) · scale; the pixel's colour is L(lu, lv) · RGB / 255.
"""
from pathlib import Path

import numpy as np

__all__ = ["write_ptm_lrgb", "quantize_scale_bias", "column_range"]

ROWS = 64                  # image rows quantized at a time


def column_range(a, fold=256):
    """(min, max) over axis 0 of a 2-D array (N, T) with few columns, the same values as
    a.min(0), a.max(0) ~15x faster: `fold` rows side by side make a long contiguous inner
    loop (12 MP HSH coefficients, (27 M, 9) float32: 0.04 s instead of 0.6)."""
    n, t = a.shape
    full = n // fold * fold
    if full == 0:
        return a.min(axis=0), a.max(axis=0)
    b = a[:full].reshape(-1, fold * t)
    lo, hi = b.min(axis=0).reshape(fold, t).min(axis=0), b.max(axis=0).reshape(fold, t).max(axis=0)
    if full < n:
        lo, hi = np.minimum(lo, a[full:].min(axis=0)), np.maximum(hi, a[full:].max(axis=0))
    return lo, hi


def quantize_scale_bias(coeffs):
    """Per-coefficient scale (float) and integer bias in [0, 255] so that every value of
    coeffs (N, 6) is within half a step of some byte: a = (byte - bias) · scale.
    Returns (scale (6,), bias (6,) int)."""
    lo, hi = column_range(coeffs)
    lo, hi = np.minimum(lo.astype(np.float64), 0.0), np.maximum(hi.astype(np.float64), 0.0)
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    bias = np.clip(np.round(-lo / span * 255.0), 0, 255).astype(int)
    # the scale that fits both ends once the zero is on an integer byte
    up = np.where(bias < 255, hi / np.maximum(255 - bias, 1), 0.0)
    down = np.where(bias > 0, -lo / np.maximum(bias, 1), 0.0)
    scale = np.maximum(np.maximum(up, down), 1e-12)
    return scale, bias


def write_ptm_lrgb(path, coeffs, rgb):
    """Write a PTM_FORMAT_LRGB file.

    coeffs : (H, W, 6) float, the luminance polynomial a0..a5 per pixel (image row 0 = top),
        in the order of `facette.recon.ptm_basis`; rgb : (H, W, 3) floats in [0, 1] (clipped).
    Returns {"scale": [6], "bias": [6]} as written.
    """
    coeffs = np.asarray(coeffs)            # float32 or float64 as given: no full-size copy
    if not np.issubdtype(coeffs.dtype, np.floating):
        coeffs = coeffs.astype(np.float64)
    rgb = np.asarray(rgb, dtype=np.float64)
    if coeffs.ndim != 3 or coeffs.shape[2] != 6 or 0 in coeffs.shape:
        raise ValueError(f"PTM coefficients must have shape (H, W, 6), got {coeffs.shape}")
    if rgb.shape != coeffs.shape[:2] + (3,):
        raise ValueError(f"rgb must have shape {coeffs.shape[:2] + (3,)}, got {rgb.shape}")
    if not (np.isfinite(coeffs).all() and np.isfinite(rgb).all()):
        raise ValueError("PTM coefficients and colours must be finite (set unfitted pixels to 0)")
    h, w, _ = coeffs.shape
    scale, bias = quantize_scale_bias(coeffs.reshape(-1, 6))
    q = np.empty(coeffs.shape, np.uint8)
    for r in range(0, h, ROWS):          # by rows, in place: no full-size float64 temporaries
        x = coeffs[r:r + ROWS].astype(np.float64)
        x /= scale
        x += bias
        np.round(x, out=x)
        q[r:r + ROWS] = np.clip(x, 0, 255, out=x)
    c = np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)
    header = ("PTM_1.2\nPTM_FORMAT_LRGB\n"
              f"{w}\n{h}\n"          # separate lines: legal (§2.3) and what every reader takes
              + " ".join(f"{s:.9g}" for s in scale) + "\n"
              + " ".join(str(int(b)) for b in bias) + "\n")
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(q[::-1].tobytes())           # bottom row first
        out.write(c[::-1].tobytes())
    tmp.replace(path)
    return {"scale": [float(s) for s in scale], "bias": [int(b) for b in bias]}
