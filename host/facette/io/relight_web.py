"""Relight's web format (CNR-ISTI's Relight writes it, openlime and Relight's web viewer read it),
written and read as openlime's LayerRTI and ShaderRTI read it.

A folder holds `info.json` (width, height, "format": "jpg", "type": "hsh" or "ptm", "colorspace":
"rgb", the lights as a flat list of x y z, "nplanes", "quality", and "materials": [{"scale",
"bias"}] with one number per plane) and the coefficient planes, three to a JPEG: plane p = 3 j + c
is channel c (R, G, B) of `plane_j`, the coefficient of basis term j for colour c. A plane's byte
b stands for the coefficient (b / 255 - bias[p]) · scale[p]. The relit colour is
Σ_j coeff_j,c · w_j(light), w the basis: HSH in RTIViewer's order (`io.rti.hsh_weights`), with
openlime's clamp of the light to at least 0.15 rad above the horizon (and its π = 3.1415); PTM
[1, x, y, x², xy, y²] (not the .ptm file's order). The values are those of the photographs
(display values: openlime's shader takes them as sRGB).

The planes are `plane_j.jpg` (layout "image") or deep-zoom pyramids `plane_j.dzi` + `plane_j_files/L/
col_row.jpg` (layout "deepzoom", as Relight writes them: tiles of 256 pixels without overlap, level 0
the whole picture in one tile, each level twice the previous, the last at full size). Rows top first.
`write_relight_web` takes the coefficients band by band and writes the pyramid tile row by tile row
(memory: a few tile rows of bytes, whatever the image's size).
"""
import json
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facette.errors import BadInputError
from facette.io.rti import hsh_terms

__all__ = ["write_relight_web", "read_relight_web", "RelightWeb", "openlime_weights", "TILE", "IMAGE_MAX"]

TILE = 256                 # deep-zoom tile size (Relight's)
QUALITY = 95               # JPEG quality of the planes (Relight's default)
IMAGE_MAX = 2048           # pictures up to this size on their long side: plain plane_j.jpg, else deep zoom
ROWS = 64                  # image rows quantised at a time
HSH_MIN_ELEVATION = 0.15   # openlime's HSH: lights lower than this (rad above the horizon) are taken at it
OPENLIME_PI = 3.1415       # openlime's HSH uses this value of π
# facette's PTM coefficient order ([x², y², xy, x, y, 1], the .ptm file's) -> openlime's [1, x, y, x², xy, y²]
PTM_TO_WEB = (5, 3, 4, 0, 2, 1)


def openlime_weights(kind, light, terms=9):
    """The basis weights (..., terms) openlime's shader gives a light (..., 3) (x right, y up, z to
    the camera): "hsh" (HSH.lightWeights, its clamp and π) or "ptm" (PTM.lightWeights)."""
    d = np.asarray(light, dtype=np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    if kind == "ptm":
        return np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    if kind != "hsh":
        raise ValueError(f"kind must be 'hsh' or 'ptm', got {kind!r}")
    pi = OPENLIME_PI
    phi = np.arctan2(y, x)
    phi = np.where(phi < 0, 2 * pi + phi, phi)
    theta = np.minimum(np.arccos(np.clip(z, -1, 1)), pi / 2 - HSH_MIN_ELEVATION)
    return hsh_terms(phi, np.cos(theta), terms, pi)


def _jpeg(path, rgb, quality):
    from PIL import Image         # Pillow, a dependency, loaded only here
    # 4:4:4: each channel is a coefficient of its own, chroma subsampling would blur them into each other
    Image.fromarray(np.ascontiguousarray(rgb)).save(path, quality=quality, subsampling=0)


def _half(x):
    """(J, rows, W, 3) uint8 -> (J, ceil(rows / 2), ceil(W / 2), 3): the mean of each 2x2 block (of
    the pixels there are at an odd edge), rounded."""
    r, w = x.shape[1:3]
    x = x.astype(np.uint16)
    if r % 2:
        x = np.concatenate([x, x[:, -1:]], axis=1)
    if w % 2:
        x = np.concatenate([x, x[:, :, -1:]], axis=2)
    s = x[:, 0::2, 0::2] + x[:, 1::2, 0::2] + x[:, 0::2, 1::2] + x[:, 1::2, 1::2]
    return ((s + 2) // 4).astype(np.uint8)


class _Pyramid:
    """Deep-zoom tiles of `jpegs` planes (3 channels each) of a w x h picture, fed top rows first at
    the full-size level (`add`: (jpegs, rows, w, 3) uint8); each level's tile rows written as soon
    as they are complete, the rows halved into the level above it as they come."""

    def __init__(self, folder, jpegs, w, h, quality):
        self.levels = max(1, int(np.ceil(np.log2(max(w, h) / TILE))) + 1) if max(w, h) > TILE else 1
        self.folder, self.jpegs, self.quality = folder, jpegs, quality
        self.buf = [None] * self.levels
        self.carry = [None] * self.levels
        self.tile_row = [0] * self.levels
        for j in range(jpegs):
            for lv in range(self.levels):
                (folder / f"plane_{j}_files" / str(lv)).mkdir(parents=True, exist_ok=True)

    def add(self, rows, last=False):
        self._push(self.levels - 1, rows, last)

    def _push(self, lv, rows, last):
        buf = rows if self.buf[lv] is None else np.concatenate([self.buf[lv], rows], axis=1)
        while buf.shape[1] >= TILE or (last and buf.shape[1]):
            self._tiles(lv, self.tile_row[lv], buf[:, :TILE])
            self.tile_row[lv] += 1
            buf = buf[:, TILE:]
        self.buf[lv] = buf
        if lv == 0:
            return
        src = rows if self.carry[lv] is None else np.concatenate([self.carry[lv], rows], axis=1)
        even = src.shape[1] // 2 * 2
        down = _half(src[:, :even]) if even else src[:, :0, ::2]
        rest = src[:, even:]
        if last and rest.shape[1]:
            down, rest = np.concatenate([down, _half(rest)], axis=1), rest[:, :0]
        self.carry[lv] = rest if rest.shape[1] else None
        if down.shape[1] or last:
            self._push(lv - 1, down, last)

    def _tiles(self, lv, row, band):
        for j in range(self.jpegs):
            for col, c0 in enumerate(range(0, band.shape[2], TILE)):
                _jpeg(self.folder / f"plane_{j}_files" / str(lv) / f"{col}_{row}.jpg",
                      band[j, :, c0:c0 + TILE], self.quality)


def write_relight_web(folder, width, height, kind, coeff_rows, coeff_range, lights, layout="auto",
                      pixel_size_mm=None, quality=QUALITY):
    """Write Relight's web format into `folder` (replaced whole, never half written).

    kind "hsh" (terms 4 or 9, RTIViewer's order) or "ptm" (6 terms in openlime's order, `PTM_TO_WEB`);
    coeff_rows(r0, r1) -> (r1 - r0, W, 3, T) float, the coefficients of image rows r0..r1 (row 0 =
    top; asked for top band first) in display units (the relit value Σ_t coeff_t w_t(light), 1 = full
    brightness); coeff_range (lo, hi), each (T,) or (3, T): their minimum and maximum over every pixel;
    lights (m, 3) the captured lights (info.json's, for RBF viewers and the record); layout "image",
    "deepzoom" or "auto" (deep zoom above IMAGE_MAX pixels on the long side).
    Returns the info dict written."""
    folder = Path(folder)
    w, h = int(width), int(height)
    lo, hi = (np.asarray(x, np.float64) for x in coeff_range)
    if lo.ndim == 1:                          # one range per term: the same for the three colours
        lo, hi = np.broadcast_to(lo, (3, lo.size)), np.broadcast_to(hi, (3, hi.size))
    terms = lo.shape[1]
    if kind not in ("hsh", "ptm") or (kind == "hsh" and terms not in (4, 9)) or (kind == "ptm" and terms != 6):
        raise ValueError(f"a {kind!r} web file of {terms} terms is not written (hsh: 4 or 9, ptm: 6)")
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("relight web coefficients must be finite (set unfitted pixels to 0)")
    layout = ("deepzoom" if max(w, h) > IMAGE_MAX else "image") if layout == "auto" else layout
    if layout not in ("image", "deepzoom"):
        raise ValueError(f"layout must be 'image', 'deepzoom' or 'auto', got {layout!r}")
    # plane p = 3 t + c: term t, colour c; byte = (coeff / scale + bias) · 255
    lo_p, hi_p = lo.T.reshape(-1), hi.T.reshape(-1)
    scale = np.where(hi_p > lo_p, hi_p - lo_p, 1.0)
    bias = -lo_p / scale
    info = {"width": w, "height": h, "format": "jpg", "type": kind, "colorspace": "rgb",
            "lights": [round(float(v), 6) for v in np.asarray(lights, float).reshape(-1)],
            "nplanes": 3 * terms, "quality": int(quality),
            "materials": [{"scale": [float(f"{v:.6g}") for v in scale], "bias": [float(f"{v:.6g}") for v in bias]}],
            "layout": layout}
    if pixel_size_mm:
        info["pixelSizeInMM"] = float(pixel_size_mm)
    # what the file says, rounded as written: the bytes quantise against these
    scale = np.array(info["materials"][0]["scale"])
    bias = np.array(info["materials"][0]["bias"])
    tmp = folder.with_name(folder.name + ".part")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        pyramid = _Pyramid(tmp, terms, w, h, quality) if layout == "deepzoom" else None
        whole = None if pyramid else np.empty((terms, h, w, 3), np.uint8)
        # byte = coeff · 255 / scale + 255 bias, per (colour, term) as the coefficients come (b, W, 3, T)
        mul = (255.0 / scale).reshape(terms, 3).T.astype(np.float32)
        add = (255.0 * bias).reshape(terms, 3).T.astype(np.float32)
        for r0 in range(0, h, ROWS):
            r1 = min(h, r0 + ROWS)
            x = np.array(coeff_rows(r0, r1), np.float32)                 # (b, W, 3, T), a copy of its own
            x *= mul
            x += add
            np.round(x, out=x)
            q = np.clip(x, 0, 255, out=x).astype(np.uint8).transpose(3, 0, 1, 2)   # (T, b, W, 3): jpeg t
            if pyramid:
                pyramid.add(np.ascontiguousarray(q), last=r1 == h)
            else:
                whole[:, r0:r1] = q
        for j in range(terms):
            if pyramid:
                (tmp / f"plane_{j}.dzi").write_text(
                    '<?xml version="1.0" encoding="UTF-8"?>\n'
                    '<Image xmlns="http://schemas.microsoft.com/deepzoom/2008"\n'
                    f'  Format="jpg"\n  Overlap="0"\n  TileSize="{TILE}"\n  >\n  <Size \n    Height="{h}"\n'
                    f'    Width="{w}"\n  />\n</Image>\n')
            else:
                _jpeg(tmp / f"plane_{j}.jpg", whole[j], quality)
        (tmp / "info.json").write_text(json.dumps(info, indent=1) + "\n")
        if folder.exists():
            shutil.rmtree(folder)
        tmp.rename(folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return info


HINT = "give the relight_web folder `facette process --outputs relight-web` wrote (or one Relight wrote), whole"
BAND_ROWS = 64             # rows relit at a time: work arrays of a band, not of the whole picture


@dataclass
class RelightWeb:
    """A Relight web folder as openlime's shader holds it: info (the json), kind, terms, planes
    (terms, H, W, 3) uint8 as in the JPEGs (row 0 at the top), scale and bias (terms, 3) per plane.
    One byte per coefficient (a 12 MP HSH folder: 0.32 GB, not 2.6 GB of float64); `coeffs` gives
    them dequantised."""
    info: dict
    kind: str
    terms: int
    planes: np.ndarray
    scale: np.ndarray
    bias: np.ndarray

    @property
    def width(self):
        return self.planes.shape[2]

    @property
    def height(self):
        return self.planes.shape[1]

    def _coeffs(self, r0, r1, dtype=np.float64):
        """(terms, r1 - r0, W, 3): (byte / 255 - bias) · scale, as openlime's shader."""
        x = self.planes[:, r0:r1].astype(dtype)
        x *= dtype(1 / 255.0)
        x -= self.bias[:, None, None, :].astype(dtype)
        x *= self.scale[:, None, None, :].astype(dtype)
        return x

    @property
    def coeffs(self):
        """(H, W, 3, terms) float64 dequantised coefficients (the whole picture's: 8 bytes each)."""
        return np.moveaxis(self._coeffs(0, self.height), 0, -1)

    def relight(self, light):
        """The picture (H, W, 3) float32 openlime shows at a light (3,) (x right, y up, z to the camera;
        its x, y as openlime's light control takes them, z from them), clipped to [0, 1]; relit
        BAND_ROWS rows at a time in float32 (the shader's precision; 12 MP: ~0.5 GB with the planes)."""
        d = np.asarray(light, np.float64)
        r = np.hypot(d[0], d[1])
        x, y = (d[0] / r, d[1] / r) if r > 1 else (d[0], d[1])      # openlime: the square onto the disc
        wts = openlime_weights(self.kind, [x, y, np.sqrt(max(0.0, 1 - x * x - y * y))], self.terms)
        wts = wts.astype(np.float32)
        out = np.empty((self.height, self.width, 3), np.float32)
        for r0 in range(0, self.height, BAND_ROWS):
            r1 = min(self.height, r0 + BAND_ROWS)
            np.clip(np.tensordot(wts, self._coeffs(r0, r1, np.float32), axes=1), 0.0, 1.0, out=out[r0:r1])
        return out


def _dzi_size(path):
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInputError(f"{path}: cannot read the deep-zoom descriptor ({exc})", hint=HINT) from None
    get = {k: re.search(rf'{k}="(\d+)"', text) for k in ("Width", "Height", "TileSize", "Overlap")}
    if not all(get.values()):
        raise BadInputError(f"{path}: not a deep-zoom descriptor (Width, Height, TileSize, Overlap)", hint=HINT)
    return {k: int(v.group(1)) for k, v in get.items()}


def _jpeg_rgb(path, what):
    """(h, w, 3) uint8 of one JPEG; a missing, truncated or unreadable one: BadInputError."""
    from PIL import Image
    if not path.is_file():
        raise BadInputError(f"{path}: {what} is missing", hint=HINT)
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("RGB"))
    except (OSError, SyntaxError, ValueError) as exc:       # PIL: truncated, not an image, bad markers
        raise BadInputError(f"{path}: {what} is not a readable JPEG ({exc})",
                            hint="the file is damaged or cut short (an interrupted copy?): copy the folder "
                                 "again, or write it anew with `facette process --outputs relight-web`") from None


def _read_plane(folder, j, w, h):
    """(H, W, 3) uint8 of plane j: plane_j.jpg, or the full-size level of plane_j.dzi's tiles."""
    single = folder / f"plane_{j}.jpg"
    dzi = folder / f"plane_{j}.dzi"
    if single.is_file() or not dzi.is_file():
        if not dzi.is_file() and not single.is_file():
            raise BadInputError(f"{folder}: plane {j} is missing (neither plane_{j}.jpg nor plane_{j}.dzi)", hint=HINT)
        a = _jpeg_rgb(single, f"plane {j}")
    else:
        size = _dzi_size(dzi)
        if size["Overlap"] != 0:
            raise BadInputError(f"{dzi}: tiles with an overlap ({size['Overlap']}) are not read",
                                hint="write the folder with Relight's default overlap 0")
        tiles = folder / f"plane_{j}_files"
        levels = [int(p.name) for p in tiles.iterdir() if p.name.isdigit()] if tiles.is_dir() else []
        if not levels:
            raise BadInputError(f"{tiles}: no level folders (plane {j}'s tiles)", hint=HINT)
        top = max(levels)
        t = size["TileSize"]
        a = np.zeros((size["Height"], size["Width"], 3), np.uint8)
        for row in range(-(-size["Height"] // t)):
            for col in range(-(-size["Width"] // t)):
                tile = _jpeg_rgb(tiles / str(top) / f"{col}_{row}.jpg", f"plane {j}'s tile {col}_{row}")
                a[row * t:row * t + tile.shape[0], col * t:col * t + tile.shape[1]] = tile
    if a.shape[:2] != (h, w):
        raise BadInputError(f"{folder}: plane {j} is {a.shape[1]}x{a.shape[0]}, info.json says {w}x{h}", hint=HINT)
    return a


def _info(folder):
    """info.json's dict, checked for what the reader needs."""
    if not folder.is_dir():
        raise BadInputError(f"{folder} is not a folder", hint=HINT)
    try:
        info = json.loads((folder / "info.json").read_text())
    except (OSError, ValueError) as exc:
        raise BadInputError(f"{folder}: no readable info.json, so not a Relight web folder ({exc})",
                            hint=HINT) from None
    try:
        kind, space, n = info.get("type"), info.get("colorspace"), int(info.get("nplanes", 0))
        w, h = int(info["width"]), int(info["height"])
        mat = info["materials"][0]
        scale, bias = np.asarray(mat["scale"], float), np.asarray(mat["bias"], float)
    except (AttributeError, KeyError, IndexError, TypeError, ValueError) as exc:
        raise BadInputError(f"{folder}/info.json lacks what a Relight web folder holds (width, height, nplanes, "
                            f"materials[0].scale and .bias): {exc!r}", hint=HINT) from None
    if kind not in ("hsh", "ptm") or space != "rgb" or n <= 0 or n % 3:
        raise BadInputError(f"{folder}: type {kind!r}, colour space {space!r}, {n} planes: HSH or PTM in rgb is read",
                            hint="facette reads Relight's HSH and PTM folders (RBF and bilinear ones are not read)")
    if scale.shape != (n,) or bias.shape != (n,) or not (np.isfinite(scale).all() and np.isfinite(bias).all()) \
            or w <= 0 or h <= 0:
        raise BadInputError(f"{folder}/info.json: {n} planes of {w}x{h} but {scale.size} scales and {bias.size} "
                            "biases (finite, one per plane, and a positive size are needed)", hint=HINT)
    return info, kind, n // 3, w, h, scale.reshape(-1, 3), bias.reshape(-1, 3)


def read_relight_web(folder):
    """Read a Relight web folder (info.json + planes, "hsh" or "ptm", colour space "rgb") -> `RelightWeb`.
    A folder that is not one, a missing plane or tile, a truncated JPEG: BadInputError with a hint."""
    folder = Path(folder)
    info, kind, terms, w, h, scale, bias = _info(folder)
    planes = np.empty((terms, h, w, 3), np.uint8)
    for j in range(terms):
        planes[j] = _read_plane(folder, j, w, h)
    return RelightWeb(info, kind, terms, planes, scale, bias)
