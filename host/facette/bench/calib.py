"""`facette bench calib`: calibration on the simulated rig, error and run time side by side.

The simulated rig's LEDs are perturbed (default ±15 % intensity, 2° direction RMS);
the wizard runs unattended, and the bench prints per LED the recovered intensity
(% error) and direction (degrees, mirror and matte sphere), then the normal error
of the pipeline (photometric stereo on the plaque-and-sphere scene) with the
nominal profile and with the calibrated one, and what the wizard says when a
target is missing or overexposed.

    facette bench calib [--seed N] [--direction-error DEG] [--intensity-error REL] [--near]
                        [--transcript] [--quick]
"""
import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import facette
from facette.calib import Lights, Profile, nominal_light_directions, save
from facette.pipeline import process
from facette.wizard import RigStation, Wizard, WizardError, angle_deg


def _true_lights(truth):
    """The rig's LEDs as they really are (`Lights`), from its truth (positions: None for far LEDs)."""
    pos = truth["light_positions_mm"]
    return Lights(truth["light_dirs"], truth["light_intensity"], None if np.isnan(pos).all() else pos)


def _pipeline_errors(scan_dir, methods=("hierarchical_tautzia2016", "woodham1980")):
    out = {}
    for meth in methods:
        t0 = time.perf_counter()
        res = process(scan_dir, outputs=["normals"], method=meth)
        out[meth] = (res.errors.get("normal_mean_deg", float("nan")),
                     res.errors.get("normal_median_deg", float("nan")), time.perf_counter() - t0)
    return out


def _compare_pipeline(args, work, profiles):
    """Scan each scene on a rig with the same LED errors, with each profile, and process."""
    rows = []
    for scene_label, brdf in (("Lambertian plaque+sphere", {"model": "lambert", "params": {}}),
                              ("glossy plaque+sphere (Cook–Torrance σ 0.1, n_i 1.3)", None)):
        rig = facette.connect("sim", direction_error_deg=args.direction_error,
                              intensity_error=args.intensity_error, seed=args.seed, near=args.near,
                              speed=2000.0, brdf=brdf)
        try:
            for name, prof in profiles.items():
                d = work / f"scan-{len(rows)}-{name}"
                t0 = time.perf_counter()
                rig.scan(d, profile=prof, progress=False)
                t_scan = time.perf_counter() - t0
                for meth, (mean, med, tp) in _pipeline_errors(d).items():
                    rows.append((scene_label, name, meth, mean, med, t_scan, tp))
        finally:
            rig.close()
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="facette bench calib", description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--direction-error", type=float, default=2.0, help="LED direction error, degrees RMS")
    ap.add_argument("--intensity-error", type=float, default=0.15, help="LED intensity error, relative RMS")
    ap.add_argument("--near", action="store_true", help="LEDs as near points at 1.5 m (wizard told the distance)")
    ap.add_argument("--positions", action="store_true", help="also locate the LEDs (two sphere placements)")
    ap.add_argument("--transcript", action="store_true", help="print the wizard's whole transcript")
    ap.add_argument("--quick", action="store_true", help="skip the pipeline comparison and the fault demos")
    args = ap.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="facette-bench-calib-"))
    rig = facette.connect("sim", direction_error_deg=args.direction_error, intensity_error=args.intensity_error,
                          seed=args.seed, near=args.near, speed=2000.0)
    status = 0
    try:
        truth = rig.truth()                 # the simulated rig's own LEDs and scene (`Rig.truth`)
        leds = _true_lights(truth)
        m = len(leds)
        nominal = Profile(rig="sim-nominal", lights=Lights(nominal_light_directions()[:m], np.ones((m, 3))),
                          pixel_pitch_mm=rig.pixel_pitch_mm)
        save(nominal, work / "nominal")
        lines = []
        station = RigStation(rig, work / "captures", attended=False, out=lines.append)
        steps = ["noise", "mirror", "positions", "matte", "spectralon", "gains"] if args.positions else None
        wiz = Wizard(station, out=lines.append, steps=steps, led_distance_mm=1500.0 if args.near else None)
        t0 = time.perf_counter()
        prof, path = wiz.run(work / "profile")
        t_wiz = time.perf_counter() - t0
        if args.transcript:
            print("-- wizard transcript (facette calibrate --rig sim --yes)")
            print("\n".join(lines))
            print()

        truth_dirs = leds.directions if leds.positions_mm is None else \
            leds.positions_mm / np.linalg.norm(leds.positions_mm, axis=1, keepdims=True)
        truth_int = leds.intensities / leds.intensities.mean(axis=0)
        d_err = angle_deg(prof.lights.directions, truth_dirs)
        d_nom = angle_deg(nominal_light_directions()[:m], truth_dirs)
        matte = np.array(wiz.figures["matte"]["directions"])
        m_err = angle_deg(matte, truth_dirs)
        i_err = 100 * (prof.lights.intensities / truth_int - 1)
        print(f"simulated rig: LED errors {args.direction_error}° RMS direction, ±{100 * args.intensity_error:.0f} % "
              f"RMS intensity, seed {args.seed}, {'near (1.5 m)' if args.near else 'distant'} LEDs; "
              f"HDR {truth['height_mm'].shape[1]}×{truth['height_mm'].shape[0]} px")
        print(" LED  true I (G)  I error % (R, G, B)        nominal dir err  mirror dir err  matte dir err")
        for i in range(m):
            print(f" {i:3d}  {truth_int[i, 1]:9.3f}  " + " ".join(f"{v:+6.2f}" for v in i_err[i])
                  + f"       {d_nom[i]:8.2f}°       {d_err[i]:8.3f}°      {m_err[i]:8.3f}°")
        print(f" max  intensity error {np.abs(i_err).max():.2f} %, direction error mirror {d_err.max():.3f}° "
              f"(mean {d_err.mean():.3f}°), matte {m_err.max():.3f}° (mean {m_err.mean():.3f}°)")
        if args.positions and "positions" in wiz.figures:
            est = np.array(wiz.figures["positions"]["positions_mm"])
            if leds.positions_mm is not None:
                perr = np.linalg.norm(est - leds.positions_mm, axis=1)
                print(f" LED positions (two placements 40 mm apart): error {np.median(perr):.0f} mm median, "
                      f"{perr.max():.0f} mm max at {np.linalg.norm(leds.positions_mm, axis=1).mean():.0f} mm; "
                      f"{'stored' if prof.lights.positions_mm is not None else 'not stored'}")
            else:
                print(f" LED positions: distant LEDs, rays meet at {np.median(np.linalg.norm(est, axis=1)):.0f} mm "
                      f"(median); {'stored' if prof.lights.positions_mm is not None else 'not stored'}")
        s, t = prof.sensor, rig.sensor
        print(f" sensor: gain {s['gain_e_per_dn']:.3f} e-/DN (true {t.gain_e_per_dn}), read noise "
              f"{s['read_noise_e']:.2f} e- (true {t.read_noise_e}), dark {s['dark_current_e_per_s']:.2f} e-/s "
              f"(true {t.dark_current_e_per_s}), black {s['black_level_dn']} DN (true {t.black_level_dn})")
        print(f" pixel pitch {prof.pixel_pitch_mm:.4f} mm (true {rig.pixel_pitch_mm:.4f}); "
              f"gains: LED spread {100 * wiz.figures['gains']['spread_before']:.1f} % → "
              f"{100 * wiz.figures['gains']['spread_after']:.2f} % after equalisation")
        print(f" wizard run time {t_wiz:.1f} s (all five steps, simulated device at 2000× real time)")

        if not args.quick:
            rows = _compare_pipeline(args, work, {"nominal": nominal, "calibrated": prof})
            print()
            print(" pipeline normal error against the simulator's truth (thesis bracket, same LED errors)")
            print(" scene                                              profile     method                    "
                  "mean err  median err  scan time  processing")
            for scene, name, meth, mean, med, ts, tp in rows:
                print(f" {scene:50s} {name:11s} {meth:25s} {mean:7.2f}°  {med:8.2f}°  {ts:7.1f} s  {tp:7.2f} s")
            print()
            print(" what the wizard says when a target is wrong:")
            for label, steps, kw in (("Spectralon missing", ["spectralon"], {"sim_faults": {"spectralon": "missing"}}),
                                     ("mirror sphere overexposed", ["mirror"],
                                      {"sim_faults": {"mirror_sphere": "overexposed"}}),
                                     ("Spectralon at 8 s", ["spectralon"], {"exposures": [8_000_000]})):
                st = RigStation(rig, work / "captures", attended=False, out=lambda s="": None,
                                sim_faults=kw.pop("sim_faults", None))
                w = Wizard(st, out=lambda s="": None, steps=steps, **kw)
                try:
                    w.run(work / f"fault-{label.replace(' ', '-')}")
                    print(f"  {label}: NOT DETECTED")
                    status = 1
                except WizardError as exc:
                    print(f"  {label}: ✗ {exc}")
    finally:
        rig.close()
    return status
