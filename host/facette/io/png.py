"""PNG reading and writing through OpenCV (libpng), 8 and 16 bits per sample.

Pillow cannot be used for 16-bit colour: it reduces 16-bit RGB to 8 bits. OpenCV keeps the
stored integers but orders colour channels BGR(A); this module turns them into RGB(A).
`read_png` returns uint8 or uint16, shape (H, W) grey or (H, W, 3|4) colour (palette images
are expanded to RGB). `write_png` takes uint8 or uint16 grey, RGB or RGBA.
"""
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from facette.io.atomic import write_bytes_atomic

__all__ = ["read_png", "read_png_text", "png_size", "write_png", "encode_png", "read_mask", "write_mask",
           "PngBandWriter"]

_SIG = b"\x89PNG\r\n\x1a\n"
_TO_RGB = {3: cv2.COLOR_BGR2RGB, 4: cv2.COLOR_BGRA2RGBA}
_FROM_RGB = {3: cv2.COLOR_RGB2BGR, 4: cv2.COLOR_RGBA2BGRA}


def read_png(path):
    """Read a PNG as stored integers: uint8 or uint16, (H, W) grey or (H, W, 3|4) RGB(A)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no PNG file at {path}")
    with open(path, "rb") as fh:              # the signature first: OpenCV reports no reason on failure
        if fh.read(8) != _SIG:
            raise ValueError(f"{path} is not a PNG file")
    # decoded from the file, the channels swapped in place: the image's bytes alone at the peak (a
    # 16-bit RGB photograph 6 bytes per pixel; with its file's bytes and an RGB copy beside it, 17.3)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: the PNG data is corrupt or truncated; re-export the image")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3:
        cv2.cvtColor(img, _TO_RGB[img.shape[2]], dst=img)
    return img


def png_size(path):
    """(width, height) of a PNG from its header, without decoding it."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != _SIG or head[12:16] != b"IHDR":
        raise ValueError(f"{path} is not a PNG file")
    return struct.unpack(">II", head[16:24])


def _chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _text_chunks(text):
    """tEXt chunks (PNG 1.2 §11.3.4.3) of {keyword: Latin-1 text}."""
    out = b""
    for key, value in (text or {}).items():
        out += _chunk(b"tEXt", str(key).encode("latin-1")[:79] + b"\0" + str(value).encode("latin-1", "replace"))
    return out


def read_png_text(path):
    """{keyword: text} of a PNG's tEXt chunks."""
    data = Path(path).read_bytes()
    out, at = {}, 8
    while at + 8 <= len(data):
        n, kind = struct.unpack(">I4s", data[at:at + 8])
        if kind == b"tEXt":
            key, _, value = data[at + 8:at + 8 + n].partition(b"\0")
            out[key.decode("latin-1")] = value.decode("latin-1")
        if kind == b"IEND":
            break
        at += 12 + n
    return out


def encode_png(image, compression=6, text=None):
    """PNG bytes of uint8 or uint16 (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) (bool: 0/255).
    compression : zlib level 0-9. text : {keyword: text} stored as tEXt chunks (what a
    viewer's file properties show, e.g. that the scan was incomplete)."""
    image = np.asarray(image)
    if image.dtype == bool:
        image = image.astype(np.uint8) * 255
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_png takes uint8 or uint16 images, got {image.dtype}; scale and "
                         "convert first")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (3, 4))) or 0 in image.shape:
        raise ValueError(f"write_png expects (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got "
                         f"{image.shape}")
    if image.ndim == 3:
        image = cv2.cvtColor(np.ascontiguousarray(image), _FROM_RGB[image.shape[2]])
    ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, int(compression)])
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} {image.dtype} image as PNG")
    data = buf.tobytes()
    if text:
        ihdr_end = 8 + 8 + 13 + 4                      # signature, IHDR (length, type, 13 bytes, CRC)
        data = data[:ihdr_end] + _text_chunks(text) + data[ihdr_end:]
    return data


def write_png(path, image, text=None):
    """Write uint8 or uint16 (H, W), (H, W, 3) or (H, W, 4) as PNG (bool is written 0/255);
    the file appears complete or not at all. text : {keyword: text} tEXt chunks."""
    write_bytes_atomic(path, encode_png(image, text=text))


def read_mask(path):
    """A mask PNG as (H, W) bool: any channel non-zero."""
    arr = read_png(path)
    return arr.any(axis=-1) if arr.ndim == 3 else arr > 0


def write_mask(path, mask, text=None, grey=None, grey_level=128):
    """Write an (H, W) bool mask as an 8-bit grey PNG (0 / 255); text as `write_png`. grey : an
    optional (H, W) bool map of the mask's pixels written `grey_level` instead of 255 (`read_mask`
    reads them as inside)."""
    mask = np.asarray(mask, bool)
    if grey is None:
        write_png(path, mask, text)
        return
    out = mask.astype(np.uint8) * np.uint8(255)
    out[mask & np.asarray(grey, bool)] = grey_level
    write_png(path, out, text)


class PngBandWriter:
    """A PNG written band of rows by band of rows, so that the whole image is never held
    (OpenCV encodes whole images only). Rows are stored unfiltered (filter type 0), zlib at
    `compression`; any PNG reader (OpenCV included) reads the file.

    path : the file; it appears complete at `close()` (written to `path.partial` until then).
    width, height : pixels; channels : 1 (grey) or 3 (RGB); dtype : uint8 or uint16.
    Use as a context manager, `write(band)` with bands of shape (rows, width[, channels]) from
    the top, `height` rows in all."""

    def __init__(self, path, width, height, channels=3, dtype=np.uint16, compression=1):
        dtype = np.dtype(dtype)
        if dtype not in (np.uint8, np.uint16) or channels not in (1, 3):
            raise ValueError(f"PngBandWriter writes uint8 or uint16 grey or RGB, got {dtype} with "
                             f"{channels} channels")
        if not (int(width) > 0 and int(height) > 0):
            raise ValueError(f"width and height must be > 0 px, got {width}x{height}")
        self.path, self.width, self.height = Path(path), int(width), int(height)
        self.channels, self.dtype, self.rows = channels, dtype, 0
        self._tmp = self.path.with_name(self.path.name + ".partial")
        self._f = open(self._tmp, "wb")
        self._z = zlib.compressobj(int(compression))
        colour = 0 if channels == 1 else 2
        self._f.write(_SIG + _chunk(b"IHDR", struct.pack(">IIBBBBB", self.width, self.height,
                                                          8 * dtype.itemsize, colour, 0, 0, 0)))

    def write(self, band):
        """Append rows: (rows, width) or (rows, width, channels) of the writer's dtype."""
        band = np.asarray(band)
        shape = (self.width,) if self.channels == 1 else (self.width, self.channels)
        if band.dtype != self.dtype or band.shape[1:] != shape:
            raise ValueError(f"{self.path.name}: a band must be (rows, {', '.join(map(str, shape))}) "
                             f"{self.dtype}, got {band.shape} {band.dtype}")
        if self.rows + band.shape[0] > self.height:
            raise ValueError(f"{self.path.name}: {self.rows + band.shape[0]} rows written, the image "
                             f"has {self.height}")
        rows = band.reshape(band.shape[0], -1).astype(self.dtype.newbyteorder(">"), copy=False)
        raw = np.zeros((band.shape[0], 1 + rows.shape[1] * self.dtype.itemsize), np.uint8)
        raw[:, 1:] = rows.view(np.uint8).reshape(band.shape[0], -1)
        data = self._z.compress(raw.tobytes())
        if data:
            self._f.write(_chunk(b"IDAT", data))
        self.rows += band.shape[0]

    def close(self):
        if self._f.closed:
            return
        if self.rows != self.height:
            self._f.close()
            self._tmp.unlink()
            raise ValueError(f"{self.path.name}: {self.rows} rows written of {self.height}; "
                             "the file was not kept")
        self._f.write(_chunk(b"IDAT", self._z.flush()) + _chunk(b"IEND", b""))
        self._f.close()
        self._tmp.replace(self.path)

    def __enter__(self):
        return self

    def __exit__(self, kind, value, tb):
        if kind is None:
            self.close()
        elif not self._f.closed:
            self._f.close()
            self._tmp.unlink()
