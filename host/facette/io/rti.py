"""Hemispherical-harmonics RTI files (.rti, "#HSH1.2"), written and read as Cultural Heritage
Imaging's RTIBuilder writes them and RTIViewer and Relight read them.

Layout: comment lines starting with '#' (the first is ``#HSH1.2``), the file type ``3``
(HSH), ``width height bands`` (bands = 3, RGB), ``terms basis_type element_size``
(order² terms, basis type 2, 1 byte per element); then `terms` little-endian float32
scales, `terms` float32 biases, and the pixels, **the top row of the picture first** (as
RTIBuilder's own files, RTIViewer's loader, which fills rows 0 .. h-1 from the top, and
Relight's, which turns them into its bottom-up rows), left to right, each as `terms` bytes for
red, then green, then blue. A coefficient is byte / 255 · scale[k] + bias[k]; the value at a
light is Σ_k coeff_k H_k(light), shown as that value × 255 (1 = full brightness).
`hsh_weights` is the basis in RTIViewer's closed form.
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facette.errors import BadInputError
from facette.io.atomic import atomic_path
from facette.io.ptm import column_range

__all__ = ["write_hsh_rti", "write_hsh_rti_rows", "read_hsh_rti", "HSHFile", "hsh_weights", "hsh_terms"]

HSH_FILE_TYPE = 3          # RTIViewer's file types: 1 PTM, 2 spherical harmonics, 3 HSH
HSH_BASIS_TYPE = 2
ROWS = 64                  # image rows quantized at a time
COMPILED = True            # the bytes by the compiled quantisation (io._quantize_jit), else numpy's steps


def write_hsh_rti(path, coeffs, comments=()):
    """Write an HSH .rti file.

    coeffs : (H, W, 3, T) float, T = 4 or 9 (order 2 or 3) HSH coefficients per colour
        channel (image row 0 = top), values that relight to [0, 1] as displayed.
    comments : lines written after ``#HSH1.2`` as '#' comments (what the values are).
    Returns {"scale": [T], "bias": [T]} as written (scale = max - min, bias = min per term).
    """
    coeffs = np.asarray(coeffs)            # float32 or float64 as given: no full-size copy
    if not np.issubdtype(coeffs.dtype, np.floating):
        coeffs = coeffs.astype(np.float64)
    if coeffs.ndim != 4 or coeffs.shape[2] != 3 or coeffs.shape[3] not in (4, 9) or 0 in coeffs.shape:
        raise ValueError(f"HSH coefficients must have shape (H, W, 3, 4 or 9), got {coeffs.shape}")
    h, w, _, t = coeffs.shape
    return write_hsh_rti_rows(path, w, h, column_range(coeffs.reshape(-1, t)), lambda r0, r1: coeffs[r0:r1],
                              comments)


def write_hsh_rti_rows(path, width, height, coeff_range, coeff_rows, comments=()):
    """`write_hsh_rti` band by band: the same bytes without the whole array.

    coeff_range : (lo (T,), hi (T,)), each term's minimum and maximum over every pixel and
    channel (`column_range` of the (H·W·3, T) coefficients, in their dtype); coeff_rows(r0, r1)
    -> (r1 - r0, W, 3, T) float, image rows r0..r1 (row 0 = top), asked for top band first.
    """
    comments = [str(c) for c in comments]
    if any("\n" in c or "\r" in c for c in comments):
        raise ValueError("an .rti comment is one line")
    h, w = int(height), int(width)
    lo, hi = (np.asarray(x) for x in coeff_range)
    t = lo.size
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):   # NaN and ±inf reach min or max
        raise ValueError("HSH coefficients must be finite (set unfitted pixels to 0)")
    scale = np.where(hi > lo, hi - lo, 1.0).astype("<f4")
    bias = lo.astype("<f4")
    header = ("#HSH1.2\n" + "".join(f"# {c}\n" for c in comments)
              + f"{HSH_FILE_TYPE}\n{w} {h} 3\n{t} {HSH_BASIS_TYPE} 1\n")
    with atomic_path(path, needed=len(header) + 3 * t * w * h + 8 * t) as tmp, open(tmp, "wb") as out:
        out.write(header.encode("utf-8"))
        out.write(scale.tobytes())
        out.write(bias.tobytes())
        for r in range(0, h, ROWS):      # by rows: no full-size float64 temporaries
            out.write(_rti_bytes(np.asarray(coeff_rows(r, min(h, r + ROWS))), bias, scale).tobytes())
    return {"scale": [float(s) for s in scale], "bias": [float(b) for b in bias]}


def _rti_bytes(c, bias, scale):
    """The bytes (..., T) uint8 of a band of coefficients c (..., T): top row first; R terms, G, B.
    Compiled when COMPILED (`_quantize_jit.rti_bytes`: numpy's bytes in one pass), else numpy's float64 steps."""
    if COMPILED and np.issubdtype(c.dtype, np.floating):
        from facette.io._quantize_jit import rti_bytes        # numba loads only when this runs
        c = np.ascontiguousarray(c)
        out = np.empty(c.shape, np.uint8)
        rti_bytes(c.reshape(-1, c.shape[-1]), bias, scale, out.reshape(-1, c.shape[-1]))
        return out
    x = c.astype(np.float64)
    x -= bias
    x /= scale
    x *= 255.0
    np.round(x, out=x)
    return np.clip(x, 0, 255, out=x).astype(np.uint8)


def hsh_weights(light, terms=9):
    """RTIViewer's hemispherical-harmonics weights (its getHSH, closed form) at light
    directions (..., 3) (x right, y up, z towards the camera) -> (..., terms), terms 4 or 9."""
    d = np.asarray(light, dtype=np.float64)
    phi = np.arctan2(d[..., 1], d[..., 0])
    ct = np.clip(d[..., 2] / np.maximum(np.linalg.norm(d, axis=-1), 1e-300), 0.0, 1.0)
    return hsh_terms(phi, ct, terms)


def hsh_terms(phi, ct, terms=9, pi=np.pi):
    """The hemispherical harmonics (Gautron 2004) at azimuth phi and cos θ ct -> (..., terms),
    terms 4 or 9; `pi` as the viewer writes it (openlime's shader: 3.1415)."""
    if terms not in (4, 9):
        raise ValueError(f"HSH terms must be 4 or 9, got {terms}")
    ct2 = ct * ct
    s = np.sqrt(np.maximum(ct - ct2, 0.0))
    w = [np.full_like(ct, 1 / np.sqrt(2 * pi)),
         np.sqrt(6 / pi) * np.cos(phi) * s,
         np.sqrt(3 / (2 * pi)) * (-1 + 2 * ct),
         np.sqrt(6 / pi) * s * np.sin(phi),
         np.sqrt(30 / pi) * np.cos(2 * phi) * (-ct + ct2),
         np.sqrt(30 / pi) * np.cos(phi) * (-1 + 2 * ct) * s,
         np.sqrt(5 / (2 * pi)) * (1 - 6 * ct + 6 * ct2),
         np.sqrt(30 / pi) * (-1 + 2 * ct) * s * np.sin(phi),
         np.sqrt(30 / pi) * (-ct + ct2) * np.sin(2 * phi)]
    return np.stack(w[:terms], axis=-1)


@dataclass
class HSHFile:
    """An HSH .rti as the readers hold it: coeffs (H, W, 3, terms) float64 with image row 0
    at the top of the picture; scale, bias (terms,) as stored; comments: the '#' lines."""
    width: int
    height: int
    terms: int
    scale: np.ndarray
    bias: np.ndarray
    coeffs: np.ndarray
    comments: list = field(default_factory=list)

    def relight(self, light):
        """The picture (H, W, 3) as displayed at a light direction (3,) or per-pixel
        directions (H, W, 3), in [0, 1]."""
        b = hsh_weights(light, self.terms)
        val = self.coeffs @ b if b.ndim == 1 else np.einsum("hwct,hwt->hwc", self.coeffs, b)
        return np.clip(val, 0.0, 1.0)

    @property
    def encoding(self):
        """"linear" when a comment says the values are linear, else "srgb" (RTIBuilder's)."""
        text = " ".join(self.comments).lower()
        return "linear" if "encoding: linear" in text else "srgb"


def read_hsh_rti(path):
    """Read an HSH .rti file (file type 3, 1 byte per element) -> `HSHFile`."""
    path = Path(path)
    data = path.read_bytes()
    if not data.startswith(b"#HSH1.2"):
        raise BadInputError(f"{path} is not an HSH .rti file (it does not start with #HSH1.2)")
    pos, comments = 0, []
    while data[pos:pos + 1] == b"#":
        end = data.index(b"\n", pos)
        comments.append(data[pos + 1:end].decode("utf-8", "replace").strip())
        pos = end + 1
    vals = []
    for _ in range(3):
        end = data.find(b"\n", pos)
        if end < 0:
            raise BadInputError(f"{path}: the .rti header ends early")
        line = data[pos:end].decode("latin-1").strip()
        try:
            vals.append([int(t) for t in line.split()])
        except ValueError:
            vals.append(None)
        if vals[-1] is None or len(vals[-1]) != (1, 3, 3)[len(vals) - 1]:
            raise BadInputError(f"{path}, line {len(comments) + len(vals)}: {line[:40]!r} is not the header's "
                                f"{('file type', 'width height bands', 'terms basis element-size')[len(vals) - 1]}"
                                " (whole numbers)", hint="rewrite the file with the tool that made it")
        pos = end + 1
    if vals[0] != [HSH_FILE_TYPE]:
        raise BadInputError(f"{path}: .rti file type {vals[0]} is not read (3, HSH, is)")
    (w, h, bands), (terms, _basis, size) = vals[1], vals[2]
    if bands != 3 or size != 1 or terms not in (4, 9):
        raise BadInputError(f"{path}: {bands} bands, {terms} terms, {size}-byte elements: "
                            "3 bands of 4 or 9 one-byte terms are read")
    if len(data) < pos + 8 * terms:
        raise BadInputError(f"{path}: the file ends in the scale and bias after the header")
    scale = np.frombuffer(data, "<f4", terms, pos).astype(np.float64)
    bias = np.frombuffer(data, "<f4", terms, pos + 4 * terms).astype(np.float64)
    n = w * h * 3 * terms
    body = np.frombuffer(data, np.uint8, offset=pos + 8 * terms)
    if body.size < n:
        raise BadInputError(f"{path}: {body.size} data bytes for {w}x{h} pixels ({n} expected)")
    q = body[:n].reshape(h, w, 3, terms)          # top row first; per pixel R, G, B blocks
    return HSHFile(w, h, terms, scale, bias, q / 255.0 * scale + bias, comments[1:])
