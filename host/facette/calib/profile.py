"""Rig calibration profiles: versioned, checksummed JSON (never pickle).

A profile lives in a folder ``calibration/profiles/<rig>/`` as ``profile.json``,
with optional array files beside it (the flat field as EXR), each referenced by
name and sha256 so a profile that was edited or half-copied is refused on load.

Schema 1::

    {"schema": 1, "id": str, "rig": str, "created": ISO-8601 str,
     "pixel_pitch_mm": float | null,          # on the object, at the HDR resolution
     "image_size_px": [w, h] | null,           # the HDR grid it was measured at (optional:
                                               # older profiles give it by their flat field)
     "binning": int | null,                    # RAW photosites per HDR pixel side (2: half-size)
     "lights": [{"index": int, "direction": [x, y, z],   # unit, camera frame (docs/conventions.md)
                 "intensity": [r, g, b],                 # relative, mean over LEDs = 1
                 "position_mm": [x, y, z] | null}],      # near-light model, or null
     "sensor": {"gain_e_per_dn", "read_noise_e", "dark_current_e_per_s",
                "black_level_dn", "white_level_dn"} | null,
     "flat_field": {"file": str, "sha256": str} | null,  # EXR, R,G,B, mean 1
     "led_gains": [float, ...] | null,                   # written to the device store
     "radiometric_scale": [r, g, b] | null,  # HDR units per unit irradiance (Spectralon);
                                             # images / (scale · intensity) are radiance factors
     "history": [str, ...],                              # what the wizard did
     "checksum": sha256 of the canonical JSON of everything else}
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import hashlib
import json
from pathlib import Path

import numpy as np

from facette.camera.sensor import SENSOR_KEYS
from facette.errors import BadInputError
from facette.io.checksum import sha256_file
from facette.io.exr import read_exr, write_exr

__all__ = ["Profile", "Lights", "load", "save", "nominal_light_directions", "SCHEMA_VERSION",
           "ProfileError", "ResolutionError", "AtSize", "pitch_at_size"]

SCHEMA_VERSION = 1
PROFILE_FILE = "profile.json"


class ProfileError(BadInputError):
    """A profile file is missing, malformed, or does not match its checksum."""


class ResolutionError(ProfileError):
    """A scan's image size cannot be reconciled with the size a profile was measured at."""


# Relative slack on the field of view: the sizes of one sensor differ by a few rows.
_FIELD_TOLERANCE = 0.01


def _scale(size_from, size_to, what):
    """Profile pixels per scan pixel for a scan of `size_to` (w, h) against a profile measured
    at `size_from` (w, h): another resolution of the same sensor keeps its width (2×2 or
    other binning; the simulator's --raw-size), and may show fewer rows of it (a centred
    crop for another aspect ratio), never more."""
    (wf, hf), (wt, ht) = (int(v) for v in size_from), (int(v) for v in size_to)
    if min(wf, hf, wt, ht) <= 0:
        raise ResolutionError(f"image sizes must be positive, got {wf}×{hf} and {wt}×{ht}")
    s = wf / wt
    if ht * s > hf * (1 + _FIELD_TOLERANCE):
        raise ResolutionError(
            f"{what} was measured on images of {wf}×{hf} px; this scan's are {wt}×{ht} px, which "
            f"at the same width would reach {ht * s / hf:.2f}× the calibrated field's height: not "
            "another resolution of the same camera setting. Recalibrate at this size "
            f"(facette calibrate with the camera at {wt}×{ht} px half-size) or scan at the "
            "profile's aspect ratio")
    return s


def pitch_at_size(pixel_pitch_mm, size_from, size_to, what="the profile"):
    """The pixel pitch (mm) of a scan of `size_to` (w, h) from one measured at `size_from`.

    Raises ResolutionError (naming both sizes) when the sizes cannot be the same sensor."""
    return float(pixel_pitch_mm) * _scale(size_from, size_to, what)


def _resample(field, size_from, size_to):
    """Bilinear resampling of a (h, w, 3) field measured at `size_from` onto `size_to` (w, h),
    centred (the rows a crop keeps are the middle ones); values at the borders are held."""
    s = _scale(size_from, size_to, "the flat field")
    wt, ht = (int(v) for v in size_to)
    hf, wf = field.shape[:2]
    xs = np.clip((np.arange(wt) + 0.5) * s - 0.5, 0, wf - 1)
    ys = np.clip((np.arange(ht) + 0.5 - ht / 2) * s + hf / 2 - 0.5, 0, hf - 1)
    x0, y0 = xs.astype(int), ys.astype(int)
    x1, y1 = np.minimum(x0 + 1, wf - 1), np.minimum(y0 + 1, hf - 1)
    fx = (xs - x0).astype(np.float32)[None, :, None]
    fy = (ys - y0).astype(np.float32)[:, None, None]
    f = np.asarray(field, np.float32)
    rows = f[:, x0] * (1 - fx) + f[:, x1] * fx      # along x on the measured rows: (hf, wt, 3)
    out = rows[y0] * (1 - fy) + rows[y1] * fy       # then along y (the same values as 2-D indexing)
    return out / np.float32(out.mean())   # a flat field has mean 1


@dataclasses.dataclass
class AtSize:
    """What a profile gives a scan of one image size: pixel_pitch_mm (or None), flat_field
    (h, w, 3) or None, and a note saying what was scaled or resampled."""
    pixel_pitch_mm: float | None
    flat_field: np.ndarray | None
    note: str


def nominal_light_directions():
    """The thesis rig's 12 LED directions (thesis §4.3.2), shape (12, 3), camera frame.

    Two alternating rings ordered by azimuth φ = 0°, 30°, …, 330°: zenith θ = 30°
    at φ = 0°, 60°, …, 300° and θ = 15° at φ = 30°, 90°, …, 330°, so that
    neighbouring LEDs never form an ill-conditioned triplet.
    """
    phi = np.deg2rad(np.arange(12) * 30.0)
    theta = np.deg2rad(np.where(np.arange(12) % 2 == 0, 30.0, 15.0))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)


@dataclasses.dataclass
class Lights:
    """Per-LED calibration. directions (m, 3) unit vectors; intensities (m, 3) per
    channel, relative; positions_mm (m, 3) or None when lights are distant."""
    directions: np.ndarray
    intensities: np.ndarray
    positions_mm: np.ndarray | None = None

    def __post_init__(self):
        self.directions = np.asarray(self.directions, dtype=np.float64)
        m = len(self.directions)
        if self.directions.shape != (m, 3) or m == 0:
            raise ProfileError(f"light directions must have shape (m, 3), got {self.directions.shape}")
        norms = np.linalg.norm(self.directions, axis=1)
        if not np.all(np.isfinite(norms)) or np.any(np.abs(norms - 1) > 1e-6):
            raise ProfileError("light directions must be finite unit vectors; "
                               f"norms are {np.round(norms, 6).tolist()}")
        self.intensities = np.asarray(self.intensities, dtype=np.float64)
        if self.intensities.shape != (m, 3):
            raise ProfileError(f"light intensities must have shape ({m}, 3) for {m} lights; "
                               f"got shape {self.intensities.shape}")
        if not np.all(self.intensities > 0):
            bad = sorted({int(i) for i in np.argwhere(~(self.intensities > 0))[:, 0]})
            raise ProfileError(f"light intensities must be positive; light(s) {bad} have "
                               f"{self.intensities[bad[0]].tolist()}")
        if self.positions_mm is not None:
            self.positions_mm = np.asarray(self.positions_mm, dtype=np.float64)
            if self.positions_mm.shape != (m, 3):
                raise ProfileError(f"light positions must have shape ({m}, 3)")

    def __len__(self):
        return len(self.directions)


@dataclasses.dataclass
class Profile:
    """A rig calibration. See the module docstring for the file format."""
    rig: str
    lights: Lights
    id: str = ""
    created: str = ""
    pixel_pitch_mm: float | None = None
    sensor: dict | None = None
    flat_field: np.ndarray | None = None   # (H, W, 3), mean 1, or None
    led_gains: list | None = None
    radiometric_scale: list | None = None   # (3,) see the module docstring; None: relative only
    image_size_px: tuple | None = None      # (w, h) of the HDR images it was measured at
    binning: int | None = None              # RAW photosites per HDR pixel side (2: half-size)
    history: list = dataclasses.field(default_factory=list)
    sha256: str = ""                        # checksum of the file it was loaded from
    path: Path | None = None

    def __post_init__(self):
        if self.radiometric_scale is not None:
            sc = np.asarray(self.radiometric_scale, dtype=float)
            if sc.shape != (3,) or not np.all(np.isfinite(sc) & (sc > 0)):
                raise ProfileError(f"radiometric_scale must be three positive numbers, got {self.radiometric_scale}")
            self.radiometric_scale = sc.tolist()
        if self.sensor is not None:
            missing = [k for k in SENSOR_KEYS if k not in self.sensor]
            if missing:
                raise ProfileError(f"sensor section lacks {missing}")
        if self.image_size_px is not None:
            size = tuple(int(v) for v in self.image_size_px)
            if len(size) != 2 or min(size) <= 0:
                raise ProfileError(f"image_size_px must be [width, height] > 0, got {self.image_size_px}")
            self.image_size_px = size
        if self.flat_field is not None and self.measured_size() != self.flat_field.shape[1::-1]:
            raise ProfileError(f"the flat field is {self.flat_field.shape[1]}×{self.flat_field.shape[0]} px "
                               f"but the profile says it was measured at {self.image_size_px[0]}×"
                               f"{self.image_size_px[1]} px")

    def measured_size(self):
        """(w, h) of the HDR images the profile was measured at (its flat field's size when the
        profile predates the image_size_px field), or None when unknown."""
        if self.image_size_px is not None:
            return tuple(self.image_size_px)
        if self.flat_field is not None:
            return (int(self.flat_field.shape[1]), int(self.flat_field.shape[0]))
        return None

    def at_size(self, size):
        """The pixel pitch and flat field for HDR images of `size` (w, h): scaled and resampled
        when the scan reads the same sensor at another resolution (see `pitch_at_size`).

        Raises ResolutionError naming both sizes when they cannot be reconciled. A profile
        that records no size gives its values unchanged, with a note saying so."""
        size = (int(size[0]), int(size[1]))
        base = self.measured_size()
        if base is None:
            return AtSize(self.pixel_pitch_mm, None, f"profile {self.id} records no image size: "
                          "its pixel pitch is used as measured (recalibrate to record it)")
        if base == size:
            return AtSize(self.pixel_pitch_mm, self.flat_field, f"profile {self.id} measured at this size")
        what = f"profile {self.id}"
        pitch = None if self.pixel_pitch_mm is None else pitch_at_size(self.pixel_pitch_mm, base, size, what)
        flat = None if self.flat_field is None else _resample(self.flat_field, base, size)
        if pitch is None:
            _scale(base, size, what)   # the same check without a pitch
        return AtSize(pitch, flat, f"profile {self.id} measured at {base[0]}×{base[1]} px, scan at "
                      f"{size[0]}×{size[1]} px: pixel pitch ×{base[0] / size[0]:.4g}"
                      + (", flat field resampled" if flat is not None else ""))

    def to_dict(self, flat_field_ref=None):
        lights = [{"index": i, "direction": self.lights.directions[i].tolist(),
                   "intensity": self.lights.intensities[i].tolist(),
                   "position_mm": None if self.lights.positions_mm is None
                   else self.lights.positions_mm[i].tolist()} for i in range(len(self.lights))]
        return {"schema": SCHEMA_VERSION, "id": self.id, "rig": self.rig, "created": self.created,
                "pixel_pitch_mm": self.pixel_pitch_mm, "lights": lights, "sensor": self.sensor,
                "flat_field": flat_field_ref, "led_gains": self.led_gains,
                "radiometric_scale": self.radiometric_scale,
                "image_size_px": None if self.measured_size() is None else list(self.measured_size()),
                "binning": self.binning, "history": list(self.history)}


def _canonical(data):
    return json.dumps(data, sort_keys=True, separators=(",", ":")).encode()


def _checksum(data):
    return hashlib.sha256(_canonical({k: v for k, v in data.items() if k != "checksum"})).hexdigest()


def save(profile, folder, keep_previous=True):
    """Write `profile` to ``folder/profile.json`` (and ``flat_field.exr``).

    An existing profile is renamed ``profile-<its id>.json`` first, so the wizard
    never loses the previous calibration. Returns the path written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if not profile.created:
        profile.created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    if not profile.id:
        profile.id = f"{profile.rig}-{profile.created.replace(':', '').replace('+0000', 'Z')}"
    target = folder / PROFILE_FILE
    if keep_previous and target.exists():
        try:
            old_id = json.loads(target.read_text()).get("id") or "unknown"
        except ValueError:
            old_id = "unreadable"
        backup = folder / f"profile-{old_id}.json"
        n = 1
        while backup.exists():
            backup, n = folder / f"profile-{old_id}-{n}.json", n + 1
        target.replace(backup)
    ref = None
    if profile.flat_field is not None:
        ff_name = f"flat_field-{profile.id}.exr"
        write_exr(folder / ff_name, profile.flat_field, channels=("R", "G", "B"))
        ref = {"file": ff_name, "sha256": sha256_file(folder / ff_name)}
    data = profile.to_dict(flat_field_ref=ref)
    data["checksum"] = _checksum(data)
    tmp = target.with_suffix(".json.partial")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(target)
    profile.sha256, profile.path = data["checksum"], target
    return target


def load(path):
    """Load a profile from a folder (its ``profile.json``) or a JSON file path.

    Raises ProfileError saying what is wrong when the file is missing, not JSON,
    of another schema version, or does not match its checksum.
    """
    path = Path(path)
    file = path / PROFILE_FILE if path.is_dir() else path
    if not file.is_file():
        raise ProfileError(f"no calibration profile at {file}; run `facette calibrate` "
                           "or give the folder of an existing profile")
    try:
        data = json.loads(file.read_text())
    except ValueError as exc:
        raise ProfileError(f"{file} is not valid JSON ({exc}); restore the previous profile "
                           "(profile-<id>.json beside it) or recalibrate") from exc
    if not isinstance(data, dict) or data.get("schema") != SCHEMA_VERSION:
        raise ProfileError(f"{file} has schema {data.get('schema') if isinstance(data, dict) else '?'}, "
                           f"this facette reads schema {SCHEMA_VERSION}")
    if data.get("checksum") != _checksum(data):
        raise ProfileError(f"{file} does not match its checksum: it was edited or damaged; "
                           "recalibrate, or restore the previous profile beside it")
    missing = [k for k in ("rig", "id", "created", "lights") if k not in data]
    if missing:
        raise ProfileError(f"{file} lacks {', '.join(missing)}: it is not a complete profile; "
                           "recalibrate, or restore the previous profile beside it")
    try:
        lights = data["lights"]
        positions = [l["position_mm"] for l in lights]
        lt = Lights(directions=[l["direction"] for l in lights],
                    intensities=[l["intensity"] for l in lights],
                    positions_mm=None if any(p is None for p in positions) else positions)
    except (KeyError, TypeError) as exc:
        raise ProfileError(f"{file}: malformed lights section (no {exc} in a light)") from exc
    except ProfileError as exc:
        raise ProfileError(f"{file}: {exc}") from exc
    flat = None
    if data.get("flat_field"):
        ff = file.parent / data["flat_field"]["file"]
        if not ff.is_file() or sha256_file(ff) != data["flat_field"]["sha256"]:
            raise ProfileError(f"flat field {ff} is missing or does not match the profile's checksum")
        flat, _ = read_exr(ff, channels=("R", "G", "B"))
    return Profile(rig=data["rig"], lights=lt, id=data["id"], created=data["created"],
                   pixel_pitch_mm=data.get("pixel_pitch_mm"), sensor=data.get("sensor"),
                   flat_field=flat, led_gains=data.get("led_gains"),
                   radiometric_scale=data.get("radiometric_scale"),
                   image_size_px=data.get("image_size_px"), binning=data.get("binning"),
                   history=list(data.get("history", [])), sha256=data["checksum"], path=file)
