"""`facette scan`: acquire a scan (simulated rig or a real device), then process it.

    facette scan --sim --press-button out/scan-demo      # what `make scan` runs
    facette scan --device /dev/ttyACM0 --camera-dir ~/tether --wait-button out/plaque

Running the same command again resumes an interrupted scan.
"""
import argparse
import os
import sys
import time
from pathlib import Path

DEFAULT_SIM_PROFILE = "calibration/profiles/sim-default"


def _exposures(text):
    """'adaptive', 'thesis', or '15,10,2,1,1/5,1/15,1/30' seconds (or with 'us' suffix: µs),
    optional '@mA'."""
    if text.strip().lower() in ("adaptive", "thesis"):
        return text.strip().lower()
    out = []
    for item in text.split(","):
        item = item.strip()
        cur = 0
        if "@" in item:
            item, c = item.split("@", 1)
            cur = int(c)
        if item.endswith("us"):
            t = float(item[:-2])
        else:
            num, _, den = item.partition("/")
            t = float(num) / (float(den) if den else 1.0) * 1e6
        if not t >= 1:
            raise argparse.ArgumentTypeError(f"exposure {item!r} is shorter than 1 µs")
        out.append((int(round(t)), cur))
    return out


def _ints(text):
    return [int(v) for v in text.split(",") if v.strip()]


def _shape(text):
    w, _, h = text.lower().partition("x")
    return int(h), int(w)


def register(sub):
    p = sub.add_parser("scan", help="acquire a scan (simulated rig or a real device)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("directory", help="scan directory (created; an existing one is resumed)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--sim", action="store_true", help="start a simulated rig (device + camera)")
    src.add_argument("--device", metavar="URL", help="serial port, pty or socket://host:port of the rig")
    p.add_argument("--camera-dir", help="folder the camera writes its RAW files to (real rigs)")
    p.add_argument("--gphoto2", action="store_true", help="tethered camera over gphoto2 (real rigs)")
    p.add_argument("--profile", help=f"calibration profile folder (default with --sim: {DEFAULT_SIM_PROFILE})")
    p.add_argument("--exposures", type=_exposures, default="adaptive",
                   help="'adaptive' (default: meter each light, then the fewest exposures giving "
                   "40 dB on the object without clipping it), 'thesis' (the thesis's fixed bracket "
                   "15,10,2,1,1/5,1/15,1/30 s) or a list, e.g. '1,1/8,1/30' (s; 'NNNus' for µs; "
                   "'@mA' per exposure)")
    p.add_argument("--lights", type=_ints, help="LED channels in scan order, e.g. 0,1,2 (default: all)")
    p.add_argument("--current", type=int, default=500, help="LED current, mA (default 500)")
    p.add_argument("--mode", choices=("camera", "bulb", "led"), default="camera", help="timing mode")
    btn = p.add_mutually_exclusive_group()
    btn.add_argument("--wait-button", action="store_true", help="wait for the rig's button to start")
    btn.add_argument("--press-button", action="store_true", help="simulated rig: press its button")
    btn.add_argument("--hid-button", metavar="VID:PID", help="wait for a USB HID button (hidapi) to start")
    p.add_argument("--no-process", action="store_true", help="acquire only")
    p.add_argument("--scene", default="plaque_sphere", help="simulated object (plaque_sphere, plaque, sphere, plane)")
    p.add_argument("--raw-size", type=_shape, default=(96, 128), metavar="WxH",
                   help="simulated RAW size (default 128x96)")
    p.add_argument("--near", action="store_true", help="simulated LEDs as near point sources")
    p.add_argument("--brdf", default="mask", help="simulated material: mask (thesis: Cook-Torrance "
                   "sigma 0.05, n_i 1.2), bust (sigma 0.1, n_i 1.3) or lambert")
    p.add_argument("--faults", default="", help="simulated faults, e.g. 'biterr=1e-3,reset_at_shot=5'")
    p.add_argument("--speed", type=float, default=2000.0, help="simulated device clock (× real time)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _connect(args):
    import facette

    if args.sim:
        return facette.connect("sim", scene=args.scene, raw_shape=args.raw_size, near=args.near,
                               brdf=args.brdf, faults=args.faults or None, speed=args.speed)
    if not args.device:
        raise SystemExit("say which rig: --sim, or --device PORT (e.g. /dev/ttyACM0, socket://host:5020)")
    from facette.cli._camera_options import real_rig_camera

    camera = real_rig_camera(args, Path(args.directory) / ".camera")
    return facette.connect(args.device, camera=camera)


def _process(scan_dir):
    """Run whatever processing stages exist; returns the list of what ran."""
    import importlib.util

    ran = []
    if importlib.util.find_spec("facette.pipeline") is not None:
        from facette.cli.main import main as cli_main

        out = Path(scan_dir) / "results"
        status = cli_main(["process", str(scan_dir), "-o", str(out)])
        ran.append(f"facette process → {out} (exit {status})")
    return ran


def run(args):
    from facette.device import DeviceError
    from facette.scan import ScanError
    from facette._data import sim_profile_dir

    profile = args.profile
    if profile is None and args.sim:
        for candidate in (Path(DEFAULT_SIM_PROFILE), sim_profile_dir()):
            if candidate.is_dir():
                profile = str(candidate)
                break
    t0 = time.perf_counter()
    rig = _connect(args)
    try:
        ident = rig.identity
        print(f"rig: {rig.device.url} firmware {ident['fw_version']} definition {ident['definition_hash']} "
              f"boot {ident['boot_count']}", flush=True)
        button = "press" if args.press_button else "wait" if args.wait_button else None
        if args.hid_button:
            from facette.device.hid_button import HidButton, parse_vid_pid

            hid_button = HidButton(*parse_vid_pid(args.hid_button))
            print("press the USB button to start the scan", flush=True)
            hid_button.wait_press()
            hid_button.close()
        if button == "press" and rig.sim is None:
            raise SystemExit("--press-button needs --sim (a real rig's button is pressed by a person: "
                             "use --wait-button)")
        try:
            scan = rig.scan(args.directory, profile=profile, exposures=args.exposures, lights=args.lights,
                            light_current_mA=args.current, mode=args.mode, button=button,
                            progress=not args.quiet, merge_hdr=not args.no_process)
        except (ScanError, DeviceError) as exc:
            print(f"scan stopped: {exc}", file=sys.stderr)
            print(f"link: {rig.device.stats}", file=sys.stderr)
            return 1
        sim_summary = rig.sim.summary() if rig.sim is not None else None
        link = dict(rig.device.stats)
    finally:
        rig.close()
    t_acq = time.perf_counter() - t0
    m = scan.manifest
    print(f"scan: {len(m['frames'])} frames in {scan.path} "
          f"(rig time {m['rig_time_s']:.1f} s, wall time {t_acq:.1f} s)", flush=True)
    if sim_summary and (sim_summary["missed"] or len(sim_summary["boots"]) > 1 or args.faults):
        print(f"simulated faults: {args.faults or '-'}; shots lost {sim_summary['missed']}, "
              f"boots {sim_summary['boots']}, link {link}")
    if not args.no_process:
        ran = _process(scan.path)
        print("processing: " + ("; ".join(ran) if ran else "no processing stage is installed yet"))
    print(f"results: {os.path.abspath(scan.path)}")
    return 0
