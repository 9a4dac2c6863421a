"""Hemispherical-harmonics RTI files (.rti, "#HSH1.2"), as written by Cultural Heritage
Imaging's RTIBuilder (its HSH fitter) and read by RTIViewer.

Layout: the ASCII lines ``#HSH1.2`` (comment lines start with '#'), the file type ``3``
(HSH), ``width height bands`` (bands = 3, RGB), ``terms basis_type element_size``
(order² terms, basis type 2, 1 byte per element); then `terms` little-endian float32
scales, `terms` float32 biases, and the pixels, the bottom row first, left to right, each
as terms bytes for red, then green, then blue. A coefficient is
byte / 255 · scale[k] + bias[k]. The basis is `facette.recon.hsh_basis`.
"""
from pathlib import Path

import numpy as np

from facette.io.ptm import column_range

__all__ = ["write_hsh_rti"]

HSH_FILE_TYPE = 3          # RTIViewer's file types: 1 PTM, 2 spherical harmonics, 3 HSH
HSH_BASIS_TYPE = 2
ROWS = 64                  # image rows quantized at a time


def write_hsh_rti(path, coeffs):
    """Write an HSH .rti file.

    coeffs : (H, W, 3, T) float, T = 4 or 9 (order 2 or 3) HSH coefficients per colour
        channel (image row 0 = top), values that relight to [0, 1] for display.
    Returns {"scale": [T], "bias": [T]} as written (scale = max - min, bias = min per term).
    """
    coeffs = np.asarray(coeffs)            # float32 or float64 as given: no full-size copy
    if not np.issubdtype(coeffs.dtype, np.floating):
        coeffs = coeffs.astype(np.float64)
    if coeffs.ndim != 4 or coeffs.shape[2] != 3 or coeffs.shape[3] not in (4, 9) or 0 in coeffs.shape:
        raise ValueError(f"HSH coefficients must have shape (H, W, 3, 4 or 9), got {coeffs.shape}")
    h, w, _, t = coeffs.shape
    terms = coeffs.reshape(-1, t)
    lo, hi = column_range(terms)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):   # NaN and ±inf reach min or max
        raise ValueError("HSH coefficients must be finite (set unfitted pixels to 0)")
    scale = np.where(hi > lo, hi - lo, 1.0).astype("<f4")
    bias = lo.astype("<f4")
    q = np.empty(coeffs.shape, np.uint8)
    for r in range(0, h, ROWS):          # by rows, in place: no full-size float64 temporaries
        x = coeffs[r:r + ROWS].astype(np.float64)
        x -= bias
        x /= scale
        x *= 255.0
        np.round(x, out=x)
        q[r:r + ROWS] = np.clip(x, 0, 255, out=x)
    header = f"#HSH1.2\n{HSH_FILE_TYPE}\n{w} {h} 3\n{t} {HSH_BASIS_TYPE} 1\n"
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "wb") as out:
        out.write(header.encode("ascii"))
        out.write(scale.tobytes())
        out.write(bias.tobytes())
        out.write(q[::-1].tobytes())           # bottom row first; per pixel R terms, G, B
    tmp.replace(path)
    return {"scale": [float(s) for s in scale], "bias": [float(b) for b in bias]}
