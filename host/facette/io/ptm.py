"""Polynomial texture maps, PTM_FORMAT_LRGB and PTM_FORMAT_RGB (Malzbender & Gelb, "Polynomial Texture Map (.ptm)
File Format", HP Labs, version 1.2, 2001), written and read as RTIViewer and Relight do.

Layout (§2 of that document): the ASCII lines ``PTM_1.2``, ``PTM_FORMAT_LRGB``, the width,
the height, six scale floats, six bias integers, then the binary data: the six luminance
coefficients a0..a5 of every pixel as bytes, then the R, G, B bytes of every pixel, both
bottom row first ("reversed scanline order": RTIViewer's loader fills rows h-1 .. 0, Relight's
keeps them as its bottom-up rows). A coefficient is a = (byte - bias) · scale.

Units, as every reader takes them: the luminance L(lu, lv) = a0 lu² + a1 lv² + a2 lu lv + a3 lu
+ a4 lv + a5 is in byte units (255 = the stored colour at full brightness; HP's own files have
constant terms reaching 510) and a pixel is shown as L · RGB / 255, RGB the stored bytes.
RTIViewer keeps each coefficient as the integer ``int((byte - bias) · scale)`` (truncated);
Relight keeps the float. `PTMFile.relight` does either (``rtiviewer=True``: the truncation).

`read_ptm` also reads PTM_FORMAT_JPEG_LRGB (HP's compressed variant: nine JPEG planes, some
predicted from others), as RTIViewer's JPEGLRGBPtm loader does.
"""
import io as _io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facette.errors import BadInputError
from facette.io.atomic import atomic_path

__all__ = ["write_ptm_lrgb", "write_ptm_lrgb_rows", "write_ptm_rgb_rows", "ptm_rgb_bytes", "quantize_scale_bias", "scale_bias_of_range",
           "column_range", "read_ptm", "PTMFile", "ptm_weights", "FULL"]

ROWS = 64                  # image rows quantized at a time
COMPILED = True            # the bytes by the compiled quantisation (io._quantize_jit), else numpy's steps
FULL = 255.0               # the luminance every reader takes as full brightness


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
    return scale_bias_of_range(*column_range(coeffs))


def scale_bias_of_range(lo, hi):
    """`quantize_scale_bias` of coefficients whose per-coefficient minimum is lo (6,) and
    maximum hi (6,) (the same answer from the range alone: a file written band by band)."""
    lo, hi = np.minimum(np.asarray(lo).astype(np.float64), 0.0), np.maximum(np.asarray(hi).astype(np.float64), 0.0)
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    bias = np.clip(np.round(-lo / span * 255.0), 0, 255).astype(int)
    # the scale that fits both ends once the zero is on an integer byte
    up = np.where(bias < 255, hi / np.maximum(255 - bias, 1), 0.0)
    down = np.where(bias > 0, -lo / np.maximum(bias, 1), 0.0)
    scale = np.maximum(np.maximum(up, down), 1e-12)
    return scale, bias


def write_ptm_lrgb(path, coeffs, rgb):
    """Write a PTM_FORMAT_LRGB file that RTIViewer and Relight show as fitted.

    coeffs : (H, W, 6) float, the luminance polynomial a0..a5 per pixel (image row 0 = top),
        in the order of `ptm_weights`, with L = 1 for the stored colour at full brightness
        (stored ×255: byte units, what the readers take); rgb : (H, W, 3) display colour in
        [0, 1] (clipped), stored as bytes. The picture shown at light l is L(l) · rgb.
    Returns {"scale": [6], "bias": [6]} as written (byte units).
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
    return write_ptm_lrgb_rows(path, w, h, column_range(coeffs.reshape(-1, 6)), lambda r0, r1: coeffs[r0:r1],
                               lambda r0, r1: rgb[r0:r1])


def ptm_rgb_bytes(rgb):
    """The stored colour bytes (..., 3) uint8 of display colours in [0, 1] (clipped)."""
    return np.clip(np.round(np.asarray(rgb, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


def write_ptm_lrgb_rows(path, width, height, coeff_range, coeff_rows, rgb_rows):
    """`write_ptm_lrgb` band by band: the same bytes without the whole arrays.

    coeff_range : (lo (6,), hi (6,)), the coefficients' minimum and maximum over every pixel
    (`column_range`); coeff_rows(r0, r1) -> (r1 - r0, W, 6) float, the coefficients of image
    rows r0..r1 (row 0 = top); rgb_rows(r0, r1) -> (r1 - r0, W, 3): display colours in [0, 1]
    or their bytes (uint8, `ptm_rgb_bytes`). They are asked for bottom band first, twice (the
    file holds every coefficient, then every colour, bottom row first).
    """
    h, w = int(height), int(width)
    lo, hi = (np.asarray(x) for x in coeff_range)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("PTM coefficients and colours must be finite (set unfitted pixels to 0)")
    scale, bias = scale_bias_of_range(lo, hi)
    scale = scale * FULL                  # byte units: the range of L·255
    header = ("PTM_1.2\nPTM_FORMAT_LRGB\n"
              f"{w}\n{h}\n"          # separate lines: legal (§2.3) and what every reader takes
              + " ".join(f"{s:.9g}" for s in scale) + "\n"
              + " ".join(str(int(b)) for b in bias) + "\n")
    bottom_up = [(max(0, r1 - ROWS), r1) for r1 in range(h, 0, -ROWS)]
    with atomic_path(path, needed=len(header) + 9 * w * h) as tmp, open(tmp, "wb") as out:
        out.write(header.encode("ascii"))
        for r0, r1 in bottom_up:         # by rows: no full-size float64 temporaries
            out.write(_ptm_bytes(np.asarray(coeff_rows(r0, r1)), scale, bias)[::-1].tobytes())   # bottom row first
        for r0, r1 in bottom_up:
            c = np.asarray(rgb_rows(r0, r1))
            if c.dtype != np.uint8:
                if not np.isfinite(c).all():
                    raise ValueError("PTM coefficients and colours must be finite (set unfitted pixels to 0)")
                c = ptm_rgb_bytes(c)
            out.write(c[::-1].tobytes())
    return {"scale": [float(s) for s in scale], "bias": [int(b) for b in bias]}


def _ptm_bytes(c, scale, bias):
    """The bytes (..., 6) uint8 of coefficients c (..., 6): compiled when COMPILED (`_quantize_jit.ptm_bytes`,
    numpy's bytes in one pass), else numpy's float64 steps."""
    if COMPILED and np.issubdtype(c.dtype, np.floating):
        from facette.io._quantize_jit import ptm_bytes        # numba loads only when this runs
        c = np.ascontiguousarray(c)
        out = np.empty(c.shape, np.uint8)
        ptm_bytes(c.reshape(-1, c.shape[-1]), FULL, np.asarray(scale, np.float64), np.asarray(bias),
                  out.reshape(-1, c.shape[-1]))
        return out
    x = c.astype(np.float64)
    x *= FULL
    x /= scale
    x += bias
    np.round(x, out=x)
    return np.clip(x, 0, 255, out=x).astype(np.uint8)


def write_ptm_rgb_rows(path, width, height, coeff_range, coeff_rows):
    """A PTM_FORMAT_RGB file (§2.4: a polynomial per colour channel), band by band.

    coeff_range : (lo (6,), hi (6,)), each term's minimum and maximum over every pixel and channel
    (the header has one scale and bias per term, shared by the channels: `column_range` of the
    coefficients as (·, 6)); coeff_rows(r0, r1) -> (r1 - r0, W, 3, 6) float, rows r0..r1 (row 0 =
    top), with 1 = the channel at full brightness (stored ×255: byte units, as in the LRGB).
    Layout, as RTIViewer's RGBPtm and HP's reader take it: the header of the LRGB with
    PTM_FORMAT_RGB, then the six bytes of every pixel for red, bottom row first, then green, then
    blue (so the rows are asked for three times, bottom band first). A channel is shown as the
    polynomial's value / 255. Returns {"scale": [6], "bias": [6]} as written (byte units)."""
    h, w = int(height), int(width)
    lo, hi = (np.asarray(x) for x in coeff_range)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("PTM coefficients must be finite (set unfitted pixels to 0)")
    scale, bias = scale_bias_of_range(lo, hi)
    scale = scale * FULL
    header = ("PTM_1.2\nPTM_FORMAT_RGB\n" f"{w}\n{h}\n" + " ".join(f"{s:.9g}" for s in scale) + "\n"
              + " ".join(str(int(b)) for b in bias) + "\n")
    bottom_up = [(max(0, r1 - ROWS), r1) for r1 in range(h, 0, -ROWS)]
    with atomic_path(path, needed=len(header) + 18 * w * h) as tmp, open(tmp, "wb") as out:
        out.write(header.encode("ascii"))
        for c in range(3):
            for r0, r1 in bottom_up:
                out.write(_ptm_bytes(np.asarray(coeff_rows(r0, r1))[:, :, c], scale, bias)[::-1].tobytes())
    return {"scale": [float(s) for s in scale], "bias": [int(b) for b in bias]}


def ptm_weights(light):
    """[lu², lv², lu·lv, lu, lv, 1] of a light (..., 3) or (..., 2): lu, lv its x (right) and
    y (up) components, the document's §1.0 order. Returns (..., 6)."""
    d = np.asarray(light, dtype=np.float64)
    u, v = d[..., 0], d[..., 1]
    return np.stack([u * u, v * v, u * v, u, v, np.ones_like(u)], axis=-1)


@dataclass
class PTMFile:
    """A PTM LRGB as the readers hold it: image row 0 at the top of the picture.

    coeffs (H, W, 6) float64, (byte - bias) · scale (byte units: 255 = full brightness);
    rgb (H, W, 3) uint8; scale (6,), bias (6,) as in the header; format the header's format line.
    A PTM_FORMAT_RGB: coeffs (H, W, 3, 6), a polynomial per channel, and rgb None.
    """
    width: int
    height: int
    format: str
    scale: np.ndarray
    bias: np.ndarray
    coeffs: np.ndarray
    rgb: np.ndarray

    def values(self, light, rtiviewer=False):
        """A PTM_FORMAT_RGB's polynomial per channel (H, W, 3) in byte units at a light (3,) or
        (H, W, 3); rtiviewer=True: each coefficient truncated to an integer first."""
        a = np.trunc(self.coeffs) if rtiviewer else self.coeffs
        b = ptm_weights(light)
        return a @ b if b.ndim == 1 else np.einsum("hwct,hwt->hwc", a, b)

    def luminance(self, light, rtiviewer=False):
        """L (H, W) in byte units at a light direction (3,) (x right, y up, z to the camera)
        or per-pixel directions (H, W, 3).
        rtiviewer=True truncates each coefficient to an integer first, as RTIViewer stores them."""
        a = np.trunc(self.coeffs) if rtiviewer else self.coeffs
        b = ptm_weights(light)
        return a @ b if b.ndim == 1 else np.einsum("hwt,hwt->hw", a, b)

    def relight(self, light, rtiviewer=False):
        """The picture (H, W, 3) as displayed, in [0, 1]: L · RGB / 255 / 255, L clipped to
        >= 0 and the result to 1 (the viewers' byte conversion); an RGB file's polynomials / 255."""
        if self.rgb is None:
            return np.clip(self.values(light, rtiviewer) / FULL, 0.0, 1.0)
        lum = np.maximum(self.luminance(light, rtiviewer), 0.0)
        return np.minimum(lum[..., None] * self.rgb / (FULL * 255.0), 1.0)


def _lines(data, pos, n):
    """n header lines (ASCII, LF or CRLF) from pos -> (list of str, position after them)."""
    out = []
    for _ in range(n):
        end = data.find(b"\n", pos)
        if end < 0:
            raise BadInputError("PTM header ends early")
        out.append(data[pos:end].decode("ascii", "replace").strip())
        pos = end + 1
    return out, pos


def _ints(line, n, what, path):
    try:
        vals = [int(t) for t in line.split()]
    except ValueError:
        vals = []
    if len(vals) != n:
        raise BadInputError(f"{path}: the PTM header's {what} line is not {n} integers: {line!r}")
    return vals


def read_ptm(path):
    """Read a PTM_FORMAT_LRGB, PTM_FORMAT_RGB or PTM_FORMAT_JPEG_LRGB file (PTM 1.2) -> `PTMFile`.

    Raises BadInputError for other formats (RGB, LUM, JPEG-LS) and for side information or
    motion compensation in a JPEG file (HP's encoder options that no sample we have uses)."""
    path = Path(path)
    data = path.read_bytes()
    (version, fmt), pos = _lines(data, 0, 2)
    if not version.startswith("PTM_1."):
        raise BadInputError(f"{path} is not a PTM file (first line {version!r})")
    if fmt not in ("PTM_FORMAT_LRGB", "PTM_FORMAT_JPEG_LRGB", "PTM_FORMAT_RGB"):
        raise BadInputError(f"{path}: {fmt} is not read (PTM_FORMAT_RGB, _LRGB and _JPEG_LRGB are)")
    # width and height: one line each (what RTIViewer reads) or both on one line (§2.3)
    (first,), pos = _lines(data, pos, 1)
    if len(first.split()) == 2:
        w, h = (int(t) for t in first.split())
    else:
        (second,), pos = _lines(data, pos, 1)
        w, h = int(first), int(second)
    (scale_line, bias_line), pos = _lines(data, pos, 2)
    scale = np.array([float(t) for t in scale_line.split()])
    bias = np.array(_ints(bias_line, 6, "bias", path), float)
    if scale.size != 6:
        raise BadInputError(f"{path}: the PTM header's scale line is not 6 numbers: {scale_line!r}")
    n = w * h
    if fmt == "PTM_FORMAT_RGB":        # red's a0..a5 of every pixel, then green's, then blue's
        body = np.frombuffer(data, np.uint8, offset=pos)
        if body.size < 18 * n:
            raise BadInputError(f"{path}: {body.size} data bytes for {w}x{h} pixels ({18 * n} expected)")
        raw = body[:18 * n].reshape(3, h, w, 6)[:, ::-1].transpose(1, 2, 0, 3)     # bottom row first
        return PTMFile(w, h, fmt, scale, bias.astype(int), (raw.astype(np.float64) - bias) * scale, None)
    if fmt == "PTM_FORMAT_LRGB":
        body = np.frombuffer(data, np.uint8, offset=pos)
        if body.size < 9 * n:
            raise BadInputError(f"{path}: {body.size} data bytes for {w}x{h} pixels ({9 * n} expected)")
        if version == "PTM_1.2":       # a0..a5 of every pixel, then R, G, B of every pixel
            planes = body[:6 * n].reshape(h, w, 6), body[6 * n:9 * n].reshape(h, w, 3)
        else:                          # PTM 1.1: a0..a5 R G B interleaved
            px = body[:9 * n].reshape(h, w, 9)
            planes = px[..., :6], px[..., 6:]
        raw, rgb = planes[0][::-1], planes[1][::-1]                # bottom row first
    else:
        raw, rgb = _jpeg_planes(data, pos, w, h, path)
    coeffs = (raw.astype(np.float64) - bias) * scale
    return PTMFile(w, h, fmt, scale, bias.astype(int), coeffs, np.ascontiguousarray(rgb, np.uint8))


def _jpeg_planes(data, pos, w, h, path):
    """PTM_FORMAT_JPEG_LRGB (§2.7): compression parameter, then nine values per line for the
    transforms, motion x, motion y, order, reference planes, compressed sizes, side information
    sizes; then each plane's JPEG stream and side information. Planes are a0..a5, R, G, B;
    a plane with a reference r is stored as (plane - ref + 128) mod 256 (transform 1: against
    255 - ref), decoded in `order`. Each JPEG's top row is the picture's bottom row.
    Returns (coefficient bytes (H, W, 6), rgb (H, W, 3)) with row 0 at the top."""
    from PIL import Image        # the JPEG decoder (Pillow, a dependency), loaded only here

    lines, pos = _lines(data, pos, 8)
    xform, mx, my, order, ref, sizes, side = (_ints(l, 9, what, path) for l, what in zip(
        lines[1:], ("transform", "motion x", "motion y", "order", "reference", "size", "side info")))
    if any(mx) or any(my):
        raise BadInputError(f"{path}: motion-compensated JPEG PTM planes are not read")
    if any(side):
        raise BadInputError(f"{path}: JPEG PTM side information (corrected pixels) is not read")
    starts = np.concatenate([[pos], pos + np.cumsum(np.add(sizes, side))])
    if starts[-1] > len(data):
        raise BadInputError(f"{path}: the file is shorter than its JPEG planes ({starts[-1]} bytes)")
    stored = []
    for k in range(9):
        img = Image.open(_io.BytesIO(data[starts[k]:starts[k] + sizes[k]]))
        a = np.asarray(img.convert("L"))
        if a.shape != (h, w):
            raise BadInputError(f"{path}: JPEG plane {k} is {a.shape[1]}x{a.shape[0]}, not {w}x{h}")
        stored.append(a.astype(np.int32))
    planes = [None] * 9
    for step in range(9):
        k = order.index(step)
        p = stored[k]
        if ref[k] >= 0:
            base = planes[ref[k]]
            if base is None:
                raise BadInputError(f"{path}: JPEG plane {k} refers to plane {ref[k]}, not decoded before it")
            base = 255 - base if xform[k] == 1 else base
            p = (p + base - 128) % 256
        planes[k] = p
    cube = np.stack(planes, axis=-1)[::-1].astype(np.uint8)        # JPEG row 0 = bottom
    return cube[..., :6], cube[..., 6:]
