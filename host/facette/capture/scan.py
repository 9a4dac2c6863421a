"""A facette scan directory as a capture: hdr/ read (merged again where needed), whole
(`load_scan`) or a window of scanlines at a time (`ScanBands`), the lights, the calibration
profile (flat field, pixel pitch), the masks; in pieces that the band-by-band reading of
`process --memory` (pipeline._tiled_process) shares."""
import warnings
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from facette.calib import ProfileError, ResolutionError, apply_flat_field, load, pitch_at_size
from facette.errors import BadInputError
from facette.io.lights import check_lights
from facette.capture.base import Bands, PSInput, _digest
from facette.capture.masks import auto_masks
from facette.capture.usable import usable_from_green
from facette.scan import MissingFrameWarning, ScanDirectory, merge_scan, stale_lights

__all__ = ["ScanBands", "divide_intensities", "load_scan", "merged_lights", "scan_manifest", "scan_lights", "scan_input", "profile_flat"]


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
    ids, notes = _lights_checked(ids, by_index, notes)
    return ids, [by_index[i] for i in ids], notes


def _lights_checked(ids, by_index, notes):
    """The frames' lights after the checks every capture's lights pass (`io.lights.check_lights`):
    those below the horizon (a direction or a position with z < 0: a profile measured wrong or a
    sign flipped) left out, said; (ids kept, notes)."""
    if len(ids) < 3:      # a scan stopped early: photometric stereo says how many it needs (exit 3)
        return list(ids), notes
    dirs = np.array([by_index[i].direction for i in ids], dtype=np.float64).reshape(-1, 3)
    for k, i in enumerate(ids):
        pos = by_index[i].position_mm
        if pos is not None and pos[2] < 0 <= dirs[k, 2]:
            dirs[k, 2] = -max(abs(dirs[k, 2]), 1e-6)      # the light's position is below: so is the light
    keep, light_notes = check_lights(dirs, "scan.json (the calibration profile's lights)",
                                     [f"light {i}" for i in ids])
    if len(keep) < len(ids):
        light_notes = [n + "; check the profile (facette calibrate)" for n in light_notes]
    return [ids[k] for k in keep], notes + light_notes


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
                            hint="wait for the scan command to end (its lock is held until then), then run "
                                 "this command again")
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
    return dirs, inten, positions, []      # checked, those below the horizon left out: `merged_lights`


def load_scan(scan_dir, pixel_pitch_mm, allow_incomplete=False, take_held=None, prepared=None):
    data, complete = scan_manifest(scan_dir, allow_incomplete)
    # prepared: the images made as the one-button scan's lights arrived (pipeline._arriving), when they still hold
    got = None if prepared is None else prepared.stacks(scan_dir, data)
    if got is not None:
        images, usable, lights, hdr_notes, (profile_pitch, profile_notes) = got
        dirs, inten, positions, light_notes = scan_lights(scan_dir, data, lights)
    else:
        images, usable, lights, hdr_notes = _load_hdr_images(scan_dir, data, take_held)
        dirs, inten, positions, light_notes = scan_lights(scan_dir, data, lights)
        divide_intensities(images, inten)
        profile_pitch, profile_notes = _apply_profile(images, data, scan_dir)
    mask, material = auto_masks(images)
    # the object: the lit pixels and those saturated under some light (which auto_masks, blind
    # to unknown values, leaves out)
    obj = mask | np.isnan(images[..., 1]).any(axis=0)
    return scan_input(scan_dir, data, complete, images, dirs, positions, mask, material, usable, obj,
                      pixel_pitch_mm or profile_pitch, hdr_notes, light_notes, profile_notes)


def divide_intensities(images, inten):
    """images (m, H, W, 3) /= each light's intensity (m, 3), in place (also one light's stack, [k:k + 1])."""
    m, h, w, c = images.shape
    if images.flags.c_contiguous:   # a light's row as one (W·3) run: 7x faster than broadcasting (..., 3)
        rows = images.reshape(m, h, w * c)                       # a view
        for k in range(m):
            rows[k] /= np.tile(inten[k].astype(np.float32), w)
    else:
        images /= inten[:, None, None, :].astype(np.float32)


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
    inp.reflectance = data.radiometric_scale is not None
    if data.radiometric_scale is None:
        inp.notes.append("no radiometric scale in scan.json (profile without a Spectralon step): "
                         "albedo and BRDF values are relative, K_d is not a reflectance")
    return inp


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


class ScanBands(Bands):
    """A scan's HDR images (hdr/light_XX.exr and _var.exr), read a band of scanlines at a time,
    as `_scan_input._read_hdr_fast` then `load_scan` make them: NaN where the variance is not
    finite, `usable` from the green channel before the light's intensity is divided out, then
    divided by the intensity and the flat field."""

    def __init__(self, scan_dir, ids, inten, flat=None):
        import Imath
        import OpenEXR
        self.scan_dir, self.ids = Path(scan_dir), list(ids)
        self.paths = [(self.scan_dir / "hdr" / f"light_{i:02d}.exr", self.scan_dir / "hdr" / f"light_{i:02d}_var.exr")
                      for i in self.ids]
        self.inten = np.asarray(inten, np.float64)
        self.flat = flat
        self.float = Imath.PixelType(Imath.PixelType.FLOAT)
        self.files, self.windows = [], []
        try:
            for img, var in self.paths:
                pair = []
                for path in (img, var):
                    if path is var and not var.is_file():
                        pair.append(None)      # radiance without its variance (made elsewhere): no noise
                        continue
                    f = OpenEXR.InputFile(str(path))
                    box = f.header()["dataWindow"]
                    pair.append(f)
                    self.windows.append((box.min.x, box.min.y, box.max.x - box.min.x + 1, box.max.y - box.min.y + 1))
                self.files.append(pair)
        except Exception as exc:
            self.close()
            raise ValueError(f"{path}: cannot read this HDR image ({exc}); delete {path.parent} to merge it "
                             "again from raw/, or rescan that light") from exc
        if len(set(self.windows)) != 1:
            self.close()
            raise ValueError(f"the HDR images of {self.scan_dir / 'hdr'} differ in size: merge them again")
        self.x0, self.y0, self.w, self.h = self.windows[0]

    def spec(self):
        """What a task needs to open the same reader (`open_bands`), flat field apart."""
        return ("scan", str(self.scan_dir), self.ids, self.inten.tolist())

    def close(self):
        for pair in self.files:
            for f in pair:
                if f is not None:
                    f.close()
        self.files = []

    def _channels(self, f, r0, r1):
        y = self.y0
        raw = f.channels(["R", "G", "B"], self.float, y + r0, y + r1 - 1)
        return [np.frombuffer(b, np.float32).reshape(r1 - r0, self.w) for b in raw]

    def read(self, r0, r1, flat=None):
        """(images (m, r1 - r0, W, 3) float32, usable (m, r1 - r0, W) bool) of rows r0..r1;
        flat: the flat field's rows r0..r1 (default this reader's own, if any)."""
        if flat is None and self.flat is not None:
            flat = self.flat[r0:r1]
        m, b, w = len(self.paths), r1 - r0, self.w
        images = np.empty((m, b, w, 3), np.float32)
        usable = np.empty((m, b, w), bool)
        for k, (f_img, f_var) in enumerate(self.files):
            for c, ch in enumerate(self._channels(f_img, r0, r1)):
                images[k, :, :, c] = ch
            if f_var is None:
                images[k][~np.isfinite(images[k]).all(axis=-1)] = np.nan
                usable[k] = np.isfinite(images[k][..., 1]) & (images[k][..., 1] > 0)
            else:
                v = self._channels(f_var, r0, r1)
                bad = ~(np.isfinite(v[0]) & np.isfinite(v[1]) & np.isfinite(v[2]))
                fin = np.isfinite(images[k])
                wild = ~(fin[..., 0] | fin[..., 1] | fin[..., 2]) & ~bad
                if wild.any():
                    raise ValueError(f"{self.paths[k][0]} has {int(wild.sum())} non-finite values (Inf or NaN) "
                                     f"where its variance is finite: the file is damaged; delete it: processing "
                                     "merges it again from raw/")
                images[k][bad] = np.nan
                usable[k] = usable_from_green(images[k][..., 1], np.ascontiguousarray(v[1]))
            images[k] /= self.inten[k].astype(np.float32)
            if flat is not None:
                np.divide(images[k], flat, out=images[k])
        return images, usable
