"""The captures of `facette bench relight`, as display values and linear values.

A `Capture` holds every photograph twice: `shown`, the display values (sRGB-encoded, 1 = white,
clipped: what a viewer shows and what the score compares) and `lin`, linear values scaled so
that 1 is the display's white. A linear capture (DiLiGenT's PNGs divided by their lights'
intensities, DiLiGenT-Π's 16-bit PNGs, the Harvard set's grey PNGs) gets its white at the 99.9th
percentile of the object's values over every light; an 8-bit sRGB capture (JPEG + .lp) is its
own display values. `make_jpeg_capture` writes such a capture from a linear one, as a dome
user's camera would (8-bit sRGB JPEG, quality 90, and an .lp).
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from facette.calib.lp import read_lp, write_lp
from facette.io.diligent import read_diligent
from facette.recon import srgb_decode, srgb_encode
from facette.recon._relight_fit import WHITE_PERCENTILE       # the linear captures' white: the model's percentile

__all__ = ["Capture", "diligent_capture", "lp_capture", "harvard_capture", "make_jpeg_capture",
           "hold_every"]

JPEG_QUALITY = 90


@dataclass
class Capture:
    name: str
    group: str
    shown: np.ndarray       # (m, H, W, 3) float32 display values in [0, 1]
    lin: np.ndarray         # (m, H, W, 3) float32 linear, 1 = white
    dirs: np.ndarray        # (m, 3) unit
    mask: np.ndarray        # (H, W) bool
    folds: list             # lists of held-out indices
    srgb8: bool = False     # photographs stored as 8-bit sRGB (JPEG)


def hold_every(m, k):
    """One fold: every k-th light held out (the k-th, 2k-th, ...)."""
    return [np.arange(k - 1, m, k)]


def _from_linear(name, group, images, dirs, mask, folds):
    vals = images[:, mask]
    white = float(np.percentile(vals[np.isfinite(vals)], WHITE_PERCENTILE))
    lin = np.nan_to_num(images / white, nan=1.0).astype(np.float32)   # unknown (clipped): white
    shown = srgb_encode(np.clip(lin, 0, 1)).astype(np.float32)
    return Capture(name, group, shown, lin, np.asarray(dirs, float), mask, folds)


def _crop(images, mask, step=1, margin=8):
    rows, cols = np.nonzero(mask)
    r0, r1 = max(rows.min() - margin, 0), min(rows.max() + margin + 1, mask.shape[0])
    c0, c1 = max(cols.min() - margin, 0), min(cols.max() + margin + 1, mask.shape[1])
    sl = (slice(r0, r1, step), slice(c0, c1, step))
    return np.ascontiguousarray(images[:, sl[0], sl[1]]), mask[sl]


def diligent_capture(folder, group, folds_of, step=1):
    """A DiLiGenT(-Π) folder (divided by the lights' intensities), cropped to the object."""
    d = read_diligent(folder)
    images, mask = _crop(np.asarray(d.images, np.float32), d.mask, step)
    return _from_linear(Path(folder).name, group, images, d.light_dirs, mask, folds_of(len(d.light_dirs)))


def harvard_capture(folder, max_side=320):
    """One object of the Harvard set: 20 grey PNGs (linear), 3×20 light directions, the
    object where the mean image is above 20; decimated to at most `max_side` px."""
    folder = Path(folder)
    dirs = np.loadtxt(folder / "light_directions.txt").T
    files = sorted((folder / "Objects").glob("Image_*.png"))
    grey = np.stack([np.asarray(Image.open(f).convert("L"), np.float32) for f in files])
    step = max(1, int(np.ceil(max(grey.shape[1:]) / max_side)))
    grey = grey[:, ::step, ::step]
    mask = grey.mean(axis=0) > 20
    images, mask = _crop(np.repeat(grey[..., None], 3, axis=-1), mask)
    return _from_linear(folder.name, "Harvard", images, dirs / np.linalg.norm(dirs, axis=1, keepdims=True),
                        mask, hold_every(len(dirs), 6))


def lp_capture(lp_path, group, name=None, k=6):
    """A JPEG + .lp capture (names relative to the .lp's folder), every k-th light held out;
    the object is every pixel (an RTI capture has no mask)."""
    lp_path = Path(lp_path)
    names, dirs = read_lp(lp_path)
    shown = np.stack([np.asarray(Image.open(lp_path.parent / n).convert("RGB"), np.float32) / 255.0
                      for n in names])
    mask = np.ones(shown.shape[1:3], bool)
    return Capture(name or lp_path.parent.parent.name, group, shown, srgb_decode(shown).astype(np.float32),
                   dirs, mask, hold_every(len(dirs), k), srgb8=True)


def make_jpeg_capture(cap, folder, k=6):
    """Write `cap` as a dome user's capture (8-bit sRGB JPEGs + dirs.lp in `folder`) and read it
    back; scored, as the source, over the object's mask."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for j, img in enumerate(cap.shown):
        name = f"{cap.name}_{j + 1:03d}.jpg"
        Image.fromarray(np.round(img * 255).astype(np.uint8)).save(folder / name, quality=JPEG_QUALITY)
        names.append(name)
    write_lp(folder / "dirs.lp", names, cap.dirs)
    out = lp_capture(folder / "dirs.lp", "JPEG + .lp", f"{cap.name}.jpg", k)
    out.mask = cap.mask
    return out
