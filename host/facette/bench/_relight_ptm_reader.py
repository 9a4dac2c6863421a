"""A PTM reader written from RTIViewer's loaders (RTIViewer 1.1, src/rgbptm.cpp, ISTI-CNR and Cultural
Heritage Imaging: `RGBPtm::loadData`, `LRGBPtm::loadData`, `createPreview`), not from facette's writer
(`io.ptm`): the check that relight.ptm is shown as fitted must not share the writer's mistakes.

Its rules, as that code has them:
- header lines: the version (PTM_1.2), the format, the width, the height (one line each; `getLine`),
  six scales (doubles), then as many biases (ints) as the basis has terms (6);
- PTM_FORMAT_RGB: for each channel j = red, green, blue in turn, for y = h-1 down to 0, for x = 0..w-1:
  six bytes c, kept as `static_cast<int>((c - bias[i]) * scale[i])` (truncated towards zero);
- PTM_FORMAT_LRGB (1.2): first the six coefficient bytes of every pixel (y = h-1 .. 0), then the
  three colour bytes of every pixel in the same order;
- shown: `evalPoly(a, lx, ly)` = a0 lx² + a1 ly² + a2 lx ly + a3 lx + a4 ly + a5 with (lx, ly) the
  light's x and y; RGB: each channel's polynomial through `tobyte` (0..255); LRGB: `tobyte(rgb ·
  lum / 255)`, lum the luminance polynomial. Here before the byte (floats in [0, 255], as the bench
  rounds every reader's picture itself).
"""
import numpy as np

__all__ = ["read_ptm_as_rtiviewer", "parse_ptm"]

FORMATS = ("PTM_FORMAT_RGB", "PTM_FORMAT_LRGB")


def _line(data, pos):
    end = data.index(b"\n", pos)
    return data[pos:end].decode("ascii").strip(), end + 1


def parse_ptm(path):
    """A PTM_FORMAT_RGB or PTM_FORMAT_LRGB file by the rules above: dict(format, width, height, scale (6,),
    bias (6,), coeffs (H, W, 6) (LRGB: the luminance) or (H, W, 3, 6) (RGB: red, green, blue), floats
    (byte - bias) · scale before RTIViewer's truncation, rgb (H, W, 3) uint8 (LRGB) or None), row 0 the
    picture's top. ValueError for another format, a header short of its scales or biases, or a body
    that is not the size the header says."""
    with open(path, "rb") as fh:
        data = fh.read()
    pos = 0
    version, pos = _line(data, pos)
    fmt, pos = _line(data, pos)
    if version != "PTM_1.2" or fmt not in FORMATS:
        raise ValueError(f"{path}: {version} {fmt} is not read here")
    width, pos = _line(data, pos)
    height, pos = _line(data, pos)
    w, h = int(width), int(height)
    scales, pos = _line(data, pos)
    biases, pos = _line(data, pos)
    scale = np.array([float(t) for t in scales.split()])
    bias = np.array([int(t) for t in biases.split()])
    if len(scale) != 6 or len(bias) != 6:
        raise ValueError(f"{path}: {len(scale)} scales, {len(bias)} biases (6 each)")
    body = np.frombuffer(data, np.uint8, offset=pos)
    n = w * h
    if body.size != n * (18 if fmt == "PTM_FORMAT_RGB" else 9):
        raise ValueError(f"{path}: {body.size} data bytes for {w}x{h} texels of {fmt}")

    def coefficients(block):          # (h, w, 6) bytes in the file's row order -> floats, top row first
        return ((block.reshape(h, w, 6).astype(np.float64) - bias) * scale)[::-1]

    if fmt == "PTM_FORMAT_RGB":
        coeffs = np.stack([coefficients(body[j * 6 * n:(j + 1) * 6 * n]) for j in range(3)], axis=2)
        colour = None
    else:
        coeffs = coefficients(body[:6 * n])
        colour = body[6 * n:9 * n].reshape(h, w, 3)[::-1]
    return dict(format=fmt, width=w, height=h, scale=scale, bias=bias, coeffs=coeffs, rgb=colour)


def read_ptm_as_rtiviewer(path):
    """relight(lx, ly) -> (H, W, 3) in [0, 255] (row 0 = top of the picture) of a PTM_FORMAT_RGB or
    PTM_FORMAT_LRGB file (`parse_ptm`), and its format line."""
    ptm = parse_ptm(path)
    ints = np.trunc(ptm["coeffs"])                     # static_cast<int>
    channels = [ints[..., j, :] for j in range(3)] if ptm["rgb"] is None else [ints]
    colour = None if ptm["rgb"] is None else ptm["rgb"].astype(np.float64)

    def relight(lx, ly):
        terms = np.array([lx * lx, ly * ly, lx * ly, lx, ly, 1.0])
        if colour is None:
            return np.stack([np.clip(a @ terms, 0.0, 255.0) for a in channels], axis=-1)
        lum = channels[0] @ terms
        return np.clip(colour * lum[..., None] / 255.0, 0.0, 255.0)

    return relight, ptm["format"]
