"""scan.json's contents: the `Manifest` and its typed records (`Light`, `Exposure`, `Frame`,
`HdrLight`, `Hdr`).

The format, every key with its unit and the version history, is `docs/scan-format.md`.
`facette.scan.ScanDirectory` (scan/directory.py) is the only reader and writer of the file;
the `Manifest` owns what is in it: set only through its methods (the plan, the frames, the
HDR merge, the completion), read through its attributes. Each record is a frozen dataclass
read with ``from_json`` and written with ``to_json``: a record written by facette comes back
byte for byte; a key a record does not know is kept (``extra``) and a key it knows but was
absent (a scan.json made by a tool) stays absent (``absent``; its attribute reads None or
empty). An older scan.json is migrated on read (`Manifest.from_dict`) and written back in this
version the next time the scan directory saves it.

Schema 2 (every top-level key present)::

    {"schema": 2,
     "created": ISO-8601 str,                  # UTC, ms; when the scan directory was made
     "rig": {...},                             # the device's identity (`Rig.identity`)
     "profile": {"id", "sha256", "path",       # the calibration profile, or null
                 "image_size_px": [w, h] | null} | null,
     "pixel_pitch_mm": float | null,           # mm per HDR (half-size) pixel on the object
     "lights": [Light],                        # {"index", "channel", "direction", "position_mm",
                                               #  "intensity"}: scan order; unit, camera frame
     "exposures": [Exposure],                  # {"index", "time_us", "current_mA", "mode"}
     "plan": {"lights", "exposures", "light_current_mA", "mode", "retries", "timing"} | null,
     "bracketing": {"name": "thesis2016" | "explicit" | "adaptive", ...} | null,
     "sensor": {SENSOR_KEYS...} | null,        # the profile's noise model, for the HDR merge
     "radiometric_scale": [r, g, b] | null,    # HDR units per unit irradiance (Spectralon)
     "frames": [Frame],                        # {"file", "light", "exposure", "time_us",
                                               #  "current_set_mA", "current_meas_mA", "start_us",
                                               #  "sync", "retry", "run", "ring", "sha256"},
                                               #  sorted (light, exposure)
     "runs": int,                              # device runs started
     "rig_time_s": float,                      # device time, metering included
     "hdr": Hdr | null,                        # the HDR merge: {"method", "unit", "current",
                                               #  "resolution", "sensor", "sensor_source",
                                               #  "lights": [HdrLight], "merge_time_s", "created"}
     "complete": bool,                         # every frame of the plan taken
     "truth": "truth.npz" | null,              # the simulator's truth, beside scan.json
     "faults_seen": [journal entries]}         # device resets, missed syncs, stray files...

Version 1 (facette until issue 27) wrote the same keys, but "sensor", "radiometric_scale",
"bracketing", "runs", "hdr" and "faults_seen" only once known, and scan.json files made by
tools lacked "plan", "complete", "created" and "truth"; version 2 writes every key.
"""
from __future__ import annotations

import copy
import dataclasses
import datetime as _dt

__all__ = ["Manifest", "Light", "Exposure", "Frame", "HdrLight", "Hdr", "SCHEMA"]

SCHEMA = 2


def _now():
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="milliseconds")


def _frozen(value):
    """A JSON list as a tuple (the records are frozen); anything else as it is."""
    return tuple(value) if isinstance(value, list) else value


def _plain(value):
    """A record's value as JSON: tuples as lists, records as their JSON objects."""
    if isinstance(value, _Record):
        return value.to_json()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


class _Record:
    """What every scan.json record shares: `from_json` (ValueError naming `where` when a
    required key is missing), `to_json` (the keys in their documented order, then the unknown
    ones), and the record's own `replace`."""
    _WHAT = "record"
    _REQUIRED = ()
    _NESTED = {}     # key -> record class of its value (or of each item of its list)

    @classmethod
    def _keys(cls):
        return [f.name for f in dataclasses.fields(cls) if f.name not in ("extra", "absent")]

    @classmethod
    def from_json(cls, data, where="scan.json"):
        """The record of a JSON object (a record is returned as it is)."""
        if isinstance(data, cls):
            return data
        if not isinstance(data, dict):
            raise ValueError(f"{where} is damaged: a {cls._WHAT} record is {type(data).__name__}, not an object")
        lacking = [k for k in cls._REQUIRED if k not in data]
        if lacking:
            raise ValueError(f"{where} is damaged: a {cls._WHAT} record lacks {lacking}: {str(data)[:120]}")
        keys = cls._keys()
        fields = {}
        for k in keys:
            if k not in data:
                continue
            v, nested = data[k], cls._NESTED.get(k)
            if nested is not None and isinstance(v, list):
                v = tuple(nested.from_json(x, where) for x in v)
            elif nested is not None and v is not None:
                v = nested.from_json(v, where)
            fields[k] = _frozen(v)
        return cls(**fields, extra={k: v for k, v in data.items() if k not in keys},
                   absent=frozenset(k for k in keys if k not in data))

    def to_json(self):
        """The record's JSON object, as scan.json holds it."""
        out = {k: _plain(getattr(self, k)) for k in self._keys() if k not in self.absent}
        out.update(self.extra)
        return out

    def replace(self, **changes):
        """A copy with these keys set (and so no longer absent)."""
        return dataclasses.replace(self, absent=self.absent - set(changes), **changes)


def _extra():
    """The field of a record's unknown keys (written back as they were)."""
    return dataclasses.field(default_factory=dict, repr=False, compare=False)


def _absent():
    """The field of the keys a record knows but was read without."""
    return dataclasses.field(default=frozenset(), repr=False, compare=False)


@dataclasses.dataclass(frozen=True)
class Light(_Record):
    """One light of the scan, in scan order (docs/scan-format.md, `lights`).

    index : int, scan order; channel : int, LED channel (None in a tool's scan.json)
    direction : (x, y, z) unit vector towards the LED, camera frame, or None
    position_mm : (x, y, z) mm, or None (no near-light model)
    intensity : (r, g, b) relative (the profile's; (1, 1, 1) without one), or None
    """
    index: int
    channel: int | None = None
    direction: tuple | None = None
    position_mm: tuple | None = None
    intensity: tuple | None = None
    extra: dict = _extra()
    absent: frozenset = _absent()
    _WHAT = "light"
    _REQUIRED = ("index",)


@dataclasses.dataclass(frozen=True)
class Exposure(_Record):
    """One exposure of the bracket: index, time_us (µs), current_mA (mA: the exposure's current,
    else the first light's), mode ("camera", "bulb" or "led")."""
    index: int
    time_us: int | None = None
    current_mA: int | None = None
    mode: str | None = None
    extra: dict = _extra()
    absent: frozenset = _absent()
    _WHAT = "exposure"
    _REQUIRED = ("index",)


@dataclasses.dataclass(frozen=True)
class Frame(_Record):
    """One frame taken (docs/scan-format.md, "A frame record").

    file : path in the scan directory (raw/L<l>_E<e>.<suffix>); light, exposure : indices
    time_us : µs; current_set_mA, current_meas_mA : mA; start_us : µs since the run started
    sync : the flash sync was seen (False: not a real frame; None: not recorded, taken as seen)
    retry : a repeat after a missing sync; run : device run; ring : index in the frame ring
    sha256 : of the file at capture (None until it is hashed)
    """
    file: str
    light: int
    exposure: int
    time_us: int | None = None
    current_set_mA: int | None = None
    current_meas_mA: int | None = None
    start_us: int | None = None
    sync: bool | None = None
    retry: bool | None = None
    run: int | None = None
    ring: int | None = None
    sha256: str | None = None
    extra: dict = _extra()
    absent: frozenset = _absent()
    _WHAT = "frame"
    _REQUIRED = ("file", "light", "exposure")

    @property
    def key(self):
        """(light, exposure) as ints."""
        return int(self.light), int(self.exposure)

    @property
    def synced(self):
        """Not recorded without its flash sync (a frame that says nothing counts as synced)."""
        return self.sync is not False


@dataclasses.dataclass(frozen=True)
class HdrLight(_Record):
    """One merged light (docs/scan-format.md, "The HDR record").

    index : light index; file, var_file : the two EXR files; frames : the frame files merged
    inputs : ({file, sha256, size, mtime_ns}, ...) what it was made from
    outputs : {path: {size, mtime_ns}} of the two files as written
    missing : ({exposure, file, reason}, ...) frames left out
    basis : {method, current, unit, sensor}; saturated_fraction, no_sample_fraction : 0..1
    time_s : {read, merge, write}, s
    """
    index: int
    file: str | None = None
    var_file: str | None = None
    frames: tuple = ()
    inputs: tuple | None = None
    outputs: dict | None = None
    missing: tuple = ()
    basis: dict | None = None
    saturated_fraction: float | None = None
    no_sample_fraction: float | None = None
    time_s: dict | None = None
    extra: dict = _extra()
    absent: frozenset = _absent()
    _WHAT = "HDR light"
    _REQUIRED = ("index",)

    def seconds(self):
        """Read + merge + write time, s (0 when not recorded)."""
        return sum((self.time_s or {}).values())


@dataclasses.dataclass(frozen=True)
class Hdr(_Record):
    """The HDR merge (scan.json "hdr"): method, unit, current, resolution, sensor (the noise
    model used), sensor_source, lights (`HdrLight`s, by index), merge_time_s (s), created."""
    method: str | None = None
    unit: str | None = None
    current: str | None = None
    resolution: str | None = None
    sensor: dict | None = None
    sensor_source: str | None = None
    lights: tuple = ()
    merge_time_s: float | None = None
    created: str | None = None
    extra: dict = _extra()
    absent: frozenset = _absent()
    _WHAT = "hdr"
    _NESTED = {"lights": HdrLight}

    def by_light(self):
        """{light index: HdrLight}."""
        return {int(r.index): r for r in self.lights}


@dataclasses.dataclass(frozen=True, eq=False)
class Manifest:
    """The contents of scan.json (schema in this module's docstring and docs/scan-format.md).

    Read through attributes (``m.frames``, ``m.complete``...); set only through the methods
    below, which `ScanDirectory` calls and then saves: the attributes refuse assignment
    (``dataclasses.FrozenInstanceError``). ``lights``, ``exposures`` and ``frames`` are
    tuples of `Light`, `Exposure` and `Frame` records, ``hdr`` an `Hdr` (or None); ``extra``
    keeps the keys of a newer writer this version does not know, written back unchanged.
    """
    rig: dict
    profile: dict | None
    pixel_pitch_mm: float | None
    lights: tuple
    exposures: tuple
    plan: dict | None = None
    created: str | None = None
    bracketing: dict | None = None
    sensor: dict | None = None
    radiometric_scale: list | None = None
    frames: tuple = ()
    runs: int = 0
    rig_time_s: float = 0.0
    hdr: Hdr | None = None
    complete: bool = False
    truth: str | None = None
    faults_seen: tuple = ()
    extra: dict = dataclasses.field(default_factory=dict)

    _RECORDS = {"lights": Light, "exposures": Exposure, "frames": Frame}

    # -- reading and writing -----------------------------------------------------------
    @classmethod
    def new(cls, rig, profile, pixel_pitch_mm, lights, exposures, plan):
        """A scan's manifest before its first frame (`lights`, `exposures`: records or their
        JSON objects)."""
        return cls(rig=rig, profile=profile, pixel_pitch_mm=pixel_pitch_mm,
                   lights=tuple(Light.from_json(x) for x in lights),
                   exposures=tuple(Exposure.from_json(x) for x in exposures), plan=plan, created=_now())

    @classmethod
    def from_dict(cls, data, where="scan.json"):
        """A manifest from scan.json's object, migrated from an older schema (1) when it is one.
        ValueError (naming `where`) when it lacks the "lights" and "frames" lists, a record
        lacks a required key, or it comes from a newer facette."""
        if not isinstance(data, dict) or not isinstance(data.get("frames"), list) \
                or not isinstance(data.get("lights"), list):
            raise ValueError(f"{where} is damaged: it has no 'frames' and 'lights' lists")
        schema = data.get("schema", 1)
        if not isinstance(schema, int) or schema > SCHEMA:
            raise ValueError(f"{where} has schema {schema!r}; this facette reads schemas 1..{SCHEMA} "
                             "(update facette)")
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        fields = {k: v for k, v in data.items() if k in known}
        for key in ("lights", "exposures", "frames", "faults_seen"):
            fields[key] = tuple(fields.get(key) or ())
        for key, record in cls._RECORDS.items():
            fields[key] = tuple(record.from_json(x, where) for x in fields[key])
        if fields.get("hdr") is not None:
            fields["hdr"] = Hdr.from_json(fields["hdr"], where)
        fields.setdefault("rig", None)
        fields.setdefault("profile", None)
        fields.setdefault("pixel_pitch_mm", None)
        fields["complete"] = bool(fields.get("complete", False))
        fields["runs"] = int(fields.get("runs") or 0)
        fields["rig_time_s"] = float(fields.get("rig_time_s") or 0.0)
        extra = {k: v for k, v in data.items() if k not in known and k != "schema"}
        return cls(**fields, extra=extra)

    @classmethod
    def of(cls, data):
        """`data` itself when it is a Manifest, else `from_dict(data)` (a scan.json dict)."""
        return data if isinstance(data, Manifest) else cls.from_dict(data)

    def to_dict(self):
        """scan.json's object (schema `SCHEMA`, every key present, in the documented order)."""
        out = {"schema": SCHEMA}
        for f in dataclasses.fields(self):
            if f.name != "extra":
                out[f.name] = _plain(getattr(self, f.name))
        out.update(self.extra)
        return out

    def snapshot(self):
        """A deep copy (for a worker that reads it while the scan goes on writing this one)."""
        return copy.deepcopy(self)

    def _set(self, **fields):
        for k, v in fields.items():
            object.__setattr__(self, k, v)

    # -- what was planned -----------------------------------------------------------------
    def set_calibration(self, sensor, radiometric_scale):
        """The profile's noise model (for the HDR merge) and radiometric scale."""
        self._set(sensor=None if sensor is None else dict(sensor),
                  radiometric_scale=None if radiometric_scale is None else list(radiometric_scale))

    def set_bracketing(self, bracketing):
        """How the exposures were chosen; the metering's rig time counts as this scan's."""
        self._set(bracketing=dict(bracketing),
                  rig_time_s=round(float(bracketing.get("meter_rig_time_s", 0.0)), 6))

    @property
    def n_planned(self):
        """Frames the plan asks for: lights × exposures."""
        return len(self.lights) * len(self.exposures)

    # -- frames and device runs -------------------------------------------------------------
    def add_frame(self, record):
        """Record a captured frame (a `Frame` or its JSON object), replacing an earlier one of
        the same light and exposure."""
        frame = Frame.from_json(record)
        frames = [f for f in self.frames if (f.light, f.exposure) != (frame.light, frame.exposure)]
        frames = sorted(frames + [frame], key=lambda f: (f.light, f.exposure))
        self._set(frames=tuple(frames))

    def drop_frames(self, files):
        """Forget the frames of these files (to be taken again): the scan is then incomplete."""
        files = set(files)
        self._set(frames=tuple(f for f in self.frames if f.file not in files), complete=False)

    def start_run(self):
        """Count a device run; returns its index."""
        self._set(runs=self.runs + 1)
        return self.runs - 1

    def add_rig_time(self, seconds):
        self._set(rig_time_s=round(self.rig_time_s + float(seconds), 6))

    def light_frames(self, light):
        """`Frame`s of one light, by exposure index."""
        return sorted((f for f in self.frames if int(f.light) == int(light)), key=lambda f: int(f.exposure))

    def frame_lights(self):
        """The light indices that have frames, sorted."""
        return sorted({int(f.light) for f in self.frames})

    # -- HDR and completion -----------------------------------------------------------------
    def set_hdr(self, record):
        """The HDR merge's record (an `Hdr` or its JSON object: `facette.scan.hdr.hdr_record`)."""
        self._set(hdr=None if record is None else Hdr.from_json(record))

    def hdr_lights(self):
        """{light index: `HdrLight`} of the HDR merge (empty before it)."""
        return {} if self.hdr is None else self.hdr.by_light()

    def set_truth(self, name):
        """The simulator's truth file beside scan.json (None: no truth)."""
        self._set(truth=name)

    def finish(self, faults_seen):
        """Every frame of the plan is taken; `faults_seen`: the journal entries worth knowing."""
        self._set(complete=True, faults_seen=tuple(faults_seen))
