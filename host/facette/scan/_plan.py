"""What a scan acquires: the `ScanPlan` (lights × exposures, checked by `default_plan`), the
sections of scan.json it decides (lights, exposures, profile) and how the missing frames are
grouped into device runs (`device_run_groups`)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from facette.calib import load as load_profile
from facette.calib import nominal_light_directions
from facette.errors import BadInputError
from facette.hdr import THESIS_BRACKET_US
from facette.scan.manifest import Exposure, Light

__all__ = ["ScanPlan", "default_plan", "load_scan_profile", "profile_section", "lights_section",
           "exposures_section", "device_run_groups"]


@dataclasses.dataclass
class ScanPlan:
    """What to acquire.

    lights : LED channels in scan order (light index i ↔ channel lights[i])
    exposures : [(time_us, current_mA)] (current 0: the light's current)
    light_current_mA : one current per light, mA
    mode : "camera" | "bulb" | "led"
    retries : repeats of a setting with a missing flash sync
    timing : other µs registers (settle_us, gap_us, ...)
    """
    lights: list
    exposures: list
    light_current_mA: list
    mode: str = "camera"
    retries: int = 1
    timing: dict = dataclasses.field(default_factory=dict)

    def key(self):
        return {"lights": list(self.lights), "exposures": [list(e) for e in self.exposures],
                "light_current_mA": list(self.light_current_mA), "mode": self.mode}

    def to_dict(self):
        return {**self.key(), "retries": self.retries, "timing": dict(self.timing)}

    def all_pairs(self):
        """Every (light index, exposure index) the plan asks for."""
        return {(l, e) for l in range(len(self.lights)) for e in range(len(self.exposures))}


def default_plan(n_leds=12, exposures=None, lights=None, light_current_mA=500, mode="camera", retries=1,
                 timing=None):
    """A plan with the thesis bracket (camera-timed) on every LED unless told otherwise.
    `exposures` : times in µs or (time_us, current_mA) pairs."""
    lights = list(range(n_leds)) if lights is None else [int(c) for c in lights]
    exps = THESIS_BRACKET_US if exposures is None else exposures
    exps = [(int(e), 0) if not hasattr(e, "__len__") else (int(e[0]), int(e[1])) for e in exps]
    cur = [int(light_current_mA)] * len(lights) if not hasattr(light_current_mA, "__len__") \
        else [int(c) for c in light_current_mA]
    if len(cur) != len(lights):
        raise BadInputError(f"{len(cur)} light currents for {len(lights)} lights")
    if not 1 <= len(lights) <= 16 or not 1 <= len(exps) <= 16:
        raise BadInputError(f"a scan takes 1..16 lights and 1..16 exposures per light, got {len(lights)} "
                            f"lights and {len(exps)} exposures")
    twice = sorted({c for c in lights if lights.count(c) > 1})
    if twice:
        raise BadInputError(f"light {twice[0]} is listed twice in lights {lights}",
                            hint="give each LED channel once (a repeat would overwrite its images)")
    bad = [c for c in lights if c < 0] + [c for c in cur if c < 1] + [c for _, c in exps if c < 0]
    if bad:
        raise BadInputError(f"LED channels are >= 0 and currents >= 1 mA; got {bad[0]}")
    if any(t < 1 for t, _ in exps):
        raise BadInputError(f"exposure times are >= 1 µs; got {[t for t, _ in exps]}")
    return ScanPlan(lights, exps, cur, mode, int(retries), dict(timing or {}))


def load_scan_profile(profile):
    """A `Profile` as given, or loaded from its folder; None stays None (nominal lights)."""
    if profile is None or hasattr(profile, "lights"):
        return profile
    return load_profile(profile)


def profile_section(profile):
    """scan.json's record of the profile: id and checksum, and where it was read from so that
    processing can apply its flat field (after checking the checksum again)."""
    if profile is None:
        return None
    path = getattr(profile, "path", None)
    size = profile.measured_size() if hasattr(profile, "measured_size") else None
    return {"id": profile.id, "sha256": profile.sha256,
            "path": None if path is None else str(Path(path).resolve()),
            # the size its pixel pitch and flat field were measured at (processing scales them)
            "image_size_px": None if size is None else list(size)}


def lights_section(plan, profile):
    """scan.json's lights: one `Light` per light in scan order, from the profile (a channel it
    did not calibrate is refused) or the nominal directions."""
    nominal = nominal_light_directions()
    out = []
    for i, ch in enumerate(plan.lights):
        if profile is not None:
            lt = profile.lights
            if ch >= len(lt):
                raise BadInputError(f"LED channel {ch} is not in profile {profile.id!r}: it calibrated "
                                    f"{len(lt)} lights (channels 0..{len(lt) - 1})",
                                    hint="choose lights among those, or calibrate that LED")
            d, inten = lt.directions[ch].tolist(), lt.intensities[ch].tolist()
            pos = None if lt.positions_mm is None else lt.positions_mm[ch].tolist()
        else:
            d, inten, pos = (nominal[ch].tolist() if ch < len(nominal) else None), [1.0, 1.0, 1.0], None
        out.append(Light(index=i, channel=ch, direction=_tuple(d), position_mm=_tuple(pos),
                         intensity=_tuple(inten)))
    return out


def exposures_section(plan):
    """scan.json's exposures: one `Exposure` each (its current, else the first light's)."""
    return [Exposure(index=e, time_us=t, current_mA=c if c else plan.light_current_mA[0], mode=plan.mode)
            for e, (t, c) in enumerate(plan.exposures)]


def _tuple(values):
    return None if values is None else tuple(values)


def device_run_groups(pending):
    """Split missing (light, exposure) pairs into device runs: lights sharing the same
    set of missing exposures form one lights × exposures scan. [(lights, exposures)]."""
    by_light = {}
    for l, e in sorted(pending):
        by_light.setdefault(l, []).append(e)
    groups = {}
    for l, es in by_light.items():
        groups.setdefault(tuple(es), []).append(l)
    return [(ls, list(es)) for es, ls in sorted(groups.items(), key=lambda kv: kv[1][0])]
