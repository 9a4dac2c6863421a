"""Inputs of `process`: a facette scan directory or a DiLiGenT-style folder."""
import os
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from facette.calib import ProfileError, ResolutionError, apply_flat_field, load, pitch_at_size
from facette.errors import BadInputError
from facette.io.diligent import is_diligent_dir, read_diligent
from facette.io.png import read_mask
from facette.pipeline._quality import MIN_LEVELS, usable_from_green
from facette.pipeline._rti_capture import is_rti_capture, read_rti_capture
from facette.scan import MissingFrameWarning, ScanDirectory, merge_scan, stale_lights

__all__ = ["PSInput", "load_input", "source_path", "auto_masks", "margin_of", "MARGIN_BORDER", "object_of",
           "OBJECT_OVER_TABLE"]

# `object_of`: an object pixel is lit, under its brightest light, at least this many times the
# table's median brightest value (simulated demo: 116,003 object pixels found of the truth's
# 116,082, 19 of the table taken; Otsu's class alone: 109,841, the sphere's dark rim left out)
OBJECT_OVER_TABLE = 2.0


# The dark class is a margin (a table, a cloth) only where it surrounds the object: at least
# this share of the lit pixels on the image's border.
MARGIN_BORDER = 0.9


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
    half = lum.shape[0] // 2              # two halves of the rows on two threads (the kernel frees the GIL)
    with ThreadPoolExecutor(2) as pool:
        list(pool.map(lambda sl: median_over_lights(ch, med, sl), (slice(0, half), slice(half, None))))
    return masks_from(lum, med, min_contrast)


def masks_from(top, med, min_contrast=4.0):
    """`auto_masks` from its two maps of the green channel over the lights, (H, W) each: `top`
    the NaN-ignoring maximum, `med` the median of the known values (NaN where none); a tiled
    reading computes them band by band (pipeline._tiled_process)."""
    lum = np.nan_to_num(top, nan=0.0)
    sub = lum.ravel()[::7]                                   # a quantile needs no full sort
    ref = float(np.quantile(sub, 0.99)) if sub.size else 0.0
    if not ref > 0:
        return np.zeros(lum.shape, bool), np.zeros(lum.shape, bool)
    lit = lum > 0.02 * ref
    ok = lit & np.isfinite(med) & (med > 0)
    if ok.sum() < 16:
        return lit, lit
    logl = np.log(med[ok])
    hist, edges = np.histogram(logl, bins=256)
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
    material = np.zeros(lum.shape, bool)
    material[ok] = logl > edges[k + 1]
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


def _unreadable(path, exc):
    return ValueError(f"{path}: cannot read this HDR image ({exc}); delete {path.parent} to "
                      "merge it again from raw/, or rescan that light")


def _read_hdr_fast(scan_dir, light_ids, take_held=None):
    """Read hdr/light_XX.exr (and _var.exr, for unknown values) into one preallocated array,
    two files at a time. NaN where the variance is not finite (saturated in every frame).
    A light merged during the scan and held by its `ScanDirectory` (`take_held`: its
    `take_held_light`) is taken from memory, the same values as its files."""
    import OpenEXR
    paths = [(scan_dir / "hdr" / f"light_{i:02d}.exr", scan_dir / "hdr" / f"light_{i:02d}_var.exr")
             for i in light_ids]
    held = [take_held(i) if take_held is not None else None for i in light_ids]
    if held[0] is not None:
        h, w = held[0][1].shape
    else:
        try:
            with OpenEXR.File(str(paths[0][0]), separate_channels=True) as f:
                h, w = f.channels()["R"].pixels.shape
        except Exception as exc:             # OpenEXR says only "file has 0 parts" and the like
            raise _unreadable(paths[0][0], exc) from exc
    images = np.empty((len(paths), h, w, 3), np.float32)
    usable = np.empty((len(paths), h, w), bool)

    def one(k):
        try:
            read_pair(k)
        except BadInputError:             # already names the file and what to do
            raise
        except Exception as exc:
            raise _unreadable(paths[k][0], exc) from exc

    def read_pair(k):
        img, var = paths[k]
        if held[k] is not None and held[k][0].shape == (h, w, 3):
            images[k], v_green = held[k]
            held[k] = None                                   # freed as it is copied
            bad = np.isnan(v_green)
        else:
            v_green, bad = read_files(k, img, var)
            if v_green is None:        # radiance without its variance
                return
        images[k][bad] = np.nan
        usable[k] = usable_from_green(images[k][..., 1], v_green)

    def read_files(k, img, var):
        """Read the pair into images[k]: (green variance, where the variance is not finite);
        (None, None) for radiance without a variance file (usable[k] then set here)."""
        try:
            with OpenEXR.File(str(img), separate_channels=True) as f:
                chans = f.channels()
                for c, name in enumerate("RGB"):
                    images[k, :, :, c] = chans[name].pixels
        except Exception as exc:  # OpenEXR raises plain exceptions on damaged files
            raise BadInputError(f"{img}: cannot read this HDR image ({exc})",
                                hint="delete it: processing merges it again from raw/") from exc
        if not var.is_file():      # radiance without its variance (made elsewhere): no noise
            images[k][~np.isfinite(images[k]).all(axis=-1)] = np.nan
            usable[k] = np.isfinite(images[k][..., 1]) & (images[k][..., 1] > 0)
            return None, None
        try:
            with OpenEXR.File(str(var), separate_channels=True) as f:
                v = [f.channels()[c].pixels for c in "RGB"]
        except Exception as exc:
            raise BadInputError(f"{var}: cannot read this HDR image ({exc})",
                                hint="delete it: processing merges it again from raw/") from exc
        # channel by channel (a reduction over the last axis of 3 is ~5x slower)
        bad = ~(np.isfinite(v[0]) & np.isfinite(v[1]) & np.isfinite(v[2]))
        fin = np.isfinite(images[k])
        wild = ~(fin[..., 0] | fin[..., 1] | fin[..., 2]) & ~bad
        if wild.any():
            raise BadInputError(f"{img} has {int(wild.sum())} non-finite values (Inf or NaN) where "
                                f"its variance {var.name} is finite: the file is damaged",
                                hint="delete it: processing merges it again from raw/")
        return v[1], bad

    with ThreadPoolExecutor(2) as pool:
        list(pool.map(one, range(len(paths))))
    return images, usable


def _load_hdr_images(scan_dir, data, take_held=None):
    """(images, usable, lights, notes): hdr/ read, after merging again (under the directory's
    lock) every light whose files are absent, made from other frames, or changed; the lights
    `take_held` gives (see `_read_hdr_fast`) from memory."""
    ids, lights, notes = merged_lights(scan_dir, data)
    images, usable = _read_hdr_fast(scan_dir, ids, take_held)
    return images, usable, lights, notes


def merged_lights(scan_dir, data):
    """(light ids, their scan.json entries, notes) once every light's hdr/ files are there and
    up to date (merged again, under the directory's lock, where absent, made from other frames,
    or changed)."""
    lights = sorted(data.lights, key=lambda l: int(l.index))
    ids = data.frame_lights() or [int(l.index) for l in lights]
    by_index = {int(l.index): l for l in lights}
    unknown = [i for i in ids if i not in by_index]
    if unknown:
        raise BadInputError(f"{scan_dir / 'scan.json'} has frames for lights {unknown} that its "
                            "'lights' list does not describe")
    notes = list(stale_lights(scan_dir, data).values())
    absent = [i for i in ids if not all((scan_dir / "hdr" / f"light_{i:02d}{x}.exr").is_file()
                                        for x in ("", "_var"))]
    if data.frames:
        # merges only the lights whose HDR is missing or no longer matches its RAW frames or
        # was changed since (nothing after a scan merged during acquisition); under the
        # directory's lock when it will write (one writer: not while a scan runs)
        sd = ScanDirectory(scan_dir)
        if notes or absent:
            try:
                sd.lock()
            except OSError as exc:       # read-only disk or folder: the scan, not the output
                why = (f"lights {absent} have no HDR image in hdr/" if absent else "; ".join(notes[:2]))
                raise BadInputError(f"the scan {scan_dir} cannot be written ({exc.strerror}) and its HDR images must "
                                    f"be merged first: {why}",
                                    hint="copy the scan to a disk you can write to (or make it writable), then "
                                         "process the copy") from exc
        try:
            with warnings.catch_warnings():           # an incomplete scan is said once, not per light
                warnings.simplefilter("ignore", MissingFrameWarning)
                merge_scan(scan_dir)
        finally:
            sd.unlock()
    return ids, [by_index[i] for i in ids], notes


def scan_manifest(scan_dir, allow_incomplete=False):
    """(scan.json's manifest, complete): BadInputError for a scan being acquired or incomplete
    unless `allow_incomplete`."""
    data = ScanDirectory(scan_dir).manifest      # a damaged scan.json is named (BadInputError)
    expected = data.n_planned
    # every (light, exposure) of the plan has a frame (scan.json's own "complete" flag is not
    # set by every writer: a scan.json made by hand or by a tool has frames but no flag)
    complete = len({(f.light, f.exposure) for f in data.frames}) >= expected
    busy = None if complete else ScanDirectory(scan_dir).writer()
    if busy and not allow_incomplete:
        raise BadInputError(f"the scan {scan_dir} is being acquired by another facette process ({busy}): "
                            f"{len(data.frames)} of {expected} frames so far",
                            hint="wait for the scan to finish, then process it (or pass --allow-incomplete "
                                 "to process what is there now)")
    if not complete and not allow_incomplete:
        raise BadInputError(f"the scan is incomplete ({len(data.frames)} of {expected} frames in "
                            f"{scan_dir}): run the same scan command to resume",
                            hint="or pass --allow-incomplete to process what is there (every output "
                                 "then says so)")
    return data, complete


def scan_lights(scan_dir, data, lights):
    """(directions (m, 3), intensities (m, 3) times the radiometric scale, positions (m, 3) or
    None, notes) of the scan's lights (`merged_lights`)."""
    dirs = np.array([l.direction for l in lights], dtype=np.float64)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    inten = np.array([l.intensity or [1.0, 1.0, 1.0] for l in lights], dtype=np.float64)
    if np.any(inten <= 0):
        raise ValueError(f"{scan_dir / 'scan.json'}: a light has a non-positive intensity; "
                         "fix the calibration profile")
    scale = data.radiometric_scale
    if scale is not None:   # the Spectralon's absolute scale: images become radiance factors
        inten = inten * np.asarray(scale, dtype=np.float64)[None, :]
    pos = [l.position_mm for l in lights]
    positions = np.array(pos, dtype=np.float64) if all(p is not None for p in pos) else None
    below = [int(l.index) for k, l in enumerate(lights)
             if dirs[k, 2] < 0 or (positions is not None and positions[k, 2] < 0)]
    notes = []
    if below:    # a profile measured wrong (or a light's sign flipped): said, not silently fitted
        notes.append(f"light(s) {below} of scan.json lie below the horizon (z < 0 in the calibration "
                     "profile's directions or positions): no such light can light a surface the camera "
                     "sees, and the normals fitted with it err; check the profile (facette calibrate)")
    return dirs, inten, positions, notes


def _load_scan(scan_dir, pixel_pitch_mm, allow_incomplete=False, take_held=None):
    data, complete = scan_manifest(scan_dir, allow_incomplete)
    images, usable, lights, hdr_notes = _load_hdr_images(scan_dir, data, take_held)
    dirs, inten, positions, light_notes = scan_lights(scan_dir, data, lights)
    m, h, w, c = images.shape
    if images.flags.c_contiguous:   # a light's row as one (W·3) run: 7x faster than broadcasting (..., 3)
        rows = images.reshape(m, h, w * c)                       # a view
        for k in range(m):
            rows[k] /= np.tile(inten[k].astype(np.float32), w)
    else:
        images /= inten[:, None, None, :].astype(np.float32)
    profile_pitch, profile_notes = _apply_profile(images, data, scan_dir)
    mask, material = auto_masks(images)
    # the object: the lit pixels and those saturated under some light (which auto_masks, blind
    # to unknown values, leaves out)
    obj = mask | np.isnan(images[..., 1]).any(axis=0)
    return scan_input(scan_dir, data, complete, images, dirs, positions, mask, material, usable, obj,
                      pixel_pitch_mm or profile_pitch, hdr_notes, light_notes, profile_notes)


def scan_input(scan_dir, data, complete, images, dirs, positions, mask, material, usable, obj, pitch,
               hdr_notes, light_notes, profile_notes):
    """The `PSInput` of a scan from its parts (images may be None: read band by band)."""
    # the merge may have just run: its record (sensor used) is in scan.json as it is now
    hdr = ScanDirectory(scan_dir).manifest.hdr
    sensor_source = (hdr.sensor_source if hdr is not None else None) or ""
    hdr_notes = list(hdr_notes)
    if sensor_source.startswith("nominal"):
        hdr_notes.append(f"HDR merged with the {sensor_source}")
    hdr_notes.extend(light_notes)
    if not pitch:
        raise ValueError(f"{scan_dir / 'scan.json'} gives no pixel_pitch_mm; pass pixel_pitch_mm=")
    truth = None
    if data.truth and (scan_dir / data.truth).is_file():
        with np.load(scan_dir / data.truth, allow_pickle=False) as z:
            truth = {k: z[k] for k in z.files}
    inp = PSInput(images, dirs, positions, mask, float(pitch), "scan", scan_dir, truth,
                  material_mask=material, usable=usable, object_mask=obj)
    expected = data.n_planned
    if not complete:
        inp.incomplete = f"{len(data.frames)} of {expected or '?'} frames"
    inp.digest = _digest(sorted((f.file, "" if "sha256" in f.absent else f.sha256) for f in data.frames))
    inp.notes.extend(profile_notes)
    inp.notes.extend(hdr_notes)
    if data.radiometric_scale is None:
        inp.notes.append("no radiometric scale in scan.json (profile without a Spectralon step): "
                         "albedo and BRDF values are relative, K_d is not a reflectance")
    return inp


def _digest(items):
    import hashlib

    return hashlib.sha256(repr(items).encode()).hexdigest()[:16]


def _file_stamps(folder):
    """(name, size, mtime_ns) of every file in a folder: what a DiLiGenT folder's images were."""
    return sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in Path(folder).iterdir()
                  if p.is_file())


def _apply_profile(images, data, scan_dir):
    """`profile_flat` applied to `images` (m, H, W, 3), in place; returns (pixel_pitch_mm or
    None, notes)."""
    pitch, notes, flat = profile_flat(data, scan_dir, (images.shape[2], images.shape[1]))
    if flat is not None:
        images[0] = apply_flat_field(images[0], flat)      # checks the field
        with ThreadPoolExecutor(2) as pool:        # in place (no full-size copy), on both cores
            list(pool.map(lambda k: np.divide(images[k], flat, out=images[k]), range(1, images.shape[0])))
    return pitch, notes


def profile_flat(data, scan_dir, size):
    """The calibration profile the scan was taken with (the manifest's profile: id, sha256,
    path, and the image size it was measured at) at the images' size (W, H): its flat field,
    resampled if the scan reads the sensor at another resolution, to divide the images by, and
    the pixel pitch at this size.

    Returns (pixel_pitch_mm or None, notes, flat field (H, W, 3) float32 or None). Raises
    ResolutionError (naming both sizes) when the scan's size cannot be another resolution of
    the profile's camera setting."""
    ref = data.profile
    pitch = data.pixel_pitch_mm
    size = tuple(size)
    if not ref:
        return pitch, ["no calibration profile recorded: no flat-field correction"], None
    profile, why = None, None
    if ref.get("path"):
        try:
            profile = load(ref["path"])
        except ProfileError as exc:
            why = f"the scan's profile could not be read ({exc})"
        else:
            if profile.sha256 != ref.get("sha256"):
                why = (f"{ref['path']} changed since the scan (checksum {profile.sha256[:12]} != "
                       f"{str(ref.get('sha256'))[:12]})")
                profile = None
    measured = ref.get("image_size_px") or (profile.measured_size() if profile else None)
    notes = []
    if pitch and measured and tuple(measured) != size:
        try:
            pitch = pitch_at_size(pitch, measured, size, f"profile {ref.get('id')}")
        except ResolutionError as exc:
            raise ResolutionError(f"{scan_dir}: {exc}") from None
        notes.append(f"pixel pitch scaled from the profile's {measured[0]}×{measured[1]} px to "
                     f"{size[0]}×{size[1]} px: {pitch:.5g} mm")
    elif pitch and not measured:
        notes.append(f"profile {ref.get('id')} records no image size: its pixel pitch is used "
                     "as measured")
    if profile is None:
        notes.append(f"flat field not applied: {why or 'no profile path recorded'}")
        return pitch, notes, None
    if profile.flat_field is None:
        notes.append(f"profile {profile.id} has no flat field: no flat-field correction")
        return pitch, notes, None
    at = profile.at_size(size)
    notes.append(f"flat field of profile {profile.id} applied"
                 + ("" if at.flat_field is profile.flat_field else
                    f" (resampled from {measured[0]}×{measured[1]} px)"))
    return pitch, notes, np.asarray(at.flat_field, np.float32)


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
        inp = _load_scan(path, pixel_pitch_mm, allow_incomplete, take_held)
        if inp.incomplete:
            inp.notes.insert(0, f"the scan is incomplete ({inp.incomplete}): these results come from "
                                "part of its data; run the same scan command to resume it")
    elif is_diligent_dir(path):
        d = read_diligent(path)
        with np.errstate(invalid="ignore"):
            levels = d.images[..., 1] * (d.light_intensities[:, 1] * (2.0 ** d.bit_depth - 1))[:, None, None]
        usable = np.isfinite(levels) & (levels >= MIN_LEVELS)
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
