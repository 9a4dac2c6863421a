"""Exposure bracketing: the thesis's fixed bracket, or an adaptive plan from metering frames.

An exposure is k = t · I in µs·mA (LED on-time × LED current). From one metering
frame per light the radiance per µs·mA of every object pixel is known (up to noise),
and the noise model (eq 2.13) predicts the SNR each set of exposures gives after the
inverse-variance merge. `plan_adaptive` picks, per light, the fewest exposures that
bring every object pixel between the shadow percentile and the brightest pixel to
the target SNR, with the shortest exposure placed so that the brightest pixel stays
below saturation. Exposures become (time_us, current_mA) pairs according to the
timing mode: with LED-defined exposure the current is raised (up to `max_current_mA`)
to shorten the time; in camera and bulb modes the current stays at the light's
current.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from facette.device.registers import TimingMode
from facette.hdr._merge import as_sensor

__all__ = ["BracketPlan", "BRACKETS", "bracket_fixed", "plan_adaptive", "predicted_snr",
           "frame_overhead_s", "DEFAULT_TIMING"]

# Named fixed brackets, exposure times in seconds.
# The thesis's fixed bracket (§4.3.2), the one source of it: 15, 10, 2, 1, 1/5, 1/15, 1/30 s.
THESIS_BRACKET_S = (15.0, 10.0, 2.0, 1.0, 1 / 5, 1 / 15, 1 / 30)
THESIS_BRACKET_US = tuple(int(round(t * 1e6)) for t in THESIS_BRACKET_S)
BRACKETS = {"thesis2016": THESIS_BRACKET_S}

# Per-frame overheads of the device's scan (register defaults, protocol/registers.toml), s.
DEFAULT_TIMING = {"settle_s": 0.1, "gap_s": 0.2, "led_pre_s": 0.1, "led_post_s": 0.05}

# The rig's timing modes, from the protocol definition (enum timing_mode): camera, bulb, led.
TIMING_MODES = tuple(m.name.lower() for m in TimingMode)


def frame_overhead_s(mode, timing=None):
    """Time a frame costs beyond its exposure time, seconds (settle/pre/post + gap)."""
    t = dict(DEFAULT_TIMING, **(timing or {}))
    if mode == "led":
        return t["led_pre_s"] + t["led_post_s"] + t["gap_s"]
    if mode in ("camera", "bulb"):
        return t["settle_s"] + t["gap_s"]
    raise ValueError(f"unknown timing mode {mode!r}; choose from {TIMING_MODES}")


@dataclass
class BracketPlan:
    """Exposures to take, per light.

    Attributes
    ----------
    exposures : list (one per light) of lists of (time_us int, current_mA int)
    mode : {"camera", "bulb", "led"}
    name : str
        "thesis2016" for the fixed bracket, "adaptive" for a planned one.
    predicted : list of dicts or None
        Per light (adaptive plans): the SNR (dB) the plan predicts at the shadow
        level, the worst SNR over the covered range, and the radiance range covered.
    """

    exposures: list
    mode: str
    name: str
    predicted: list | None = field(default=None)

    def exposure_time_s(self):
        """Sum of exposure (LED on / shutter) times over all lights, seconds."""
        return sum(t for light in self.exposures for t, _ in light) * 1e-6

    def rig_time_s(self, timing=None):
        """Estimated rig time, seconds: exposure times plus per-frame overheads."""
        n = sum(len(light) for light in self.exposures)
        return self.exposure_time_s() + n * frame_overhead_s(self.mode, timing)

    def n_frames(self):
        return sum(len(light) for light in self.exposures)

    def registers(self):
        """Holding-register values realising the plan on the device, or None.

        The device runs one exposure list for every light (exposure_time_us[e],
        exposure_current_mA[e], 0 meaning the light's own light_current_mA[i]).
        A plan is expressible when all lights have the same times and either the
        same currents per exposure, or one current per light.
        """
        n = len(self.exposures[0])
        if any(len(light) != n for light in self.exposures):
            return None
        times = [t for t, _ in self.exposures[0]]
        if any([t for t, _ in light] != times for light in self.exposures):
            return None
        currents = [[c for _, c in light] for light in self.exposures]
        if all(c == currents[0] for c in currents):
            return {"n_exposures": n, "exposure_time_us": times,
                    "exposure_current_mA": currents[0], "timing_mode": self.mode}
        if all(len(set(c)) == 1 for c in currents):
            return {"n_exposures": n, "exposure_time_us": times, "exposure_current_mA": [0] * n,
                    "light_current_mA": [c[0] for c in currents], "timing_mode": self.mode}
        return None

    def scan_kwargs(self):
        """Keyword arguments for `facette.scan.run_scan` (exposures, light_current_mA, mode).

        Raises ValueError when the lights do not share one exposure list (plan with
        ``shared=True``, or scan the lights in groups).
        """
        regs = self.registers()
        if regs is None:
            raise ValueError("the lights of this plan have different exposure lists, which one "
                             "scan cannot run; plan with shared=True or scan lights in groups")
        if "light_current_mA" in regs:
            return {"exposures": [(t, 0) for t in regs["exposure_time_us"]],
                    "light_current_mA": regs["light_current_mA"], "mode": self.mode}
        return {"exposures": list(zip(regs["exposure_time_us"], regs["exposure_current_mA"])),
                "mode": self.mode}

    def to_dict(self):
        return {"name": self.name, "mode": self.mode,
                "exposures": [[[int(t), int(c)] for t, c in light] for light in self.exposures],
                "predicted": self.predicted, "rig_time_s": round(self.rig_time_s(), 3)}

    def to_json(self):
        return json.dumps(self.to_dict())


def bracket_fixed(name="thesis2016", n_lights=12, current_mA=500, mode="bulb"):
    """A named fixed bracket for every light: [(time_us, current_mA), ...] × n_lights.

    "thesis2016": t = 15, 10, 2, 1, 1/5, 1/15, 1/30 s (thesis §4.3.2). Its exposure
    times add up to 28.3 s per light (the thesis reports 27.3 s, i.e. 327.6 s for
    12 lights: one second less than its own list sums to).
    """
    if name not in BRACKETS:
        raise ValueError(f"unknown fixed bracket {name!r}; choose from {sorted(BRACKETS)}")
    if mode not in TIMING_MODES:
        raise ValueError(f"unknown timing mode {mode!r}; choose from {TIMING_MODES}")
    light = [(int(round(t * 1e6)), int(current_mA)) for t in BRACKETS[name]]
    return BracketPlan(exposures=[list(light) for _ in range(int(n_lights))], mode=mode, name=name)


def _var_dn2(sensor, signal, n_ph):
    g = sensor.gain_e_per_dn
    return (np.maximum(signal, 0.0) / g + (sensor.read_noise_e / g) ** 2 + 1.0 / 12.0) / n_ph


def predicted_snr(radiance, exposures, sensor=None, n_photosites=2, saturation_fraction=0.95):
    """SNR (linear) of the inverse-variance merge of `exposures` for each radiance value.

    radiance : array, black-subtracted DN per exposure unit; exposures : (n,) same unit.
    A sample counts if its mean is below `saturation_fraction` of the saturation level.
    n_photosites: photosites averaged per value (2 for half-size green).
    """
    sensor = as_sensor(sensor)
    x = np.asarray(radiance, dtype=np.float64)[..., None]
    k = np.asarray(exposures, dtype=np.float64)
    sat = sensor.saturation_dn - sensor.black_level_dn
    s = x * k
    ok = s < saturation_fraction * sat
    info = np.where(ok, k ** 2 / _var_dn2(sensor, s, n_photosites), 0.0).sum(axis=-1)
    return np.where(info > 0, x[..., 0] * np.sqrt(info), 0.0)


_SHUTTER_S = 2.0 ** (np.arange(-39, 12) / 3.0)  # 1/3-stop camera shutter times, 1/8000 .. 13 s


def _to_time_current(k, mode, base_mA, max_mA, min_mA, min_time_us, max_time_us):
    """Exposure k (µs·mA) -> (time_us, current_mA) for the timing mode (never over-exposing)."""
    if mode == "led":
        i = float(max_mA)
        t = k / i
        if t < min_time_us:  # too short a pulse: lower the current instead
            t = float(min_time_us)
            i = max(float(min_mA), k / t)
    else:
        i = float(base_mA)
        t = k / i
        if mode == "camera":  # the camera's own 1/3-stop speeds: round down
            cands = _SHUTTER_S[_SHUTTER_S * 1e6 <= t * 1.0001]
            t = (cands[-1] if cands.size else _SHUTTER_S[0]) * 1e6
    t = min(max(t, float(min_time_us)), float(max_time_us))
    return int(round(t)), int(round(i))


def plan_adaptive(meterings, metering_exposures, sensor=None, masks=None, *, target_snr_db=40.0,
                  shadow_percentile=10.0, highlight_percentile=100.0, max_dynamic_range=1e3,
                  mode="led", light_current_mA=500, max_current_mA=1000, min_current_mA=10,
                  min_time_us=100, max_time_us=30_000_000, max_frames=10, headroom=0.85,
                  n_photosites=(1, 2, 1), shared=False):
    """Plan the fewest exposures per light reaching `target_snr_db` without clipping highlights.

    Parameters
    ----------
    meterings : sequence of m arrays (H, W, 3) (or RawFrame)
        One metering frame per light, black-subtracted DN (half-size). Take it short
        enough that the object's highlights are not saturated.
    metering_exposures : sequence of m (time_us, current_mA)
    sensor : noise model (SensorModel, profile dict, Profile, None = nominal)
    masks : sequence of m (H, W) bool, one (H, W) bool for all, or None (whole frame)
    target_snr_db : float or callable
        SNR to reach (20·log10(radiance/σ)) for every radiance between the shadow
        level and the brightest pixel; a callable gets radiance (DN per µs·mA, array)
        and returns the target in dB per value.
    shadow_percentile : float in [0, 100)
        Object values below this percentile (deep shadows) need not reach the target.
    highlight_percentile : float
        Values above it may clip (100: nothing on the object may clip).
    max_dynamic_range : float
        The shadow level is at least brightest / max_dynamic_range.
    mode : {"led", "bulb", "camera"}
        Timing mode; only "led" varies the current (up to max_current_mA).
    light_current_mA : float
        Current used in bulb / camera modes.
    max_frames : int
        Cap on exposures per light (the prediction then reports the SNR reached).
    headroom : float in (0, 1)
        The brightest value sits at this fraction of saturation in the shortest exposure.
    shared : bool
        One exposure list for all lights (planned over the union of their ranges),
        as the device's registers and `facette.scan.run_scan` take it; False plans
        each light on its own (fewer frames, but one scan per distinct list).

    Returns
    -------
    BracketPlan (name "adaptive"), with per-light predictions.
    """
    sensor = as_sensor(sensor)
    if mode not in TIMING_MODES:
        raise ValueError(f"unknown timing mode {mode!r}; choose from {TIMING_MODES}")
    meterings = [m.image if hasattr(m, "image") else np.asarray(m, dtype=np.float64)
                 for m in meterings]
    if len(meterings) != len(metering_exposures):
        raise ValueError(f"{len(meterings)} metering frames for {len(metering_exposures)} "
                         "metering exposures")
    sat = sensor.saturation_dn - sensor.black_level_dn
    n_g = float(np.max(n_photosites))
    base_mA = light_current_mA if mode != "led" else max_current_mA
    k_max_time = float(max_time_us) * (max_current_mA if mode == "led" else light_current_mA)
    ranges = []
    for li, (img, (t_us, i_ma)) in enumerate(zip(meterings, metering_exposures)):
        km = float(t_us) * float(i_ma)
        if not km > 0:
            raise ValueError(f"light {li}: metering exposure {t_us} µs × {i_ma} mA must be > 0")
        mask = None
        if masks is not None:
            mask = masks[li] if isinstance(masks, (list, tuple)) else masks
            mask = np.asarray(mask, dtype=bool)
        vals = img[mask] if mask is not None else img.reshape(-1, img.shape[-1])
        vals = np.asarray(vals, dtype=np.float64).reshape(-1)
        if vals.size == 0:
            raise ValueError(f"light {li}: the object mask selects no pixel")
        clipped = vals >= 0.95 * sat
        x = vals / km
        notes = []
        if highlight_percentile >= 100:
            x_hi = float(x.max())
        else:
            x_hi = float(np.percentile(x, highlight_percentile))
        if clipped.mean() > (100.0 - highlight_percentile) / 100.0 and clipped.any():
            # Metering already clipped: true highlights are brighter than we can see.
            x_hi = max(x_hi, 4.0 * sat / km)
            notes.append("metering frame clipped: highlights assumed 4x its saturation; "
                         "meter shorter for a tighter plan")
        if not x_hi > 0:
            raise ValueError(f"light {li}: the metering frame is black over the object; meter "
                             "with a longer exposure or a higher current")
        x_lo = max(float(np.percentile(x, shadow_percentile)), x_hi / float(max_dynamic_range))
        ranges.append((x_lo, x_hi, notes))
    if shared:
        # One exposure list for every light (what the device's registers express):
        # plan for the union of the lights' ranges.
        x_lo = min(r[0] for r in ranges)
        x_hi = max(r[1] for r in ranges)
        notes = sorted({n for r in ranges for n in r[2]})
        ranges = [(x_lo, x_hi, notes)] * len(ranges)
    per_light, predicted, cache = [], [], {}
    for li, (x_lo, x_hi, notes) in enumerate(ranges):
        if (x_lo, x_hi) not in cache:
            cache[(x_lo, x_hi)] = _plan_range(x_lo, x_hi, target_snr_db, sensor, sat, n_g, headroom,
                                              k_max_time, max_frames)
        ks, grid, snr, target_lin = cache[(x_lo, x_hi)]
        light = [_to_time_current(k, mode, base_mA, max_current_mA, min_current_mA, min_time_us,
                                  max_time_us) for k in sorted(ks)]
        per_light.append(light)
        predicted.append({"light": li, "radiance_range": [x_lo, x_hi],
                          "snr_db_at_shadow": float(20 * np.log10(max(snr[0], 1e-12))),
                          "snr_db_min": float(20 * np.log10(max(snr.min(), 1e-12))),
                          "target_met": bool(np.all(snr >= target_lin * 0.999)),
                          "notes": list(notes)})
    return BracketPlan(exposures=per_light, mode=mode, name="adaptive", predicted=predicted)


def _plan_range(x_lo, x_hi, target_snr_db, sensor, sat, n_g, headroom, k_max_time, max_frames):
    """Greedy exposure choice (µs·mA) for radiances in [x_lo, x_hi]; see `plan_adaptive`."""
    grid = np.geomspace(x_lo, x_hi, 256)
    target = (target_snr_db(grid) if callable(target_snr_db)
              else np.full(grid.shape, float(target_snr_db)))
    target_lin = 10.0 ** (np.asarray(target, dtype=np.float64) / 20.0)
    ks = [headroom * sat / x_hi]  # shortest: brightest value below saturation
    while len(ks) < max_frames:
        snr = predicted_snr(grid, ks, sensor, n_g)
        short = np.nonzero(snr < target_lin)[0]
        if short.size == 0:
            break
        xf = grid[short[-1]]  # brightest failing value: fix from the top down
        # Longest exposure keeping xf unsaturated: the fewest frames overall ...
        k_top = min(headroom * sat / xf, k_max_time)
        chosen = k_top
        # ... unless a shorter one already brings every failing value to target (last frame).
        if k_top > ks[-1]:
            for kc in np.geomspace(ks[-1], k_top, 48)[1:]:
                if np.all(predicted_snr(grid[short], ks + [kc], sensor, n_g) >= target_lin[short]):
                    chosen = kc
                    break
        ks.append(chosen)
    ks = _shorten(ks, grid, target_lin, sensor, n_g)
    return ks, grid, predicted_snr(grid, ks, sensor, n_g), target_lin


def _shorten(ks, grid, target_lin, sensor, n_g, steps=48):
    """Shorten each exposure, longest first, as far as the whole range stays at target.

    The greedy choice puts the shortest exposure at the highlight's headroom, which is
    more than a dim light needs when one or two frames already exceed the target: the
    rig time is the exposures' sum, so every exposure goes down to the shortest value
    that keeps every radiance at its target (never below the next shorter exposure).
    A plan that misses the target somewhere (max_frames reached) is left as it is.
    """
    ks = sorted(ks)
    if not np.all(predicted_snr(grid, ks, sensor, n_g) >= target_lin * 0.999):
        return ks
    for i in range(len(ks) - 1, -1, -1):
        floor = ks[i - 1] if i > 0 else ks[0] * 1e-3
        for kc in np.geomspace(floor, ks[i], steps)[:-1]:
            trial = ks[:i] + [float(kc)] + ks[i + 1:]
            if np.all(predicted_snr(grid, trial, sensor, n_g) >= target_lin * 0.999):
                ks = trial
                break
    return ks
