"""PNG reading and writing, including 16-bit colour (which Pillow reduces to 8 bits).

`read_png` returns the stored integers (uint8 or uint16), shape (H, W) or (H, W, C);
16-bit RGB/RGBA files are decoded here (zlib + the five PNG filters, vectorised along
anti-diagonals), everything else through Pillow. `write_png` writes uint8 or uint16 grey,
RGB or RGBA, unfiltered.
"""
import struct
import zlib
from pathlib import Path

import numpy as np
from PIL import Image

__all__ = ["read_png", "write_png", "read_mask", "write_mask"]

_SIG = b"\x89PNG\r\n\x1a\n"
_CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}   # colour type -> samples per pixel (no palette here)


def _chunks(data):
    pos = 8
    while pos + 8 <= len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        yield kind, data[pos + 8:pos + 8 + n]
        pos += 12 + n


def _unfilter(raw, h, row_bytes, bpp):
    """Undo PNG filtering. raw: bytes of h rows of (1 + row_bytes). Returns (h, row_bytes) uint8."""
    buf = np.frombuffer(raw, np.uint8)
    if buf.size < h * (row_bytes + 1):
        raise ValueError("truncated PNG image data")
    buf = buf[:h * (row_bytes + 1)].reshape(h, row_bytes + 1)
    ftype = buf[:, 0].astype(np.int16)
    if np.any(ftype > 4):
        raise ValueError("corrupt PNG: unknown filter type")
    w = row_bytes // bpp
    x = buf[:, 1:].reshape(h, w, bpp).astype(np.int16)
    out = np.zeros((h + 1, w + 1, bpp), np.int16)       # one row/column of zero padding
    # pixel (r, c) needs (r, c-1), (r-1, c), (r-1, c-1): every anti-diagonal depends only on
    # the previous ones, so each is decoded as one vector operation
    for t in range(h + w - 1):
        r = np.arange(max(0, t - w + 1), min(h, t + 1))
        c = t - r
        a = out[r + 1, c]
        b = out[r, c + 1]
        cc = out[r, c]
        f = ftype[r][:, None]
        p = a + b - cc
        pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - cc)
        paeth = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, cc))
        pred = np.select([f == 1, f == 2, f == 3, f == 4], [a, b, (a + b) // 2, paeth], 0)
        out[r + 1, c + 1] = (x[r, c] + pred) & 255
    return out[1:, 1:].reshape(h, row_bytes).astype(np.uint8)


def read_png(path):
    """Read a PNG as stored integers: uint8 or uint16, (H, W) grey or (H, W, C)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no PNG file at {path}")
    data = path.read_bytes()
    if data[:8] != _SIG:
        raise ValueError(f"{path} is not a PNG file")
    ihdr = None
    idat = []
    for kind, body in _chunks(data):
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body[:13])
        elif kind == b"IDAT":
            idat.append(body)
    if ihdr is None:
        raise ValueError(f"{path}: PNG without IHDR")
    w, h, depth, ctype, _, _, interlace = ihdr
    if depth == 16 and ctype in (2, 6):
        if interlace:
            raise ValueError(f"{path}: interlaced 16-bit colour PNG is not supported; re-save it "
                             "without interlacing")
        ch = _CHANNELS[ctype]
        bpp = 2 * ch
        rows = _unfilter(zlib.decompress(b"".join(idat)), h, w * bpp, bpp)
        return rows.view(">u2").reshape(h, w, ch).astype(np.uint16)
    with Image.open(path) as im:
        arr = np.asarray(im)
    if arr.dtype == np.int32 or arr.dtype == np.int64:   # Pillow's "I" modes
        arr = arr.astype(np.uint16)
    return arr


def write_png(path, image):
    """Write uint8 or uint16 (H, W), (H, W, 3) or (H, W, 4) as PNG (bool is written 0/255)."""
    image = np.asarray(image)
    if image.dtype == bool:
        image = image.astype(np.uint8) * 255
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_png takes uint8 or uint16 images, got {image.dtype}; scale and "
                         "convert first")
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4) or 0 in image.shape:
        raise ValueError(f"write_png expects (H, W) or (H, W, 1-4), got {image.shape}")
    h, w, ch = image.shape
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[ch]
    depth = 16 if image.dtype == np.uint16 else 8
    rows = image.astype(">u2" if depth == 16 else np.uint8).reshape(h, -1).view(np.uint8)
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rows], axis=1).tobytes()

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    data = (_SIG + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, ctype, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_bytes(data)
    tmp.replace(path)


def read_mask(path):
    """A mask PNG as (H, W) bool: any channel non-zero."""
    arr = read_png(path)
    return arr.any(axis=-1) if arr.ndim == 3 else arr > 0


def write_mask(path, mask):
    """Write an (H, W) bool mask as an 8-bit grey PNG (0 / 255)."""
    write_png(path, np.asarray(mask, bool))
