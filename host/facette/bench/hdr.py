"""`facette bench hdr`: HDR merge accuracy and speed, adaptive vs fixed bracketing.

Prints, on simulated brackets with known radiance (sensor model of facette.camera.sensor):

1. SNR (dB) and relative RMSE of the inverse-variance merge, Debevec–Malik hat
   weights and colour-hdri's `image_stack_to_HDRI`, on the same frames, with the
   time of each (one light, the thesis's fixed bracket);
2. adaptive vs the thesis's fixed bracket over 12 lights: rig time and the SNR
   reached in shadows, midtones and highlights;
3. merge time for one 12 MP frame set (4288×2848 RAW -> half-size), decode included;
4. (``--perlight``) per-light adaptive plans against one shared exposure list, on every
   simulated scene × material × far/near LEDs × timing mode: rig time of each.

Usage: facette bench hdr [--size H W] [--seed N] [--skip-12mp] [--target-db DB] [--perlight]
"""
from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from facette.camera.raw import read_raw
from facette.camera.sensor import SensorModel, bayer_mosaic_rggb
from facette.hdr import bracket_fixed, merge, plan_adaptive, predicted_snr
from facette.sim.dng import write_dng
from facette.sim.lights import thesis_leds
from facette.sim.render import radiance_per_led
from facette.sim.scene import make_scene

CURRENT_MA = 500  # the fixed bracket's LED current (register default light_current_mA)


def _light_dirs():
    th = np.radians([30 if i % 2 == 0 else 15 for i in range(12)])
    ph = np.radians(np.arange(12) * 30.0)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)


def synthetic_scene(h, w, sensor, seed=0):
    """Radiance per µs·mA (black-subtracted DN) for the 12 thesis lights: a bumpy glossy
    dome with albedo patches, attached shadows and specular highlights.

    Returns (radiance (12, h, w, 3), mask (h, w) bool). Scaled so that the brightest
    highlight reaches 80 % of saturation at 1/30 s and 500 mA (the thesis's
    shortest exposure just holds it).
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    u, v = (xx - w / 2) / (0.45 * min(h, w)), (yy - h / 2) / (0.45 * min(h, w))
    r2 = u ** 2 + v ** 2
    mask = r2 < 1.0
    # Dome plus bumps: height field -> normals.
    z = np.sqrt(np.clip(1 - r2, 0, None)) * 0.6
    for _ in range(12):
        cx, cy = rng.uniform(-.7, .7, size=2)
        s, a = rng.uniform(.05, .2), rng.uniform(-.15, .15)
        z = z + a * np.exp(-((u - cx) ** 2 + (v - cy) ** 2) / (2 * s ** 2))
    gy, gx = np.gradient(z, 1.0 / (0.45 * min(h, w)))
    n = np.stack([-gx, gy, np.ones_like(z)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    albedo = np.ones((h, w, 3)) * np.array([0.6, 0.5, 0.4])
    patches = rng.integers(0, 4, size=(4, 4))
    levels = np.array([[0.08, 0.07, 0.05], [0.3, 0.25, 0.2], [0.6, 0.5, 0.4], [0.85, 0.8, 0.75]])
    albedo = levels[patches[(yy * 4 // h), (xx * 4 // w)]]
    out = []
    view = np.array([0.0, 0.0, 1.0])
    for s in _light_dirs():
        cos = np.clip(n @ s, 0, None)
        hvec = (s + view) / np.linalg.norm(s + view)
        spec = np.clip(n @ hvec, 0, None) ** 200
        rad = albedo * cos[..., None] + 40.0 * spec[..., None]
        out.append(np.where(mask[..., None], rad, 0.0))
    rad = np.stack(out)
    sat = sensor.saturation_dn - sensor.black_level_dn
    rad *= 0.8 * sat / (rad.max() * 33333 * CURRENT_MA)
    return rad, mask


def simulate_frames(radiance, exposures, sensor, rng):
    """Half-size frames (black-subtracted DN, peaks) for one light and [(time_us, mA), ...]."""
    frames, peaks = [], []
    g = sensor.gain_e_per_dn
    for t_us, i_ma in exposures:
        electrons = bayer_mosaic_rggb(radiance * g * t_us * i_ma)
        raw = sensor.expose_charge(electrons, t_us * 1e-6, rng).astype(np.float32)
        raw -= sensor.black_level_dn
        gm = 0.5 * (raw[0::2, 1::2] + raw[1::2, 0::2])
        frames.append(np.stack([raw[0::2, 0::2], gm, raw[1::2, 1::2]], -1))
        peaks.append(np.stack([raw[0::2, 0::2], np.maximum(raw[0::2, 1::2], raw[1::2, 0::2]),
                               raw[1::2, 1::2]], -1))
    return frames, peaks


def _regions(truth, mask):
    """Shadows / midtones / highlights: percentile bands of the lit object's true radiance."""
    vals = truth[mask].reshape(-1)
    lit = vals[vals > 0]
    q = np.percentile(lit, [2, 10, 45, 55, 99.5])
    sel = mask[..., None] & (truth > 0)
    return {"shadows": sel & (truth >= q[0]) & (truth < q[1]),
            "midtones": sel & (truth >= q[2]) & (truth < q[3]),
            "highlights": sel & (truth >= q[4])}


def _snr_db(est, truth, sel):
    err = est[sel] - truth[sel]
    err = err[np.isfinite(err)]
    if err.size == 0:
        return float("nan")
    return float(10 * np.log10(np.sum(truth[sel] ** 2) / max(np.sum(err ** 2), 1e-300)))


def _colour_hdri(frames, ks, sat):
    from colour_hdri import ImageStack, image_stack_to_HDRI
    from colour_hdri.utilities import Image, Metadata
    stack = ImageStack()
    for f, k in sorted(zip(frames, ks), key=lambda p: p[1]):  # shortest first, as from_files sorts
        img = Image()
        img.data = np.clip(f / sat, 1e-6, 1.0)
        img.metadata = Metadata(f_number=1.0, exposure_time=float(k), iso=100.0)
        stack.append(img)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = image_stack_to_HDRI(stack)
    return out * 100.0 / 12.5 * sat  # undo average_luminance(N=1, t, S=100, k=12.5)


def bench_methods(sensor, h, w, seed):
    rad, mask = synthetic_scene(h, w, sensor, seed)
    truth = rad[0]
    exps = bracket_fixed("thesis2016", 1, CURRENT_MA).exposures[0]
    ks = [t * i for t, i in exps]
    frames, peaks = simulate_frames(truth, exps, sensor, np.random.default_rng(seed + 1))
    reg = _regions(truth, mask)
    sat = sensor.saturation_dn - sensor.black_level_dn
    rows = []
    for name in ("inverse_variance", "debevec1997", "colour_hdri"):
        t0 = time.perf_counter()
        if name == "colour_hdri":
            est = _colour_hdri(frames, ks, sat)
        else:
            est = merge(frames, ks, sensor, method=name, peaks=peaks, n_photosites=(1, 2, 1),
                        times_s=[t * 1e-6 for t, _ in exps]).radiance
        dt = time.perf_counter() - t0
        sel = mask[..., None] & (truth > 1e-6 * truth.max())
        rel = (est[sel] - truth[sel]) / truth[sel]
        rows.append((name, _snr_db(est, truth, sel), *[_snr_db(est, truth, reg[r]) for r in reg],
                     float(np.sqrt(np.nanmean(rel ** 2))), dt))
    print(f"\n[1] merge methods, one light, thesis bracket (7 frames), {h}x{w} half-size, "
          f"SNR vs known radiance")
    print(f"{'method':18s} {'SNR dB':>7s} {'shadow':>7s} {'mid':>7s} {'high':>7s} "
          f"{'relRMSE':>8s} {'time s':>7s}")
    for r in rows:
        print(f"{r[0]:18s} {r[1]:7.2f} {r[2]:7.2f} {r[3]:7.2f} {r[4]:7.2f} {r[5]:8.4f} {r[6]:7.3f}")
    return rows


def rig_default_scene(h, w, sensor, seed=0):
    """The simulated rig's default scene (facette.sim: plaque_sphere, thesis LEDs, its exposure
    scale), as radiance per µs·mA in black-subtracted DN, (12, h, w, 3), and its object mask."""
    scene = make_scene("plaque_sphere", (h, w), seed=seed)
    leds = thesis_leds(0.5, 0.05, seed=seed + 1)
    return radiance_per_led(scene, leds) / sensor.gain_e_per_dn, np.asarray(scene.mask, bool)


def bench_bracketing(sensor, h, w, seed, target_db, scene="synthetic"):
    if scene == "rig":
        rad, mask = rig_default_scene(h, w, sensor, seed)
        label = "simulated rig's default scene (plaque_sphere)"
    else:
        rad, mask = synthetic_scene(h, w, sensor, seed)
        label = "synthetic glossy dome, highlight at 80 % of saturation in 1/30 s"
    rng = np.random.default_rng(seed + 2)
    fixed = bracket_fixed("thesis2016", 12, CURRENT_MA, mode="bulb")
    # Metering: one frame per light at the fixed bracket's shortest exposure (1/30 s, 500 mA).
    meter_exp = (33333, CURRENT_MA)
    meters = [simulate_frames(rad[li], [meter_exp], sensor, rng)[0][0] for li in range(12)]
    plans = {"fixed thesis2016": (fixed, 0.0)}
    meter_time = 12 * (meter_exp[0] * 1e-6 + 0.35)
    for tdb in sorted({target_db - 5, target_db - 2, target_db}):
        plans[f"adaptive {tdb:g} dB"] = (
            plan_adaptive(meters, [meter_exp] * 12, sensor, mask, target_snr_db=tdb, mode="led"),
            meter_time)

    plans[f"adaptive {target_db - 2:g} dB shared"] = (
        plan_adaptive(meters, [meter_exp] * 12, sensor, mask, target_snr_db=target_db - 2,
                      mode="led", shared=True), meter_time)

    # Adaptive matched to the fixed bracket's predicted SNR at every radiance (+0.5 dB).
    ks_fixed = [t * i for t, i in fixed.exposures[0]]

    def match(x):
        return 20 * np.log10(np.maximum(predicted_snr(x, ks_fixed, sensor, 2), 1e-9)) + 0.5

    plans["adaptive = fixed SNR"] = (
        plan_adaptive(meters, [meter_exp] * 12, sensor, mask, target_snr_db=match, mode="led",
                      max_frames=16), meter_time)
    print(f"\n[2] bracketing, 12 lights, {label}, {h}x{w} half-size; SNR (dB) vs known "
          "radiance, median over lights")
    print(f"{'plan':26s} {'frames':>6s} {'expo s':>7s} {'rig s':>7s} {'shadow':>7s} {'mid':>7s} "
          f"{'high':>7s} {'merge s':>7s}")
    out = {}
    for name, (plan, extra) in plans.items():
        snrs, tm = [], 0.0
        for li in range(12):
            exps = plan.exposures[li] + ([meter_exp] if extra else [])
            frames, peaks = simulate_frames(rad[li], exps, sensor, rng)
            t0 = time.perf_counter()
            est = merge(frames, [t * i for t, i in exps], sensor, peaks=peaks,
                        n_photosites=(1, 2, 1), times_s=[t * 1e-6 for t, _ in exps]).radiance
            tm += time.perf_counter() - t0
            reg = _regions(rad[li], mask)
            snrs.append([_snr_db(est, rad[li], reg[r]) for r in ("shadows", "midtones",
                                                                 "highlights")])
        med = np.nanmedian(np.array(snrs), axis=0)
        rig = plan.rig_time_s() + extra
        out[name] = (plan, rig, med)
        print(f"{name:26s} {plan.n_frames():6d} {plan.exposure_time_s():7.1f} {rig:7.1f} "
              f"{med[0]:7.2f} {med[1]:7.2f} {med[2]:7.2f} {tm:7.3f}")
    print("  regions: percentile bands of the lit object's true radiance: shadows 2-10 %, "
          "midtones 45-55 %, highlights > 99.5 %; adaptive plans: LED-defined exposure up to "
          "1000 mA, metering frame (1/30 s, 500 mA) counted and merged; 'shared': one exposure "
          "list for all lights (one device scan), otherwise one list per light")
    print("  rig s = exposure times + per-frame overheads (register defaults) + metering frames; "
          "the thesis reports 327.6 s of exposure for 12 lights (its list sums to 339.6 s)")
    return out


def bench_12mp(sensor, seed):
    rng = np.random.default_rng(seed)
    h, w = 2848 // 2, 4288 // 2
    rad = np.exp(rng.uniform(np.log(1e-7), np.log(2e-3), size=(h, w, 3)))
    exps = bracket_fixed("thesis2016", 1, CURRENT_MA).exposures[0]
    with tempfile.TemporaryDirectory() as d:
        paths = []
        for e, (t_us, i_ma) in enumerate(exps):
            electrons = bayer_mosaic_rggb(rad * sensor.gain_e_per_dn * t_us * i_ma)
            mosaic = sensor.expose_charge(electrons, t_us * 1e-6, rng)
            paths.append(write_dng(Path(d) / f"E{e:02d}.dng", mosaic, sensor.black_level_dn,
                                   sensor.white_level_dn, t_us * 1e-6, sensor.iso))
        t0 = time.perf_counter()
        frames = [read_raw(p) for p in paths]
        t1 = time.perf_counter()
        res = merge(frames, [t * i for t, i in exps], sensor, times_s=[t * 1e-6 for t, _ in exps])
        t2 = time.perf_counter()
    rel = np.abs(res.radiance - rad) / rad
    print(f"\n[3] one 12 MP frame set (7 DNGs 4288x2848 -> {w}x{h}x3): decode {t1 - t0:.2f} s, "
          f"inverse-variance merge {t2 - t1:.2f} s; median rel. error {np.median(rel):.4f}")
    return t1 - t0, t2 - t1


def bench_perlight(sensor, h, w, seed, target_db):
    """Rig time of per-light plans vs one shared list (the device's registers) per scene."""
    from facette.sim.lights import thesis_leds
    from facette.sim.render import radiance_per_led
    from facette.sim.scene import SCENES, make_scene
    sat = sensor.saturation_dn - sensor.black_level_dn
    print(f"\n[4] per-light vs shared adaptive plans ({target_db:g} dB), {h}x{w} half-size; "
          "rig s include one metering frame per light")
    print(f"{'scene':14s} {'brdf':8s} {'leds':4s} {'mode':6s} {'frames':>6s} {'per-light s':>11s} "
          f"{'frames':>6s} {'shared s':>9s} {'saving':>7s}")
    rows = []
    for name in sorted(SCENES):
        for brdf in ("mask", "bust", "lambert"):
            for near in (False, True):
                scene = make_scene(name, (h, w), seed=seed, brdf=brdf)
                rad = radiance_per_led(scene, thesis_leds(0.5, 0.05, near=near, seed=seed + 1))
                rad = rad / sensor.gain_e_per_dn
                mask = np.asarray(scene.mask, bool)
                mask = mask if mask.any() else np.ones(mask.shape, bool)
                rng = np.random.default_rng(seed + 2)
                meters, mexp = [], []
                for li in range(len(rad)):
                    t = 33333  # meter at 1/30 s, shorter until the object's highlight holds
                    while rad[li][mask].max() * t * CURRENT_MA > 0.9 * sat and t > 200:
                        t //= 2
                    mexp.append((t, CURRENT_MA))
                    meters.append(simulate_frames(rad[li], [mexp[-1]], sensor, rng)[0][0])
                meter_s = sum(t * 1e-6 + 0.35 for t, _ in mexp)
                for mode in ("led", "bulb", "camera"):
                    own = plan_adaptive(meters, mexp, sensor, mask, target_snr_db=target_db, mode=mode)
                    one = plan_adaptive(meters, mexp, sensor, mask, target_snr_db=target_db, mode=mode,
                                        shared=True)
                    a, b = own.rig_time_s() + meter_s, one.rig_time_s() + meter_s
                    rows.append((name, brdf, near, mode, a, b))
                    print(f"{name:14s} {brdf:8s} {'near' if near else 'far':4s} {mode:6s} "
                          f"{own.n_frames():6d} {a:11.1f} {one.n_frames():6d} {b:9.1f} "
                          f"{100 * (1 - a / b):6.1f}%", flush=True)
    saving = np.array([1 - r[4] / r[5] for r in rows])
    print(f"  saving of per-light lists: median {100 * np.median(saving):.1f} % "
          f"(min {100 * saving.min():.1f}, max {100 * saving.max():.1f}) over {len(rows)} cases")
    for name in sorted(SCENES):
        v = [1 - r[4] / r[5] for r in rows if r[0] == name]
        print(f"    {name:14s} median {100 * np.median(v):5.1f} %")
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(prog="facette bench hdr", description=__doc__.splitlines()[0])
    p.add_argument("--size", nargs=2, type=int, default=(192, 256), metavar=("H", "W"),
                   help="half-size image for parts 1 and 2 (default 192 256)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--target-db", type=float, default=40.0, help="adaptive plan's target SNR")
    p.add_argument("--skip-12mp", action="store_true", help="skip part 3 (12 MP timing)")
    p.add_argument("--perlight", action="store_true",
                   help="only part 4: per-light vs shared plans on every simulated scene")
    args = p.parse_args(argv)
    sensor = SensorModel()
    print(f"sensor: {sensor}")
    h, w = args.size
    if args.perlight:
        bench_perlight(sensor, h // 2, w // 2, args.seed, args.target_db)
        return 0
    bench_methods(sensor, h, w, args.seed)
    bench_bracketing(sensor, h, w, args.seed, args.target_db)
    bench_bracketing(sensor, h, w, args.seed, args.target_db, scene="rig")
    if not args.skip_12mp:
        bench_12mp(sensor, args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
