"""Opening a capture, whichever its kind: a facette scan directory, a DiLiGenT-style folder or an
RTI capture, whole (`load_input`) or as the band reader a task opens from its `spec()`
(`open_bands`)."""
from pathlib import Path

import numpy as np

from facette.capture.base import NO_PITCH_NOTE, PSInput, _digest, _file_stamps, given_mask, source_path
from facette.capture.diligent import DiligentBands, _Staged
from facette.capture.masks import auto_masks
from facette.capture.rti import is_rti_capture, read_rti_capture
from facette.capture.scan import ScanBands, load_scan
from facette.capture.usable import usable_from_levels
from facette.io.diligent import is_diligent_dir, read_diligent
from facette.scan import ScanDirectory

__all__ = ["load_input", "open_bands"]


def load_input(source, mask=None, pixel_pitch_mm=None, allow_incomplete=False, capture=None):
    """Read a scan directory (scan.json + hdr/) or a DiLiGenT-style folder into a `PSInput`.

    source : a path, or a `ScanDirectory` (as `run_scan` returns it: the lights it merged and
    held in memory are taken from it, the same values as their files, which are then not read).
    mask : optional (H, W) bool array or path to a PNG; default: scan -> lit pixels,
    DiLiGenT -> its mask.png. pixel_pitch_mm overrides the scan's (DiLiGenT default 1).
    allow_incomplete : process a scan that is not complete (BadInputError otherwise).
    capture : options of an RTI capture folder (`capture.rti.read_rti_capture`:
        encoding, sphere, reference).
    """
    path = source_path(source)
    if not path.is_dir():
        raise FileNotFoundError(f"{path} is not a directory; give a scan directory (with scan.json) "
                                "or a DiLiGenT-style folder (with filenames.txt)")
    if (path / "scan.json").is_file():
        take_held = source.take_held_light if isinstance(source, ScanDirectory) else None
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


def open_bands(spec):
    """The band reader a `spec()` describes (in a task, on whichever worker runs it)."""
    if spec[0] == "scan":
        return ScanBands(Path(spec[1]), spec[2], spec[3])
    staged = _Staged.__new__(_Staged)
    staged.paths, staged.shape, staged.dtype = [Path(p) for p in spec[1]], tuple(spec[2]), np.dtype(spec[3])
    reader = DiligentBands.__new__(DiligentBands)
    reader._init(staged, spec[4])
    return reader
