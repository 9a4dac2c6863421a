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
from facette.io.png import read_mask
from facette.pipeline._quality import usable_from_levels

__all__ = ["IMAGE_SUFFIXES", "ENCODINGS", "is_rti_capture", "read_rti_capture", "srgb_to_linear",
           "parse_circle", "parse_box"]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".png")
ENCODINGS = ("srgb", "linear")
LP_NAME = "lights.lp"        # the .lp written beside the results when the sphere gave the lights


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
    """(stored values as float32 (H, W, 3), top of the range, bit depth) of a JPEG, PNG or TIFF."""
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
        return img.astype(np.float32), 255.0, 8
    if img.dtype == np.uint16:
        return img.astype(np.float32), 65535.0, 16
    if img.dtype in (np.float32, np.float64):
        return img.astype(np.float32), np.inf, 32
    raise BadInputError(f"{path}: {img.dtype} samples are not supported (8 or 16 bits, or float)")


def _lp_images(folder, lp):
    """The .lp's file names resolved in the folder (RTIBuilder writes absolute paths of the
    machine it ran on: the name alone is looked for then)."""
    names, vecs = read_lp(lp, normalize=False)
    paths = []
    for i, name in enumerate(names, start=2):
        p = folder / name
        if not p.is_file():
            p = folder / name.replace("\\", "/").rsplit("/", 1)[-1]
        if not p.is_file():
            raise BadInputError(f"{lp} line {i}: {name} is not in {folder}",
                                hint="the .lp must name the photographs of its folder")
        paths.append(p)
    return paths, vecs


def _directions(vecs, lp, notes):
    norms = np.linalg.norm(vecs, axis=1)
    if not np.all(np.abs(norms - 1) < 0.05):
        notes.append(f"{lp.name} holds positions (lengths {norms.min():.3g}–{norms.max():.3g}), not unit "
                     "directions: each light's direction is taken from the frame's centre (far light)")
    return vecs / norms[:, None]


def read_rti_capture(folder, auto_masks, pixel_pitch_mm=None, encoding=None, sphere=None, reference=None):
    """Read an RTI capture folder into the keyword arguments of a `PSInput`.

    folder : the capture (photographs, and an `.lp` file or a reflective sphere in view).
    auto_masks : the function that finds (lit, material) masks from the images (the scan's:
        `pipeline._inputs.auto_masks`); a mask.png in the folder is the object's mask instead.
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
    notes = []
    if encoding is not None and encoding not in ENCODINGS:
        raise BadInputError(f"encoding {encoding!r}: choose one of {', '.join(ENCODINGS)}")
    lps = sorted(folder.glob("*.lp"))
    if len(lps) > 1:
        raise BadInputError(f"{folder} holds {len(lps)} .lp files ({', '.join(p.name for p in lps[:3])}): "
                            "one capture has one", hint="move the others out of the folder")
    if lps:
        try:
            paths, vecs = _lp_images(folder, lps[0])
        except ValueError as exc:            # read_lp names the line
            raise BadInputError(str(exc), hint="fix the .lp file: the count, then 'filename x y z' per line") from None
    else:
        paths, vecs = _images_in(folder), None
    if len(paths) < 3:
        raise BadInputError(f"{folder} has {len(paths)} photographs: photometric stereo needs 3 or more")
    first, top, bits = _read_image(paths[0])
    h, w = first.shape[:2]
    enc = encoding or ("srgb" if bits == 8 else "linear")
    notes.append(f"RTI capture: {len(paths)} {bits}-bit photographs read as {enc}"
                 + ("" if encoding else " (from their bit depth; --encoding srgb|linear to say otherwise)"))
    images = np.empty((len(paths), h, w, 3), np.float32)
    usable = np.empty((len(paths), h, w), bool)
    lut = srgb_to_linear(np.arange(256) / 255.0) if enc == "srgb" and bits == 8 else None
    inten = _read_intensities(folder / "light_intensities.txt", len(paths), notes)
    for k, p in enumerate(paths):
        raw, top_k, _ = (first, top, bits) if k == 0 else _read_image(p)
        if raw.shape[:2] != (h, w):
            raise BadInputError(f"{p.name} is {raw.shape[1]}x{raw.shape[0]} px, {paths[0].name} is {w}x{h}",
                                hint="every photograph of a capture must have the same size")
        usable[k] = usable_from_levels(raw[..., 1]) if np.isfinite(top_k) else raw[..., 1] > 0
        clipped = raw >= top_k
        scale = top_k if np.isfinite(top_k) else 1.0
        if enc == "linear":            # one division in float64, as the DiLiGenT reader does
            images[k] = raw / (scale * (1.0 if inten is None else inten[k]))
        else:
            images[k] = lut[raw.astype(np.uint8)] if lut is not None else srgb_to_linear(raw / scale)
            if inten is not None:
                images[k] /= inten[k].astype(np.float32)
        images[k][clipped] = np.nan
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
        lights_file = ([p.name for p in paths], dirs) if lp_ok else None
    factors = None if inten is None else np.asarray(inten, float)
    if reference is not None:      # what each photograph was divided by, to fit them as photographed
        level = _divide_by_reference(images, reference, notes)[:, None]
        factors = level if factors is None else factors * level
    mask_file = next((p for p in folder.iterdir() if p.name.lower() == "mask.png"), None)
    if mask_file is not None:          # the capture's own mask: the object, as a given mask
        mask = read_mask(mask_file)
        if mask.shape != (h, w):
            raise BadInputError(f"{mask_file} is {mask.shape[1]}x{mask.shape[0]} px, the photographs {w}x{h}")
        material = mask.copy()
        source = str(mask_file)
    else:
        mask, material = auto_masks(images)
        source = "the lit pixels of the photographs"
    if sphere_circle is not None:      # the sphere is not the object
        rows, cols = np.mgrid[0:h, 0:w]
        disc = np.hypot(cols - sphere_circle.cx, rows - sphere_circle.cy) < 1.05 * sphere_circle.r + 2
        mask, material = mask & ~disc, material & ~disc
    extra = [p for p in (mask_file, folder / "light_intensities.txt") if p is not None and p.is_file()]
    stamps = sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in paths + lps + extra)
    digest = hashlib.sha256(repr((stamps, enc, str(sphere), reference)).encode()).hexdigest()[:16]
    return dict(images=images, light_dirs=dirs, positions_mm=None, mask=mask, pixel_pitch_mm=float(pixel_pitch_mm or 1.0),
                kind="rti", source=folder, notes=notes,
                material_mask=None if mask_file else material, usable=usable,
                object_mask=mask & material, mask_source=source,
                digest=digest, lights_file=lights_file,
                photographed={"encoding": enc, "gains": factors})


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
    level = np.array([np.nanmedian(im[y0:y1, x0:x1, 1]) for im in images])
    if not np.all(np.isfinite(level) & (level > 0)):
        raise BadInputError("the reference patch is black or clipped in some photographs",
                            hint="give a patch that every light reaches without clipping")
    scale = level / level.mean()
    for k in range(m):
        images[k] /= np.float32(scale[k])
    notes.append(f"each photograph divided by its reference patch ({x0},{y0})-({x1},{y1}): light levels "
                 f"{scale.min():.3f}–{scale.max():.3f} of their mean")
    return scale

