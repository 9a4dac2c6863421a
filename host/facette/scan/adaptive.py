"""The adaptive bracket of the one-button scan: meter each light once, plan, then scan.

`meter_and_plan` takes one metering frame per light into ``<scan>/meter/`` (a scan
directory of its own, so an interrupted metering resumes like any scan), finds the
object in them, and asks `facette.hdr.plan_adaptive` for the fewest exposures that bring
the object to the target SNR without clipping its highlights, as one exposure list for
every light (what the device's registers run in one scan).
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from facette.camera.raw import read_raw
from facette.hdr import as_sensor, plan_adaptive

__all__ = ["meter_and_plan", "object_mask", "sampled_for_plan", "METER_DIR", "METER_TIME_US", "METER_PIXELS"]

METER_DIR = "meter"
# The thesis bracket's shortest exposure (1/30 s): a glossy highlight at 500 mA holds there.
METER_TIME_US = 33_333
# Metering again this much shorter when a highlight clipped, at most this often.
_SHORTER, _RETRIES = 8, 3
METER_PIXELS = 4_000_000
"""Half-size pixels of a metering frame kept for the plan: a larger frame (a RAW over 16 MP) is
kept every k-th row and column (12 lights at 11648x8736 held whole are 7.3 GB), its highlights
exactly (`sampled_for_plan`)."""


def object_mask(meterings, background_fraction=0.1):
    """(H, W) bool: the pixels that belong to the object in metering frames (m, H, W, 3).

    A pixel is on the object when, under its brightest light, its green value reaches
    `background_fraction` of the 99th percentile of those values: a dark background
    (black velvet, the simulator's table at 4 % albedo) is left out of the plan, so
    that the exposures are not stretched for it.
    """
    g = np.max(np.stack([np.asarray(m)[..., 1] for m in meterings]), axis=0)
    ref = float(np.percentile(g, 99))
    if not ref > 0:
        return np.ones(g.shape, bool)
    mask = g >= background_fraction * ref
    return mask if mask.sum() >= 16 else np.ones(g.shape, bool)


def _clipped(frame, sat, fraction=1e-4):
    return float(np.mean(frame.peak >= 0.95 * sat)) > fraction


def sampled_for_plan(image, pixels=METER_PIXELS):
    """(image (H, W, 3) as the plan sees it, k): the frame itself when it has at most `pixels`
    pixels (k = 1), else every k-th row and column of it, except that a k×k block whose
    brightest value reaches half the frame's brightest keeps its brightest values (the plan
    must see the highlights it keeps from clipping, which a sample could step over)."""
    hh, ww = image.shape[:2]
    k = int(np.ceil(np.sqrt(hh * ww / pixels))) if hh * ww > pixels else 1
    if k == 1:
        return image, 1
    hb, wb = hh // k, ww // k
    out = np.array(image[:hb * k:k, :wb * k:k], dtype=image.dtype)
    blocks = image[:hb * k, :wb * k].reshape(hb, k, wb, k, -1).max(axis=(1, 3))
    bright = blocks.max(axis=-1) >= 0.5 * float(blocks.max())
    out[bright] = blocks[bright]
    return out, k


def meter_and_plan(scan, directory, light_current_mA, mode, sensor=None, *, button=None,
                   target_snr_db=40.0, shadow_percentile=20.0):
    """Meter every light once and plan the scan's exposures.

    Parameters
    ----------
    scan : callable(directory, exposures, button) -> ScanDirectory
        Runs one scan of the scan's lights with `exposures` (`run_scan` bound to the rig and
        the scan's settings).
    directory : Path of the scan directory; the metering goes to ``directory / "meter"``
        (and ``meter-1``, ... when a highlight clipped and the light is metered shorter).
    light_current_mA : list of one current per light, mA
    mode : "camera" | "bulb" | "led" (timing mode of the scan to plan)
    sensor : the noise model (SensorModel, profile sensor dict, None: nominal)
    button : how the first metering run starts (see `run_scan`)
    target_snr_db, shadow_percentile : SNR of every object value from that percentile up
        (default 40 dB from the 20th: the midtones and highlights reach it, the darkest fifth
        gets what those frames give it; from the 10th the camera-timed demo scan needs 61 s
        of rig time instead of 35 s)

    Returns
    -------
    (BracketPlan, record dict for scan.json's "bracketing": the metering directories, their
    rig time, the object's pixel count, the target and the plan's predictions)
    """
    sensor = as_sensor(sensor)
    sat = sensor.saturation_dn - sensor.black_level_dn
    t_us = METER_TIME_US
    meters, rig_s, dirs = None, 0.0, []
    for attempt in range(_RETRIES + 1):
        name = METER_DIR if attempt == 0 else f"{METER_DIR}-{attempt}"
        sd = scan(directory / name, [(t_us, 0)], button)
        button = None
        dirs.append(name)
        rig_s += sd.manifest.rig_time_s
        frames = sorted(sd.manifest.frames, key=lambda f: int(f.light))
        meters, clipped = [], False
        for f in frames:      # one frame decoded at a time: only what the plan needs is kept
            raw = read_raw(sd.path / f.file)
            clipped = clipped or _clipped(raw, sat)
            meters.append((sampled_for_plan(raw.image), (int(f.time_us), int(f.current_set_mA))))
            del raw
        if not clipped or attempt == _RETRIES:
            break
        t_us = max(100, t_us // _SHORTER)
    images = [m for (m, _), _ in meters]
    step = meters[0][0][1]
    meters = [(m, e) for (m, _), e in meters]
    mask = object_mask(images)
    # as frames (an .image), so that the plan reads the float32 values without a float64 copy
    plan = plan_adaptive([SimpleNamespace(image=m) for m in images], [e for _, e in meters], sensor, mask, target_snr_db=target_snr_db,
                         shadow_percentile=shadow_percentile, mode=mode, light_current_mA=int(np.max(light_current_mA)), shared=True)
    record = {"name": "adaptive", "target_snr_db": float(target_snr_db),
              "shadow_percentile": float(shadow_percentile), "meter_dirs": dirs,
              "meter_exposure_us": t_us, "meter_rig_time_s": round(rig_s, 6),
              "object_pixels": int(mask.sum()) * step * step, "predicted": plan.predicted,
              "planned_rig_time_s": round(plan.rig_time_s(), 3)}
    return plan, record
