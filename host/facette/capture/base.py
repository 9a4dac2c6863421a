"""What every capture reader gives `process`: a `PSInput` (the photographs or a band reader, the
lights, the masks, the notes) and the helpers the readers share."""
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facette.capture.masks import margin_of
from facette.io.png import read_mask

__all__ = ["Bands", "ArrayBands", "PSInput", "NO_PITCH_NOTE", "source_path", "given_mask"]


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


def _digest(items):
    import hashlib

    return hashlib.sha256(repr(items).encode()).hexdigest()[:16]


def _file_stamps(folder):
    """(name, size, mtime_ns) of every file in a folder: what a DiLiGenT folder's images were."""
    return sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in Path(folder).iterdir()
                  if p.is_file())


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


class Bands:
    """What every capture's band reader is (`ScanBands`, `DiligentBands`, `RTIBands`, `ArrayBands`):
    h, w : the photographs' size; inten : (m, 3) the lights' intensities the values are divided by
    (None: none); encoding : how the stored values became linear ("linear", or "srgb" for sRGB
    photographs decoded); read(r0, r1) -> (images (m, r1 - r0, W, 3) float32, NaN where unknown,
    usable (m, r1 - r0, W) bool) of rows r0..r1; spec() : what `capture.open_bands` needs to open
    the same reader in another process; close()."""
    inten = None
    encoding = "linear"

    def read(self, r0, r1, flat=None):
        raise NotImplementedError

    def spec(self):
        raise NotImplementedError

    def close(self):
        pass


class ArrayBands(Bands):
    """Photographs held in memory (a script's arrays, or a capture read whole) behind the band
    readers' interface: read(r0, r1) -> (images (m, r1 - r0, W, C) float32, usable (m, r1 - r0, W)
    bool: given, or known and > 0 where none is given)."""

    def __init__(self, images, usable=None):
        self.images, self.usable = images, usable
        self.h, self.w = images.shape[1:3]

    def spec(self):
        return ("arrays", self.images, self.usable)

    def read(self, r0, r1, flat=None):
        band = self.images[:, r0:r1].copy()      # a band of its own, as a file reader's: the loop divides it in place
        if self.usable is not None:
            return band, self.usable[:, r0:r1]
        with np.errstate(invalid="ignore"):
            return band, np.isfinite(band[..., 1]) & (band[..., 1] > 0)

    def close(self):
        pass
