"""`facette calibrate`: the calibration wizard.

    facette calibrate --rig sim --yes -o out/calib          # unattended, on the simulated rig
    facette calibrate --rig /dev/ttyACM0 --camera-dir ~/tether   # guided, on a real rig
    facette calibrate --rig sim --check calibration/profiles/sim-default   # drift report

Steps: noise, mirror, matte, spectralon, gains (and positions with --positions);
--only runs some of them, keeping the other values from --base (default nominal).
The profile goes to calibration/profiles/<rig>/ (or -o DIR); the previous one is kept.
Exit status: 0 done (or no drift), 1 drift beyond tolerance, 2 a step failed.
"""
import argparse
import sys
import tempfile
from pathlib import Path

from facette.cli._process import _number
from facette.cli._scan import SIM_RAW_SIZE, SIM_RAW_SIZE_TEXT, _current, _positive, _shape


def _exposures(text):
    from facette.cli._scan import _exposures as parse

    return [t for t, _ in parse(text)]


def _faults(text):
    out = {}
    for item in text.split(","):
        if not item.strip():
            continue
        k, _, v = item.partition("=")
        if k.strip() not in ("spectralon", "mirror_sphere", "matte_sphere", "lens_cap") or \
                v.strip() not in ("missing", "overexposed"):
            raise argparse.ArgumentTypeError(f"bad --sim-target-fault {item!r}: use TARGET=missing|overexposed "
                                             "with TARGET spectralon, mirror_sphere or matte_sphere")
        out[k.strip()] = v.strip()
    return out


def register(sub):
    p = sub.add_parser("calibrate", help="the calibration wizard", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rig", default="sim", help="'sim' (simulated rig) or the device's port / URL")
    p.add_argument("--camera-dir", help="folder the camera writes its RAW files to (real rigs)")
    p.add_argument("--gphoto2", action="store_true", help="tethered camera over gphoto2 (real rigs)")
    p.add_argument("-o", "--output", help="profile folder (default calibration/profiles/<rig>)")
    p.add_argument("--yes", action="store_true", help="unattended: do not wait for a person to place targets")
    p.add_argument("--button", action="store_true",
                   help="start each capture with the rig's button instead of Enter (simulated rig: pressed for you)")
    p.add_argument("--check", metavar="PROFILE", help="re-measure and report drift against this profile")
    p.add_argument("--only", help="comma-separated steps (noise,mirror,positions,matte,spectralon,gains)")
    p.add_argument("--positions", action="store_true", help="also locate the LEDs (two sphere placements)")
    p.add_argument("--base", help="profile (or an RTI .lp file) whose values are kept for steps not run "
                                  "(default nominal)")
    p.add_argument("--exposures", type=_exposures, help="bracket for every target, e.g. '1,1/4,1/16' (s)")
    p.add_argument("--current", type=_current, default=500, help="LED current during calibration, mA")
    p.add_argument("--led-distance", type=_number(float, 0, None, True, "--led-distance"), metavar="MM",
                   help="LEDs' distance from the object (e.g. 1500): directions from the field's centre, "
                        "not from the sphere (default: distant LEDs)")
    p.add_argument("--leds", type=_number(int, 4, 16, what="--leds"), default=12,
                   help="number of LEDs fitted, 4-16 (default 12)")
    p.add_argument("--keep-captures", metavar="DIR", help="keep the calibration captures in DIR")
    sim = p.add_argument_group("simulated rig")
    sim.add_argument("--sim-direction-error", type=_number(float, 0, 45, what="--sim-direction-error"), default=0.5,
                     help="LED direction error, degrees RMS, 0-45")
    sim.add_argument("--sim-intensity-error", type=_number(float, 0, 1, what="--sim-intensity-error"), default=0.05,
                     help="LED intensity error, relative RMS, 0-1")
    sim.add_argument("--sim-raw-size", type=_shape, default=SIM_RAW_SIZE, metavar="WxH",
                     help=f"RAW size (default {SIM_RAW_SIZE_TEXT})")
    sim.add_argument("--sim-near", action="store_true", help="LEDs as near point sources at 1.5 m")
    sim.add_argument("--sim-seed", type=_number(int, 0, None, what="--sim-seed"), default=0)
    sim.add_argument("--sim-speed", type=_positive(float), default=2000.0, help="device clock, × real time")
    sim.add_argument("--sim-target-fault", type=_faults, default={},
                     help="show a target wrongly, e.g. 'spectralon=missing' or 'mirror_sphere=overexposed'")
    return p


def connect_rig(args):
    import facette

    if args.rig == "sim":
        return facette.connect("sim", raw_shape=args.sim_raw_size, near=args.sim_near,
                               direction_error_deg=args.sim_direction_error,
                               intensity_error=args.sim_intensity_error, seed=args.sim_seed,
                               speed=args.sim_speed)
    from facette.cli._camera_options import real_rig_camera

    camera = real_rig_camera(args)
    return facette.connect(args.rig, camera=camera)


def run(args):
    from facette.calib import ProfileError, load
    from facette.wizard import STEPS, RigStation, Wizard, WizardError

    steps = None
    if args.only:
        steps = [s.strip() for s in args.only.split(",") if s.strip()]
        bad = [s for s in steps if s not in STEPS]
        if bad:
            raise SystemExit(f"unknown step(s) {bad}; choose from {', '.join(STEPS)}")
    elif args.positions:
        steps = ["noise", "mirror", "positions", "matte", "spectralon", "gains"]
    try:
        if args.base and args.base.endswith(".lp"):
            # directions from the RTI world (RTIBuilder, a dome's .lp), unit intensities
            from facette.calib import Profile
            from facette.calib.lp import lights_from_lp

            base = Profile(rig="lp", lights=lights_from_lp(args.base)[0])
        else:
            base = load(args.base) if args.base else None
        check = load(args.check) if args.check else None
    except ProfileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    tmp = None
    if args.keep_captures:
        workdir = Path(args.keep_captures)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="facette-calib-")
        workdir = Path(tmp.name)
    rig = connect_rig(args)
    try:
        station = RigStation(rig, workdir, attended=not args.yes, sim_faults=args.sim_target_fault,
                             n_leds=args.leds, light_current_mA=args.current, button=args.button)
        wiz = Wizard(station, out=lambda s="": print(s, flush=True), steps=steps, base=base or check,
                     exposures=args.exposures, led_distance_mm=args.led_distance)
        try:
            if check is not None:
                ok, _ = wiz.check(check)
                return 0 if ok else 1
            wiz.run(folder=args.output)
        except WizardError as exc:
            print(f"\n  ✗ {exc}", flush=True)
            print("nothing was written; the previous profile is unchanged", flush=True)
            return 2
        except EOFError:
            print("\n  ✗ no one to answer (the input is closed): run with --yes for an unattended "
                  "calibration; nothing was written", flush=True)
            return 2
        return 0
    finally:
        rig.close()
        if tmp is not None:
            tmp.cleanup()
