"""An RTI capture as the input of `process`: a folder of photographs (JPEG, TIFF, PNG; 8 or 16
bits; sRGB or linear) with an `.lp` file of light directions or positions, as RTIBuilder and
Relight take them, or with a reflective sphere in every photograph and no `.lp`.

The photographs are linearised (sRGB decoded, or taken as linear: `encoding`, said in a note
and overridable), values at the top of the file's range are unknown (NaN), each photograph is
divided by its reference patch where the capture has one (`reference`), and the light
directions come from the `.lp` (positions are made directions from the frame's centre; a
`light_intensities.txt` beside it, R G B per light, divides each photograph) or,
without one, from the mirror sphere (`calib.mirror_sphere_directions`: found, or given as a
circle or a mask); the sphere's disc is then left out of the object's mask. The input folder is
only read: the `.lp` made from the sphere goes beside the results (`PSInput.lights_file`).
"""
import hashlib
from pathlib import Path

import cv2
import numpy as np

from facette.calib.lp import read_lp
from facette.calib.mirror_sphere import Circle, mirror_sphere_directions
from facette.errors import BadInputError
from facette.io.lights import check_lights, photograph_paths
from facette.io.png import read_mask
from facette._threads import run_blocks
from facette.capture.base import Bands
from facette.capture.masks import masks_from
from facette.capture.usable import usable_from_levels

__all__ = ["IMAGE_SUFFIXES", "ENCODINGS", "RTIBands", "rti_files", "open_rti_bands", "is_rti_capture", "read_rti_capture", "srgb_to_linear",
           "parse_circle", "parse_box"]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".png")
ENCODINGS = ("srgb", "linear")
LP_NAME = "lights.lp"        # the .lp written beside the results when the sphere gave the lights
CONVERT_ROWS = 256           # rows of a photograph converted at a time (`RTIBands._convert`)


def _images_in(folder):
    """The photographs of a folder, in the order Relight lists them (by name, case ignored)."""
    return sorted((p for p in Path(folder).iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")
                   and p.stem.lower() != "mask"), key=lambda p: p.name.lower())


def is_rti_capture(path):
    """A folder with an .lp file, or with three photographs or more (the sphere then gives the
    lights)."""
    path = Path(path)
    return path.is_dir() and (any(path.glob("*.lp")) or len(_images_in(path)) >= 3)


def srgb_to_linear(v):
    """IEC 61966-2-1 decoding of values in [0, 1] (any shape), float32."""
    v = np.asarray(v, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


_SRGB_LUT = srgb_to_linear(np.arange(256) / 255.0)        # an 8-bit sRGB level's linear value (float32)


def parse_circle(text):
    """'cx,cy,r' (px) -> Circle, or a mask PNG's path -> its (H, W) bool."""
    parts = str(text).split(",")
    if len(parts) == 3:
        try:
            cx, cy, r = (float(p) for p in parts)
        except ValueError:
            pass
        else:
            if not r > 0:
                raise BadInputError(f"--sphere {text}: the radius must be > 0 px")
            return Circle(cx, cy, r)
    if not Path(text).is_file():
        raise BadInputError(f"--sphere {text} is neither 'cx,cy,r' (pixels) nor a mask file",
                            hint="give the sphere's centre and radius in pixels, or a PNG mask of it")
    return read_mask(text)


def parse_box(text):
    """'x0,y0,x1,y1' (px, x1 and y1 excluded) -> a tuple of 4 ints."""
    try:
        x0, y0, x1, y1 = (int(round(float(p))) for p in str(text).split(","))
    except ValueError:
        raise BadInputError(f"--reference {text} is not 'x0,y0,x1,y1' (pixels)") from None
    if x1 <= x0 or y1 <= y0 or min(x0, y0) < 0:
        raise BadInputError(f"--reference {text}: need 0 <= x0 < x1 and 0 <= y0 < y1")
    return x0, y0, x1, y1


def _read_image(path):
    """(stored values (H, W, 3): uint8, uint16 or float32, top of the range, bit depth) of a JPEG, PNG or TIFF."""
    data = np.fromfile(path, np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)
    if img is None:
        raise BadInputError(f"{path}: cannot read this photograph (not a JPEG, PNG or TIFF, or damaged)",
                            hint="re-export it, or move it out of the capture folder")
    if img.ndim == 3 and img.shape[2] >= 3:
        img = cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2RGB)
    elif img.ndim == 3:
        img = img[..., 0]
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.dtype == np.uint8:
        return img, 255.0, 8
    if img.dtype == np.uint16:
        return img, 65535.0, 16
    if img.dtype in (np.float32, np.float64):
        return img.astype(np.float32), np.inf, 32
    raise BadInputError(f"{path}: {img.dtype} samples are not supported (8 or 16 bits, or float)")


def _lp_images(folder, lp, notes):
    """The .lp's photographs in the folder (`io.lights.photograph_paths`: RTIBuilder writes absolute
    paths of the machine it ran on, read from this folder by their names and said; a photograph
    listed twice, or in no folder but another, refused) and its vectors."""
    names, vecs = read_lp(lp, normalize=False)
    paths, path_notes = photograph_paths(folder, names, lp.name)
    notes.extend(path_notes)
    return paths, vecs


def _bit_depth(path):
    """A photograph's bits per sample from its header (nothing decoded): JPEG 8; PNG its IHDR's
    bit depth; TIFF its BitsPerSample tag (32 for float samples)."""
    suffix = path.suffix.lower()
    if suffix in (".jpg", ".jpeg"):
        return 8
    if suffix == ".png":
        with open(path, "rb") as fh:
            head = fh.read(25)
        return int(head[24]) if len(head) == 25 and head[:8] == b"\x89PNG\r\n\x1a\n" else None
    try:
        import tifffile
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            return int(page.bitspersample)
    except Exception:              # not a TIFF after all: the decoder says what it is
        return None


def _one_depth(paths):
    """The capture's one bit depth (None when no header says it); BadInputError listing the
    photographs of each depth when they mix (an 8-bit JPEG is sRGB, a 16-bit TIFF linear: one
    capture read under one encoding would wrap or darken some of them)."""
    depths = {}
    for p in paths:
        depths.setdefault(_bit_depth(p), []).append(p.name)
    known = {d: n for d, n in depths.items() if d is not None}
    if len(known) > 1:
        listed = "; ".join(f"{d}-bit: {', '.join(n[:4])}{'...' if len(n) > 4 else ''} ({len(n)})"
                           for d, n in sorted(known.items()))
        raise BadInputError(f"the photographs mix bit depths ({listed}): one capture is photographed and "
                            "exported alike, and each depth has its own encoding (8-bit sRGB, 16-bit linear)",
                            hint="export every photograph of the capture alike (all 8-bit JPEGs, or all 16-bit TIFFs)")
    return next(iter(known), None)


def _directions(vecs, lp, notes):
    norms = np.linalg.norm(vecs, axis=1)
    if not np.all(np.abs(norms - 1) < 0.05):
        notes.append(f"{lp.name} holds positions (lengths {norms.min():.3g}–{norms.max():.3g}), not unit "
                     "directions: each light's direction is taken from the frame's centre (far light)")
    return vecs / norms[:, None]


def rti_files(folder, encoding=None):
    """What an RTI capture folder holds, nothing decoded: (photographs, the .lp's vectors or None,
    the .lp files, intensities (m, 3) or None, notes); the lights checked (`io.lights`: those below
    the horizon left out), the photographs' bit depth one (`_one_depth`)."""
    notes = []
    if encoding is not None and encoding not in ENCODINGS:
        raise BadInputError(f"encoding {encoding!r}: choose one of {', '.join(ENCODINGS)}")
    lps = sorted(folder.glob("*.lp"))
    if len(lps) > 1:
        raise BadInputError(f"{folder} holds {len(lps)} .lp files ({', '.join(p.name for p in lps[:3])}): "
                            "one capture has one", hint="move the others out of the folder")
    if lps:
        try:
            paths, vecs = _lp_images(folder, lps[0], notes)
        except BadInputError:
            raise
        except ValueError as exc:            # read_lp names the line
            raise BadInputError(str(exc), hint="fix the .lp file: the count, then 'filename x y z' per line") from None
        keep, light_notes = check_lights(vecs, lps[0].name, [p.name for p in paths])
        notes.extend(light_notes)
    else:
        paths, vecs = _images_in(folder), None
        keep = np.arange(len(paths))
    # light_intensities.txt lists every photograph of the .lp, those left out included
    inten = _read_intensities(folder / "light_intensities.txt", len(paths), notes)
    paths = [paths[k] for k in keep]
    vecs, inten = (None if vecs is None else vecs[keep]), (None if inten is None else inten[keep])
    if len(paths) < 3:
        raise BadInputError(f"{folder} has {len(paths)} photographs: photometric stereo needs 3 or more")
    _one_depth(paths)
    return paths, vecs, lps, inten, notes


class RTIBands(Bands):
    """An RTI capture's photographs read a band of rows at a time: linear (sRGB decoded, or divided by the
    top of the file's range), divided by the light's intensity (and reference patch, `set_reference`), NaN
    where clipped; usable from the file's grey levels. Each photograph is decoded once (the decoders give
    whole images), its stored values kept as they are: in memory, or in a raw file in a `work` folder (a band
    is one read per photograph; `spec()` reopens it in a task); or read whole, converted as decoded (`whole`).
    encoding : "srgb", "linear" or None (from the bit depth: 8-bit sRGB, else linear)."""

    def __init__(self, paths, inten, encoding=None, work=None):
        self.paths, self.inten, self.scale, self.store = list(paths), inten, None, [None] * len(paths)

        def stage(k):      # the decoders (PIL, OpenCV) and the writes give the GIL up: two at once
            raw = self.store[k] = self._decoded(k, self.paths[k], encoding)
            if work is not None:
                self.store[k] = Path(work) / f"rti_{k:04d}.raw"
                np.ascontiguousarray(raw).tofile(self.store[k])
        stage(0)           # the first sets the size, depth and encoding the others are checked against
        run_blocks(stage, range(1, len(self.paths)))

    def _decoded(self, k, p, encoding):
        """Photograph k's stored values (`_read_image`); the first sets the size, depth and encoding."""
        raw, top, bits = _read_image(p)
        if k == 0:
            self.h, self.w = raw.shape[:2]
            self.dtype, self.top, self.bits = raw.dtype, top, bits
            self.enc = encoding or ("srgb" if bits == 8 else "linear")
        elif bits != self.bits:            # a header `_one_depth` could not read: the decoder's word
            raise BadInputError(f"{p.name} holds {bits}-bit samples, {self.paths[0].name} {self.bits}-bit: the "
                                "photographs mix bit depths", hint="export every photograph of the capture alike")
        elif raw.shape[:2] != (self.h, self.w):
            raise BadInputError(f"{p.name} is {raw.shape[1]}x{raw.shape[0]} px, {self.paths[0].name} is "
                                f"{self.w}x{self.h}", hint="every photograph of a capture must have the same size")
        return raw

    @classmethod
    def whole(cls, paths, inten, encoding=None):
        """(reader keeping no photograph, images (m, H, W, 3) float32, usable (m, H, W) bool): `read(0, H)`'s
        values, each photograph decoded, converted into its place and freed before the next (holding
        the decoded ones took 0.58 GB more for 16 JPEGs of 12 MP)."""
        self = cls.__new__(cls)
        self.paths, self.inten, self.store, self.scale = list(paths), inten, [], None
        for k, p in enumerate(self.paths):
            raw = self._decoded(k, p, encoding)
            if k == 0:
                images = np.empty((len(self.paths), self.h, self.w, 3), np.float32)
                usable = np.empty((len(self.paths), self.h, self.w), bool)
            self._convert(k, raw, images[k], usable[k])
            del raw
        return self, images, usable

    @property
    def encoding(self):
        return self.enc

    def note(self, encoding=None):
        return (f"RTI capture: {len(self.paths)} {self.bits}-bit photographs read as {self.enc}"
                + ("" if encoding else " (from their bit depth; --encoding srgb|linear to say otherwise)"))

    def spec(self):
        """What a task needs to open the same reader (`open_bands`): the staged files only."""
        return ("rti", [str(s) for s in self.store], (self.h, self.w), np.dtype(self.dtype).str, self.top, self.bits,
                self.enc, None if self.inten is None else np.asarray(self.inten).tolist(),
                None if self.scale is None else self.scale.tolist())

    @classmethod
    def from_spec(cls, spec):
        self = cls.__new__(cls)
        _, files, (self.h, self.w), dtype, self.top, self.bits, self.enc, inten, scale = spec
        self.store, self.dtype = [Path(f) for f in files], np.dtype(dtype)
        self.paths = self.store
        self.inten = None if inten is None else np.asarray(inten, np.float64)
        self.scale = None if scale is None else np.asarray(scale, np.float64)
        return self

    def close(self):
        pass

    def _stored(self, k, r0, r1):
        s = self.store[k]
        if isinstance(s, np.ndarray):
            return s[r0:r1]
        item = np.dtype(self.dtype).itemsize
        raw = np.fromfile(s, self.dtype, count=(r1 - r0) * self.w * 3, offset=r0 * self.w * 3 * item)
        return raw.reshape(r1 - r0, self.w, 3)

    def read(self, r0, r1, flat=None):
        """(images (m, r1 - r0, W, 3) float32, usable (m, r1 - r0, W) bool) of rows r0..r1."""
        m = len(self.store)
        images = np.empty((m, r1 - r0, self.w, 3), np.float32)
        usable = np.empty((m, r1 - r0, self.w), bool)
        run_blocks(lambda k: self._convert(k, self._stored(k, r0, r1), images[k], usable[k]), range(m))  # numpy: no GIL
        return images, usable

    def _convert(self, k, stored, image, usable):
        """Photograph k's stored values (rows, W, 3) into `image` (linear, NaN where clipped) and `usable`,
        CONVERT_ROWS rows at a time (per sample: the same values; 12 MP whole took 0.45 GB of floats)."""
        top, inten = self.top, self.inten
        scale = top if np.isfinite(top) else 1.0
        lut = _SRGB_LUT if self.enc == "srgb" and self.bits == 8 else None
        for a in range(0, len(stored), CONVERT_ROWS):
            b = min(len(stored), a + CONVERT_ROWS)
            raw = stored[a:b].astype(np.float32)
            usable[a:b] = usable_from_levels(raw[..., 1]) if np.isfinite(top) else raw[..., 1] > 0
            clipped = raw >= top
            out = image[a:b]
            if self.enc == "linear":            # one division in float64, as the DiLiGenT reader does
                out[...] = raw / (scale * (1.0 if inten is None else inten[k]))
            else:
                out[...] = lut[stored[a:b]] if lut is not None else srgb_to_linear(raw / scale)
                if inten is not None:
                    out /= inten[k].astype(np.float32)
            out[clipped] = np.nan
            if self.scale is not None:
                out /= np.float32(self.scale[k])

    def set_reference(self, box, notes):
        """Each photograph divided, from now on, by its reference patch `box` (as `_divide_by_reference`)."""
        x0, y0, x1, y1 = box
        if x1 > self.w or y1 > self.h:
            raise BadInputError(f"the reference patch ({x0},{y0})-({x1},{y1}) is outside the {self.w}x{self.h} px "
                                "photographs")
        patch = self.read(y0, y1)[0][:, :, x0:x1]
        self.scale = _reference_scale(patch, box, notes)


def read_rti_capture(folder, auto_masks, pixel_pitch_mm=None, encoding=None, sphere=None, reference=None):
    """Read an RTI capture folder into the keyword arguments of a `PSInput`.

    folder : the capture (photographs, and an `.lp` file or a reflective sphere in view).
    auto_masks : the function that finds (lit, material) masks from the images (the scan's:
        `capture.masks.auto_masks`); a mask.png in the folder is the object's mask instead.
    pixel_pitch_mm : the object-side pixel size, or None (heights in pixels, said in a note).
    encoding : "srgb" or "linear", or None: sRGB for 8-bit files (what cameras and RTIBuilder's
        JPEGs hold), linear for 16-bit and float files (raw converters', DiLiGenT's).
    sphere : the mirror sphere as a `Circle`, (cx, cy, r) or an (H, W) bool mask, when the
        capture has no .lp and the sphere is not to be found.
    reference : (x0, y0, x1, y1) px of a white or grey patch in every photograph: each is
        divided by the patch's median green (relative to their mean), which evens out a flash
        or a lamp that does not give the same light every time.
    """
    folder = Path(folder)
    paths, vecs, lps, inten, notes = rti_files(folder, encoding)
    bands, images, usable = RTIBands.whole(paths, inten, encoding)     # each decoded, converted, freed
    enc, h, w = bands.enc, bands.h, bands.w
    notes.append(bands.note(encoding))
    if pixel_pitch_mm is None:
        notes.append("an RTI capture carries no pixel pitch: heights are in pixels (--pixel-pitch to give it)")
    sphere_circle = None
    if vecs is not None:
        dirs = _directions(vecs, lps[0], notes)
        lights_file = None
    else:
        # Relight reads 4 fields a line: no .lp it could not load
        lp_ok = all(len(p.name.split()) == 1 for p in paths)
        dirs, sphere_circle = _sphere_directions(images, sphere, notes, lp_ok)
        keep, light_notes = check_lights(dirs, "the mirror sphere's directions", [p.name for p in paths])
        notes.extend(light_notes)
        if len(keep) < len(paths):
            images, usable, dirs = images[keep], usable[keep], dirs[keep]
            paths = [paths[k] for k in keep]
        lights_file = ([p.name for p in paths], dirs) if lp_ok else None
    factors = None if inten is None else np.asarray(inten, float)
    if reference is not None:      # what each photograph was divided by, to fit them as photographed
        level = _divide_by_reference(images, reference, notes)[:, None]
        factors = level if factors is None else factors * level
    return _input_of(folder, paths, lps, (h, w), lambda: auto_masks(images), sphere_circle,
                     dict(images=images, light_dirs=dirs, usable=usable, notes=notes, lights_file=lights_file,
                          photographed={"encoding": enc, "gains": factors}),
                     (enc, str(sphere), reference), pixel_pitch_mm)


def _input_of(folder, paths, lps, shape, masks, sphere_circle, parts, choices, pixel_pitch_mm):
    """The keyword arguments of a `PSInput` of an RTI capture from its `parts` (images, usable,
    light_dirs, notes, lights_file): its masks (the folder's mask.png, or `masks()` -> (lit,
    material), the sphere's disc left out) and its digest (the files and the `choices` read with)."""
    h, w = shape
    mask_file = next((p for p in folder.iterdir() if p.name.lower() == "mask.png"), None)
    if mask_file is not None:          # the capture's own mask: the object, as a given mask
        mask = read_mask(mask_file)
        if mask.shape != (h, w):
            raise BadInputError(f"{mask_file} is {mask.shape[1]}x{mask.shape[0]} px, the photographs {w}x{h}")
        material = mask.copy()
        source = str(mask_file)
    else:
        mask, material = masks()
        source = "the lit pixels of the photographs"
    if sphere_circle is not None:      # the sphere is not the object
        rows, cols = np.mgrid[0:h, 0:w]
        disc = np.hypot(cols - sphere_circle.cx, rows - sphere_circle.cy) < 1.05 * sphere_circle.r + 2
        mask, material = mask & ~disc, material & ~disc
    extra = [p for p in (mask_file, folder / "light_intensities.txt") if p is not None and p.is_file()]
    stamps = sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in paths + lps + extra)
    digest = hashlib.sha256(repr((stamps,) + tuple(choices)).encode()).hexdigest()[:16]
    return dict(parts, positions_mm=None, mask=mask, pixel_pitch_mm=float(pixel_pitch_mm or 1.0),
                kind="rti", source=folder, material_mask=None if mask_file else material,
                object_mask=mask & material, mask_source=source, digest=digest)


def open_rti_bands(folder, work, maps, pixel_pitch_mm=None, encoding=None, sphere=None, reference=None):
    """An RTI capture with an .lp read band by band, its photographs staged in `work`: (the
    keyword arguments of its `PSInput`, images and usable None; its `RTIBands`; the brightest
    green over the lights (H, W), or None with a mask.png). maps(bands) -> (brightest, median,
    unknown) of the green channel over the lights, computed band by band (`capture.open`). None
    for a capture without an .lp: its sphere is found on the whole photographs (`read_rti_capture`)."""
    folder = Path(folder)
    paths, vecs, lps, inten, notes = rti_files(folder, encoding)
    if vecs is None:
        return None
    bands = RTIBands(paths, inten, encoding, work)
    notes.append(bands.note(encoding))
    if pixel_pitch_mm is None:
        notes.append("an RTI capture carries no pixel pitch: heights are in pixels (--pixel-pitch to give it)")
    dirs = _directions(vecs, lps[0], notes)
    factors = None if inten is None else np.asarray(inten, float)
    if reference is not None:      # what each photograph was divided by, to fit them as photographed
        bands.set_reference(reference, notes)
        factors = bands.scale[:, None] if factors is None else factors * bands.scale[:, None]
    top = []

    def masks():
        brightest, med, _ = maps(bands)
        top.append(brightest)
        return masks_from(brightest, med)
    kwargs = _input_of(folder, paths, lps, (bands.h, bands.w), masks, None,
                       dict(images=None, light_dirs=dirs, usable=None, notes=notes, lights_file=None,
                            photographed={"encoding": bands.enc, "gains": factors}),
                       (bands.enc, str(sphere), reference), pixel_pitch_mm)
    return kwargs, bands, (top[0] if top else None)


def _sphere_directions(images, sphere, notes, lp_written=True):
    """Directions from the mirror sphere in the photographs (linear, NaN where clipped);
    `lp_written`: whether its .lp goes beside the results (the note says)."""
    # a clipped highlight is at the top of its photograph
    filled = np.stack([np.nan_to_num(im, nan=float(np.nanmax(im)) if np.isfinite(im).any() else 1.0)
                       for im in images])
    kw = {}
    if isinstance(sphere, Circle) or (sphere is not None and np.ndim(sphere) == 1):
        kw["circle"] = sphere
    elif sphere is not None:
        m = np.asarray(sphere, bool)
        if m.shape != images.shape[1:3]:
            raise BadInputError(f"the sphere's mask is {m.shape[1]}x{m.shape[0]} px, the photographs "
                                f"{images.shape[2]}x{images.shape[1]}")
        kw["mask"] = m
    try:
        dirs, circle, hls = mirror_sphere_directions(filled, **kw)
    except ValueError as exc:
        raise BadInputError(f"the capture has no .lp file and its light directions could not be taken "
                            f"from a mirror sphere: {exc}",
                            hint="add the capture's .lp file, or give the sphere (--sphere cx,cy,r or a mask)") from None
    how = "given" if kw else "found"
    notes.append(f"light directions from the mirror sphere ({how}: centre ({circle.cx:.1f}, {circle.cy:.1f}) px, "
                 f"radius {circle.r:.1f} px), one highlight per photograph; "
                 + (f"{LP_NAME} written beside the results" if lp_written
                    else f"no {LP_NAME} written: a file name holds a space"))
    if any(h.area < 2 for h in hls):
        notes.append("some highlights on the sphere are a pixel or less: their directions are rough")
    return dirs, circle


def _read_intensities(path, m, notes):
    """A light_intensities.txt beside the photographs (R G B per light, in the order of the .lp
    or of the names; DiLiGenT's layout): (m, 3), or None when there is none."""
    if not path.is_file():
        return None
    try:
        inten = np.loadtxt(path, ndmin=2)
    except ValueError as exc:
        raise BadInputError(f"{path}: not a table of numbers ({exc})", hint="R G B per light, one line each") from None
    if inten.shape != (m, 3) or not np.all(np.isfinite(inten) & (inten > 0)):
        raise BadInputError(f"{path} must hold {m} lines of 3 positive numbers (R G B per "
                            f"light), it holds {inten.shape}")
    notes.append(f"each photograph divided by its light's intensity ({path.name}: {inten[:, 1].min():.3g}–"
                 f"{inten[:, 1].max():.3g} in green)")
    return inten


def _divide_by_reference(images, box, notes):
    x0, y0, x1, y1 = box
    m, h, w, _ = images.shape
    if x1 > w or y1 > h:
        raise BadInputError(f"the reference patch ({x0},{y0})-({x1},{y1}) is outside the {w}x{h} px photographs")
    scale = _reference_scale(images[:, y0:y1, x0:x1], box, notes)
    for k in range(m):
        images[k] /= np.float32(scale[k])
    return scale


def _reference_scale(patch, box, notes):
    """Each photograph's light level over their mean, from the reference patch's (m, h, w, 3)
    linear values: their median green; said in a note."""
    x0, y0, x1, y1 = box
    level = np.array([np.nanmedian(im[..., 1]) for im in patch])
    if not np.all(np.isfinite(level) & (level > 0)):
        raise BadInputError("the reference patch is black or clipped in some photographs",
                            hint="give a patch that every light reaches without clipping")
    scale = level / level.mean()
    notes.append(f"each photograph divided by its reference patch ({x0},{y0})-({x1},{y1}): light levels "
                 f"{scale.min():.3f}–{scale.max():.3f} of their mean")
    return scale
