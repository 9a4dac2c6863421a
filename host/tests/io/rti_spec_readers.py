"""Readers of PTM and HSH .rti files written from the formats' published definitions, not
from facette's writers: the HP Labs "Polynomial Texture Map (.ptm) File Format" v1.2 (2001)
and RTIViewer's HSH file layout and basis (the one RTIViewer and Relight evaluate)."""
import struct
from pathlib import Path

import numpy as np


def _header_tokens(data, pos, count):
    """`count` whitespace-separated ASCII tokens from pos, ending at a line end; returns
    (tokens, position of the first binary byte)."""
    tokens = []
    while len(tokens) < count:
        end = data.index(b"\n", pos)
        tokens.extend(data[pos:end].split())
        pos = end + 1
    assert len(tokens) == count, f"header line carries extra tokens: {tokens}"
    return tokens, pos


def read_ptm(path):
    """PTM_1.2 / PTM_FORMAT_LRGB -> dict(width, height, scale, bias, coeffs (H, W, 6) float,
    rgb (H, W, 3) uint8) with image row 0 at the top."""
    data = Path(path).read_bytes()
    first = data.index(b"\n")
    second = data.index(b"\n", first + 1)
    assert data[:first].strip() == b"PTM_1.2"
    assert data[first + 1:second].strip() == b"PTM_FORMAT_LRGB"
    # §2.3-2.5: width and height (one line or two), 6 scale floats, 6 bias integers
    tok, pos = _header_tokens(data, second + 1, 14)
    w, h = int(tok[0]), int(tok[1])
    scale = np.array([float(t) for t in tok[2:8]])
    bias = np.array([int(t) for t in tok[8:14]])
    n = w * h
    body = np.frombuffer(data, np.uint8, offset=pos)
    assert body.size == n * 9, f"{body.size} data bytes for {w}x{h} pixels (expected {n * 9})"
    # §2.6 LRGB: a0..a5 of every texel, then R, G, B of every texel, bottom row first
    raw = body[:n * 6].reshape(h, w, 6)[::-1]
    rgb = body[n * 6:].reshape(h, w, 3)[::-1]
    coeffs = (raw.astype(np.float64) - bias) * scale
    return dict(width=w, height=h, scale=scale, bias=bias, coeffs=coeffs, rgb=rgb)


def ptm_luminance(coeffs, lu, lv):
    """C = a0 Lu² + a1 Lv² + a2 Lu Lv + a3 Lu + a4 Lv + a5 (the document's §1.0)."""
    a = coeffs
    return (a[..., 0] * lu * lu + a[..., 1] * lv * lv + a[..., 2] * lu * lv + a[..., 3] * lu
            + a[..., 4] * lv + a[..., 5])


def ptm_colour(ptm, light):
    """RTIViewer's LRGB rendering: L clipped to >= 0 times the stored colour / 255."""
    lum = np.maximum(ptm_luminance(ptm["coeffs"], light[0], light[1]), 0.0)
    return lum[..., None] * ptm["rgb"] / 255.0


def read_hsh(path):
    """#HSH1.2 .rti -> dict(width, height, terms, scale, bias, coeffs (H, W, 3, terms))."""
    data = Path(path).read_bytes()
    pos = 0
    while data[pos:pos + 1] == b"#":                 # comment lines
        pos = data.index(b"\n", pos) + 1
    tok, pos = _header_tokens(data, pos, 1)
    assert int(tok[0]) == 3, "file type 3 is HSH"
    tok, pos = _header_tokens(data, pos, 3)
    w, h, bands = map(int, tok)
    assert bands == 3
    tok, pos = _header_tokens(data, pos, 3)
    terms, basis_type, element_size = map(int, tok)
    assert element_size == 1
    scale = np.array(struct.unpack(f"<{terms}f", data[pos:pos + 4 * terms]))
    bias = np.array(struct.unpack(f"<{terms}f", data[pos + 4 * terms:pos + 8 * terms]))
    body = np.frombuffer(data, np.uint8, offset=pos + 8 * terms)
    assert body.size == w * h * 3 * terms
    q = body.reshape(h, w, 3, terms)[::-1]           # bottom row first; per pixel R, G, B blocks
    return dict(width=w, height=h, terms=terms, basis_type=basis_type, scale=scale, bias=bias,
                coeffs=q / 255.0 * scale + bias)


def hsh_weights(light, terms):
    """RTIViewer's hemispherical-harmonics weights at a light direction (x, y, z)."""
    phi = np.arctan2(light[1], light[0])
    ct = np.cos(np.arccos(np.clip(light[2], -1, 1)))
    ct2 = ct * ct
    s = np.sqrt(max(ct - ct2, 0.0))
    w = [1 / np.sqrt(2 * np.pi),
         np.sqrt(6 / np.pi) * np.cos(phi) * s,
         np.sqrt(3 / (2 * np.pi)) * (-1 + 2 * ct),
         np.sqrt(6 / np.pi) * s * np.sin(phi),
         np.sqrt(30 / np.pi) * np.cos(2 * phi) * (-ct + ct2),
         np.sqrt(30 / np.pi) * np.cos(phi) * (-1 + 2 * ct) * s,
         np.sqrt(5 / (2 * np.pi)) * (1 - 6 * ct + 6 * ct2),
         np.sqrt(30 / np.pi) * (-1 + 2 * ct) * s * np.sin(phi),
         np.sqrt(30 / np.pi) * (-ct + ct2) * np.sin(2 * phi)]
    return np.array(w[:terms])


def hsh_colour(rti, light):
    """Σ_k coeff_k · H_k(light) per channel, clipped to >= 0."""
    return np.maximum(rti["coeffs"] @ hsh_weights(light, rti["terms"]), 0.0)
