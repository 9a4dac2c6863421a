"""Opening a capture, whichever its kind: a facette scan directory, a DiLiGenT-style folder or an
RTI capture, whole (`load_input`) or as the band reader a task opens from its `spec()`
(`open_bands`)."""
from pathlib import Path

import numpy as np

from facette.capture.base import NO_PITCH_NOTE, ArrayBands, PSInput, _digest, _file_stamps, given_mask, source_path
from facette.capture.diligent import DiligentBands, _Staged
from facette.capture.masks import auto_masks, masks_from
from facette.capture.rti import RTIBands, is_rti_capture, open_rti_bands, read_rti_capture, rti_files
from facette.capture.scan import (ScanBands, load_scan, merged_lights, profile_flat, scan_input, scan_lights,
                                  scan_manifest)
from facette.capture.usable import usable_from_levels
from facette.io.diligent import is_diligent_dir, read_diligent, read_diligent_lights
from facette.io.png import png_size, read_mask
from facette.scan import ScanDirectory

__all__ = ["SCAN_MAPS_BYTES", "capture_size", "load_input", "open_bands", "open_capture"]


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
        held = isinstance(source, ScanDirectory)
        inp = load_scan(path, pixel_pitch_mm, allow_incomplete, source.take_held_light if held else None,
                        source.prepared if held else None)
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
        raise _not_a_capture(path)
    if mask is not None:
        given_mask(inp, mask)
    return inp


def _not_a_capture(path):
    return ValueError(f"{path} holds neither scan.json (a facette scan) nor filenames.txt and "
                      "light_directions.txt (a DiLiGenT-style folder) nor photographs with an .lp "
                      "file (an RTI capture)")


def open_bands(spec):
    """The band reader a `spec()` describes (in a task, on whichever worker runs it)."""
    if spec[0] == "scan":
        return ScanBands(Path(spec[1]), spec[2], spec[3])
    if spec[0] == "rti":
        return RTIBands.from_spec(spec)
    if spec[0] == "arrays":
        return ArrayBands(spec[1], spec[2])
    staged = _Staged.__new__(_Staged)
    staged.paths, staged.shape, staged.dtype = [Path(p) for p in spec[1]], tuple(spec[2]), np.dtype(spec[3])
    reader = DiligentBands.__new__(DiligentBands)
    reader._init(staged, spec[4])
    return reader


# a scan's maps held in memory at the image's size besides the mask and the two flags that
# `rows_per_tile` counts, at their most (bytes per pixel): while the bands run, the brightest value
# (float32, until the object mask is made) and the material, object and sample masks (1 byte each); before,
# while the masks' maps are read, the brightest value, the median (float32) and the unknown pixels
# (6); a DiLiGenT folder holds its mask only
SCAN_MAPS_BYTES = 7


def _maps_task(spec, r0, r1, flat):
    """A band's part of the masks' maps: (r0, r1, brightest value, median over the lights,
    unknown under some light) of the green channel."""
    from facette.capture._pixels_jit import median_over_lights
    reader = open_bands(spec)
    try:
        g = reader.read(r0, r1, flat)[0][..., 1]
    finally:
        reader.close()
    med = np.empty(g.shape[1:], g.dtype)
    median_over_lights(g, med, slice(0, r1 - r0))
    return r0, r1, np.fmax.reduce(g, axis=0), med, np.isnan(g).any(axis=0)


def _bands_of(h, rows):
    return [(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]


def _here(fn, calls):
    for args in calls:
        yield fn(*args)


def _maps(bands, rows, run, flat=None):
    """(brightest value, median, unknown under some light) of the green channel over the lights,
    (H, W) each, read `rows` rows at a time as tasks of `run`."""
    h, w = bands.h, bands.w
    top, med = np.empty((h, w), np.float32), np.empty((h, w), np.float32)
    unknown = np.zeros((h, w), bool)
    calls = [(bands.spec(), r0, r1, None if flat is None else flat[r0:r1]) for r0, r1 in _bands_of(h, rows)]
    for r0, r1, t, md, u in run(_maps_task, calls):
        top[r0:r1], med[r0:r1], unknown[r0:r1] = t, md, u
    return top, med, unknown


def open_capture(source, work, rows_for, run=None, allow_incomplete=False, pixel_pitch_mm=None, mask=None,
                 capture=None, hand_back=None):
    """A capture of any kind opened band by band, its photographs never held whole: (PSInput with
    images=None and usable=None, band reader with .h, .w, .spec(), .read(r0, r1) and .close(), the
    brightest value over the lights (H, W) or None, band rows).

    work : a folder for staged photographs (a DiLiGenT folder's PNGs, an RTI capture's JPEGs, PNGs
        or TIFFs: their decoders give whole images only). rows_for(w, h, m, maps_bytes) -> the band's
        rows (maps_bytes: bytes per pixel this reading holds at the image's size). run(fn, calls):
        fn(*args) for each args, results as they come (default here, one after the other; on a
        cluster's workers, which then must see the capture's path). The masks' maps (a scan, an RTI
        capture without mask.png) are read band by band. An RTI capture without an .lp is read
        whole (its sphere is found on every photograph at once). capture : an RTI capture's options
        (`capture.rti.read_rti_capture`). hand_back() : called once the maps are made."""
    path = source_path(source)
    run = run or _here
    if (path / "scan.json").is_file():
        inp, bands, top, n = _open_scan(path, rows_for, run, allow_incomplete, pixel_pitch_mm, hand_back)
    elif is_diligent_dir(path):
        names, dirs, inten, notes = read_diligent_lights(path)
        bands = DiligentBands(path, names, inten, work)
        h, w = bands.h, bands.w
        n = rows_for(w, h, len(names), 0)
        own = read_mask(path / "mask.png") if (path / "mask.png").is_file() else np.ones((h, w), bool)
        if own.shape != (h, w):
            raise ValueError(f"mask.png is {own.shape[1]}x{own.shape[0]}, images are {w}x{h}")
        inp = PSInput(None, dirs, None, own, float(pixel_pitch_mm or 1.0), "diligent", path, object_mask=own,
                      mask_source=f"{path / 'mask.png'}" if (path / "mask.png").is_file() else "the image")
        inp.digest = _digest(_file_stamps(path))
        inp.notes.extend(notes)
        if pixel_pitch_mm is None:
            inp.notes.append(NO_PITCH_NOTE)
        top = None
    elif is_rti_capture(path):
        inp, bands, top, n = _open_rti(path, work, rows_for, run, pixel_pitch_mm, capture)
    else:
        raise _not_a_capture(path)
    if mask is not None:
        given_mask(inp, mask)
    return inp, bands, (None if mask is not None else top), n


def _open_scan(path, rows_for, run, allow_incomplete, pixel_pitch_mm, hand_back):
    data, complete = scan_manifest(path, allow_incomplete)
    ids, lights, hdr_notes = merged_lights(path, data)
    dirs, inten, positions, light_notes = scan_lights(path, data, lights)
    bands = ScanBands(path, ids, inten)
    try:
        h, w = bands.h, bands.w
        pitch, profile_notes, bands.flat = profile_flat(data, path, (w, h))
        if bands.flat is not None and bands.flat.shape != (h, w, 3):
            raise ValueError(f"the flat field is {bands.flat.shape} but the images are {(h, w, 3)}: the profile "
                             "was made at another resolution; recalibrate at this one (facette calibrate)")
        if bands.flat is not None and not (np.all(np.isfinite(bands.flat)) and np.all(bands.flat > 0)):
            raise ValueError("the flat field has non-positive or non-finite values: the profile is damaged")
        n = rows_for(w, h, len(ids), SCAN_MAPS_BYTES)
        top, med, unknown = _maps(bands, n, run, bands.flat)
        mask, material = masks_from(top, med)
        del med
        if hand_back is not None:
            hand_back()   # the maps' bands and the median: not under the bands
        inp = scan_input(path, data, complete, None, dirs, positions, mask, material, None, mask | unknown,
                         pixel_pitch_mm or pitch, hdr_notes, light_notes, profile_notes)
    except BaseException:
        bands.close()
        raise
    return inp, bands, top, n


def _open_rti(path, work, rows_for, run, pixel_pitch_mm, capture):
    """An RTI capture band by band (`rti.open_rti_bands`), or, without an .lp, read whole and
    served from memory (`ArrayBands`)."""
    rows = []

    def maps(bands):
        rows.append(rows_for(bands.w, bands.h, len(bands.store), SCAN_MAPS_BYTES))
        return _maps(bands, rows[0], run)
    opened = open_rti_bands(path, work, maps, pixel_pitch_mm, **(capture or {}))
    if opened is None:
        inp = PSInput(**read_rti_capture(path, auto_masks, pixel_pitch_mm, **(capture or {})))
        bands = ArrayBands(inp.images, inp.usable)
        inp.images = inp.usable = None
        top = np.fmax.reduce(bands.images[..., 1], axis=0)
        return inp, bands, top, rows_for(bands.w, bands.h, len(bands.images), SCAN_MAPS_BYTES)
    kwargs, bands, top = opened
    n = rows[0] if rows else rows_for(bands.w, bands.h, len(bands.store), SCAN_MAPS_BYTES)
    return PSInput(**kwargs), bands, top, n


def capture_size(source):
    """(photographs, height, width) of a capture from its files' headers, nothing decoded; None
    when they do not say (a scan not merged yet, a file no header reader knows)."""
    try:
        path = source_path(source)
        if (path / "scan.json").is_file():
            import OpenEXR
            data = ScanDirectory(path).manifest
            ids = data.frame_lights() or [int(l.index) for l in data.lights]
            f = OpenEXR.InputFile(str(path / "hdr" / f"light_{ids[0]:02d}.exr"))
            box = f.header()["dataWindow"]
            f.close()
            return len(ids), box.max.y - box.min.y + 1, box.max.x - box.min.x + 1
        if is_diligent_dir(path):
            names = [l.strip() for l in (path / "filenames.txt").read_text().splitlines() if l.strip()]
            w, h = png_size(path / names[0])
            return len(names), h, w
        if is_rti_capture(path):
            from PIL import Image
            paths = rti_files(path)[0]
            with Image.open(paths[0]) as im:
                w, h = im.size
            return len(paths), h, w
    except Exception:            # the reader itself will say what is wrong with the capture
        return None
    return None
