"""Inputs of `process`: a facette scan directory or a DiLiGenT-style folder."""
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from facette.io.diligent import is_diligent_dir, read_diligent
from facette.io.png import read_mask
from facette.pipeline._quality import usable_from_levels
from facette.pipeline._rti_capture import is_rti_capture, read_rti_capture
from facette.scan import ScanDirectory

__all__ = ["PSInput", "load_input", "source_path", "auto_masks", "margin_of", "MARGIN_BORDER", "object_of",
           "OBJECT_OVER_TABLE"]

# `object_of`: an object pixel is lit, under its brightest light, at least this many times the
# table's median brightest value (simulated demo: 116,003 object pixels found of the truth's
# 116,082, 19 of the table taken; Otsu's class alone: 109,841, the sphere's dark rim left out)
OBJECT_OVER_TABLE = 2.0


# The dark class is a margin (a table, a cloth) only where it surrounds the object: at least
# this share of the lit pixels on the image's border.
MARGIN_BORDER = 0.9

# `masks_from` reads its two maps this many rows at a time
MASK_ROWS = 512


@dataclass
class PSInput:
    """images (m, H, W, 3) float32 divided by the light intensities (NaN where unknown);
    light_dirs (m, 3) unit vectors (camera frame); positions_mm (m, 3) or None;
    mask (H, W) bool, where normals and heights are computed; pixel_pitch_mm; kind "scan" or
    "diligent"; truth: dict or None; material_mask (H, W) bool or None (= mask), the pixels
    whose reflectance samples feed the BRDF fit (see `auto_masks`)."""
    images: np.ndarray
    light_dirs: np.ndarray
    positions_mm: object
    mask: np.ndarray
    pixel_pitch_mm: float
    kind: str
    source: Path
    truth: object = None
    notes: list = field(default_factory=list)
    material_mask: object = None
    usable: object = None          # (m, H, W) bool: known and above noise (see _quality)
    object_mask: object = None     # (H, W) bool: the pixels that should get a result
    mask_source: str = "the lit pixels"
    incomplete: str = ""           # scans: "" when complete, else e.g. "5 of 6 frames"
    digest: str = ""               # what the inputs were: changes when a frame or image changes
    lights_file: object = None     # RTI captures lit by a sphere: (file names, directions) of the .lp to write
    reflectance: bool = False      # the images are radiance factors (a scan with the Spectralon's radiometric scale)
    photographed: object = None    # RTI captures: {"encoding", "gains" (m, 3) or None} (pipeline._rti_exposure)

    def sample_mask(self):
        """Pixels whose reflectance samples are taken: the mask, within the material mask."""
        return self.mask if self.material_mask is None else self.mask & self.material_mask

    def background_mask(self):
        """The dark table or cloth around the object (`margin_of`), or None (also for a given
        mask or a DiLiGenT folder, which have no material mask)."""
        return None if self.material_mask is None else margin_of(self.mask, self.material_mask)


NO_PITCH_NOTE = "DiLiGenT folders carry no pixel pitch: heights are in pixels (pitch 1)"


def source_path(source):
    """A path from a str/PathLike or an object with .path / .directory / .root (a Scan)."""
    if isinstance(source, (str, os.PathLike)):
        return Path(source)
    for attr in ("path", "directory", "root", "scan_dir"):
        value = getattr(source, attr, None)
        if isinstance(value, (str, os.PathLike)):
            return Path(value)
    raise TypeError(f"cannot process {type(source).__name__}: pass a scan directory, a "
                    "DiLiGenT-style folder, or a Scan object")


def auto_masks(images, min_contrast=4.0):
    """Two masks, (lit, material), each (H, W) bool.

    lit : pixels lit above 2 % of the bright end (99th percentile of the per-pixel maximum
        over the lights): where photometric stereo and integration run. A dark table under
        the object stays in, so heights keep one reference plane across separate objects.
    material : the lit pixels on the bright side of Otsu's threshold on log luminance when
        the scene has a dark background (black velvet, the simulator's table); else `lit`.
        The reflectance samples, hence the BRDF fit, come from these pixels only: a
        background is another material and drags the fit away (on the simulated sphere, with
        the table in, σ came out 1.43 instead of 0.05).

    The background is cut only when the two classes' mean luminances differ by more than
    `min_contrast` times: a slab that fills the frame keeps every lit pixel. The luminance for
    that split is the median over the lights (highlights and shadows do not move it).
    """
    ch = images[..., 1] if images.shape[-1] == 3 else images.mean(axis=-1)
    lum = np.fmax.reduce(ch, axis=0)      # NaN-ignoring max over the lights
    from facette.pipeline._pixels_jit import median_over_lights
    med = np.empty(lum.shape, ch.dtype)  # pixels unknown under every light: NaN, dropped below
    median_over_lights(ch, med, slice(None), workers=2)
    return masks_from(lum, med, min_contrast)


def masks_from(top, med, min_contrast=4.0, rows=MASK_ROWS):
    """`auto_masks` from its two maps of the green channel over the lights, (H, W) each: `top`
    the NaN-ignoring maximum, `med` the median of the known values (NaN where none); a tiled
    reading computes them band by band (pipeline._tiled_process). Read `rows` rows at a time:
    besides the two masks nothing is made at the image's size (at 100 MP the whole-image
    temporaries were ~1.7 GB on top of the two maps); the same masks for any `rows`."""
    h = top.shape[0]
    bands = [slice(r0, r0 + rows) for r0 in range(0, h, rows)]
    sub = np.nan_to_num(top.ravel()[::7], nan=0.0)            # a quantile needs no full sort
    ref = float(np.quantile(sub, 0.99)) if sub.size else 0.0
    if not ref > 0:
        return np.zeros(top.shape, bool), np.zeros(top.shape, bool)
    lit = np.empty(top.shape, bool)
    lo, hi, n_ok = None, None, 0

    def log_ok(b):        # log of the median where it is known and positive on a lit pixel
        with np.errstate(invalid="ignore"):
            ok = lit[b] & np.isfinite(med[b]) & (med[b] > 0)
        return ok, np.log(med[b][ok])
    for b in bands:
        with np.errstate(invalid="ignore"):
            lit[b] = np.nan_to_num(top[b], nan=0.0) > 0.02 * ref
        ok, logl = log_ok(b)
        if logl.size:
            lo = logl.min() if lo is None else min(lo, logl.min())
            hi = logl.max() if hi is None else max(hi, logl.max())
            n_ok += logl.size
    if n_ok < 16:
        return lit, lit
    hist, edges = 0, None            # np.histogram(all, 256) has the range (min, max): same bins
    for b in bands:
        part, edges = np.histogram(log_ok(b)[1], bins=256, range=(lo, hi))
        hist = hist + part
    w0 = np.cumsum(hist)                                     # Otsu: maximise the between-class variance
    w1 = w0[-1] - w0
    centres = 0.5 * (edges[1:] + edges[:-1])
    s0 = np.cumsum(hist * centres)
    with np.errstate(divide="ignore", invalid="ignore"):
        m0, m1 = s0 / w0, (s0[-1] - s0) / w1
        between = np.where((w0 > 0) & (w1 > 0), w0 * w1 * (m0 - m1) ** 2, -1.0)
    k = int(np.argmax(between))
    if between[k] <= 0 or m1[k] - m0[k] < np.log(min_contrast):
        return lit, lit
    material = np.zeros(top.shape, bool)
    for b in bands:
        ok, logl = log_ok(b)
        material[b][ok] = logl > edges[k + 1]
    return lit, material


def object_of(images, lit, material, factor=OBJECT_OVER_TABLE, top=None):
    """The object (H, W) bool: `material` (Otsu's bright class of `auto_masks`) grown into the
    lit pixels connected to it that are brighter, under their brightest light, than `factor`
    times the table's median (the dark rims and grooves of an object, which the median over the
    lights puts on the table's side). `lit` itself when there is no table (material == lit).
    top : that brightest value (H, W), NaN-ignoring maximum of the green channel over the lights,
    when it is at hand (then `images` is not read and may be None)."""
    lit, material = np.asarray(lit, bool), np.asarray(material, bool)
    table = lit & ~material
    if not table.any() or not material.any():
        return material.copy()
    if top is None:
        ch = images[..., 1] if images.shape[-1] == 3 else images.mean(axis=-1)
        top = np.fmax.reduce(ch, axis=0)             # NaN-ignoring; all-NaN (saturated): NaN
    floor = factor * float(np.median(np.nan_to_num(top[table], nan=0.0)))
    with np.errstate(invalid="ignore"):
        bright = lit & ((top > floor) | np.isnan(top))
    labels, _ = ndimage.label(bright | material)
    keep = np.zeros(labels.max() + 1, bool)
    keep[np.unique(labels[material])] = True
    keep[0] = False
    return keep[labels]


def margin_of(lit, material):
    """The lit pixels outside the object's material (the dark table or cloth it lies on) when
    they surround it, else None: no dark class, or a dark class that is part of the object (a
    slab filling the frame with a dark matrix: less than MARGIN_BORDER of the image's lit border
    pixels in it). lit, material : (H, W) bool, as `auto_masks` gives them."""
    lit = np.asarray(lit, bool)
    bg = lit & ~np.asarray(material, bool)

    def border(a):
        return np.concatenate([a[0], a[-1], a[1:-1, 0], a[1:-1, -1]])

    if not bg.any() or border(bg).sum() < MARGIN_BORDER * max(1, border(lit).sum()):
        return None
    return bg


def _digest(items):
    import hashlib

    return hashlib.sha256(repr(items).encode()).hexdigest()[:16]


def _file_stamps(folder):
    """(name, size, mtime_ns) of every file in a folder: what a DiLiGenT folder's images were."""
    return sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in Path(folder).iterdir()
                  if p.is_file())


def load_input(source, mask=None, pixel_pitch_mm=None, allow_incomplete=False, capture=None):
    """Read a scan directory (scan.json + hdr/) or a DiLiGenT-style folder into a `PSInput`.

    source : a path, or a `ScanDirectory` (as `run_scan` returns it: the lights it merged and
    held in memory are taken from it, the same values as their files, which are then not read).
    mask : optional (H, W) bool array or path to a PNG; default: scan -> lit pixels,
    DiLiGenT -> its mask.png. pixel_pitch_mm overrides the scan's (DiLiGenT default 1).
    allow_incomplete : process a scan that is not complete (BadInputError otherwise).
    capture : options of an RTI capture folder (`pipeline._rti_capture.read_rti_capture`:
        encoding, sphere, reference).
    """
    path = source_path(source)
    if not path.is_dir():
        raise FileNotFoundError(f"{path} is not a directory; give a scan directory (with scan.json) "
                                "or a DiLiGenT-style folder (with filenames.txt)")
    if (path / "scan.json").is_file():
        take_held = source.take_held_light if isinstance(source, ScanDirectory) else None
        from facette.pipeline._scan_input import load_scan     # it reads PSInput from here
        inp = load_scan(path, pixel_pitch_mm, allow_incomplete, take_held)
        if inp.incomplete:
            inp.notes.insert(0, f"the scan is incomplete ({inp.incomplete}): these results come from "
                                "part of its data; run the same scan command to resume it")
    elif is_diligent_dir(path):
        d = read_diligent(path)
        with np.errstate(invalid="ignore"):
            levels = d.images[..., 1] * (d.light_intensities[:, 1] * (2.0 ** d.bit_depth - 1))[:, None, None]
        usable = usable_from_levels(levels)
        inp = PSInput(d.images, d.light_dirs, None, d.mask, float(pixel_pitch_mm or 1.0),
                      "diligent", path, usable=usable, object_mask=d.mask,
                      mask_source=f"{path / 'mask.png'}" if (path / "mask.png").is_file() else "the image")
        inp.digest = _digest(_file_stamps(path))
        inp.notes.extend(d.notes)
        if pixel_pitch_mm is None:
            inp.notes.append(NO_PITCH_NOTE)
    elif is_rti_capture(path):
        inp = PSInput(**read_rti_capture(path, auto_masks, pixel_pitch_mm, **(capture or {})))
    else:
        raise ValueError(f"{path} holds neither scan.json (a facette scan) nor filenames.txt and "
                         "light_directions.txt (a DiLiGenT-style folder) nor photographs with an .lp "
                         "file (an RTI capture)")
    if mask is not None:
        given_mask(inp, mask)
    return inp


def given_mask(inp, mask):
    """A mask given to `process` (array or PNG path) in place of the input's own."""
    m = read_mask(mask) if isinstance(mask, (str, os.PathLike)) else np.asarray(mask, bool)
    if m.shape != inp.mask.shape:
        raise ValueError(f"the mask {mask if isinstance(mask, (str, os.PathLike)) else ''} is "
                         f"{m.shape[1]}x{m.shape[0]} px, the images are {inp.mask.shape[1]}x"
                         f"{inp.mask.shape[0]}: give a mask of the images' size")
    inp.mask, inp.material_mask = m, None     # a given mask is the object: samples follow it
    inp.object_mask = m
    inp.mask_source = f"--mask {mask}" if isinstance(mask, (str, os.PathLike)) else "the given mask"
