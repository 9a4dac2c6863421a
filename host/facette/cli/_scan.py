"""`facette scan`: acquire a scan (simulated rig or a real device), then process it.

    facette scan --sim --press-button out/scan-demo      # what `make scan` runs
    facette scan --device /dev/ttyACM0 --camera-dir ~/tether --wait-button out/plaque

Running the same command again resumes an interrupted scan.
"""
import argparse
import math
import os
import threading
import time
from pathlib import Path

from facette.cli._process import PROCESS_FIT_OPTIONS, _outputs, _size, print_result

DEFAULT_SIM_PROFILE = "calibration/profiles/sim-default"


def _limits(name):
    """(min, max) of a register in the protocol definition: the hard limits the device enforces."""
    from facette.device import registers as R

    reg = R.register(name)
    return reg.minimum, reg.maximum


def _exposures(text):
    """'adaptive', 'thesis', or '15,10,2,1,1/5,1/15,1/30' seconds (or with 'us' suffix: µs),
    optional '@mA'."""
    if text.strip().lower() in ("adaptive", "thesis"):
        return text.strip().lower()
    lo_us, hi_us = _limits("exposure_time_us")
    _, hi_ma = _limits("exposure_current_mA")
    out = []
    items = [i.strip() for i in text.split(",")]
    if not text.strip() or any(not i for i in items):
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of exposures: give times in seconds "
                                         "separated by commas, e.g. '1/5,1/50' or '250us@800'")
    for item in items:
        t_text, _, c_text = item.partition("@")
        try:
            cur = int(c_text) if c_text else 0
            if t_text.endswith("us"):
                t = float(t_text[:-2])
            else:
                num, _, den = t_text.partition("/")
                t = float(num) / (float(den) if den else 1.0) * 1e6
        except (ValueError, ZeroDivisionError):
            raise argparse.ArgumentTypeError(
                f"exposure {item!r} is not a time: write seconds ('2', '1/15'), microseconds "
                "('250us'), optionally '@mA' for its LED current ('1/5@800')") from None
        if c_text and not 1 <= cur <= hi_ma:
            raise argparse.ArgumentTypeError(f"exposure {item!r}: the current after '@' must be "
                                             f"1..{hi_ma} mA, got {cur}")
        if not t >= lo_us:
            raise argparse.ArgumentTypeError(f"exposure {item!r} is shorter than 1 µs")
        if t > hi_us:
            raise argparse.ArgumentTypeError(f"exposure {item!r} is longer than the device's hard "
                                             f"limit of {hi_us / 1e6:g} s")
        out.append((int(round(t)), cur))
    if len(out) > 16:
        raise argparse.ArgumentTypeError(f"{len(out)} exposures; a scan takes 1..16 per light")
    return out


def _lights(text):
    """'0,1,2': LED channels in scan order, each once, within the device's channels."""
    _, hi = _limits("light_order")
    try:
        out = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of LED channels: give numbers "
                                         f"separated by commas, e.g. 0,1,2 (0..{hi})") from None
    if not out:
        raise argparse.ArgumentTypeError("no LED channel given; e.g. --lights 0,1,2")
    seen = set()
    for c in out:
        if c in seen:
            raise argparse.ArgumentTypeError(f"light {c} is listed twice in {text!r}: give each LED "
                                             "channel once (a repeat would overwrite its images)")
        if not 0 <= c <= hi:
            raise argparse.ArgumentTypeError(f"LED channel {c} does not exist: channels are 0..{hi}")
        seen.add(c)
    return out


def _current(text):
    lo, hi = _limits("light_current_mA")
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--current {text!r} is not a whole number of mA") from None
    if not lo <= v <= hi:
        raise argparse.ArgumentTypeError(f"--current {v} mA is outside {lo}..{hi} mA (the device's "
                                         "hard limit; its own max_current_mA may be lower)")
    return v


def _positive(kind):
    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not v > 0:
            raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
        return v
    return parse


# The simulated rig's RAW size when none is given (scan --sim, sim, calibrate --sim): the size
# of the one-button demo, 512x384 px results where the fossil's ribs show (at 128x96 the
# maps are 64x48 px). The whole command (scan and processing) took 31 s there against 7 s at
# 128x96 on a busy 2-core machine: tests that need speed pass a small --raw-size.
SIM_RAW_SIZE = (768, 1024)     # (rows, columns)
SIM_RAW_SIZE_TEXT = f"{SIM_RAW_SIZE[1]}x{SIM_RAW_SIZE[0]}"


def _shape(text):
    """'WxH' (e.g. 128x96) -> (H, W), both at least 8 and even (a Bayer RAW)."""
    w, _, h = text.lower().partition("x")
    try:
        w, h = int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a size: write WxH, e.g. 128x96") from None
    if w < 8 or h < 8 or w % 2 or h % 2:
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be even and at least 8")
    return h, w


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
    p.add_argument("--lights", type=_lights, help="LED channels in scan order, e.g. 0,1,2 (default: all)")
    p.add_argument("--current", type=_current, default=500, help="LED current, mA (default 500)")
    p.add_argument("--mode", choices=("camera", "bulb", "led"), default="camera", help="timing mode")
    btn = p.add_mutually_exclusive_group()
    btn.add_argument("--wait-button", action="store_true", help="wait for the rig's button to start")
    btn.add_argument("--press-button", action="store_true", help="simulated rig: press its button")
    btn.add_argument("--hid-button", metavar="VID:PID", help="wait for a USB HID button (hidapi) to start")
    p.add_argument("--no-process", action="store_true", help="acquire only")
    p.add_argument("--memory", metavar="SIZE", type=_size, help="a memory budget such as 2GB: each light's HDR is written "
                   "to hdr/ and not kept in memory, and the processing after the last frame runs as "
                   "`facette process --memory SIZE` does (bands of rows, a per-pixel method; default outputs: "
                   "those that stream)")
    p.add_argument("--outputs", type=_outputs, help="what the processing after the last frame writes: a "
                   "comma-separated subset of facette process --outputs (default: all; with --memory those "
                   "that stream)")
    p.add_argument("--scene", default="plaque_sphere", help="simulated object (plaque_sphere, plaque, sphere, plane)")
    p.add_argument("--raw-size", type=_shape, default=SIM_RAW_SIZE, metavar="WxH",
                   help=f"simulated RAW size (default {SIM_RAW_SIZE_TEXT})")
    p.add_argument("--near", action="store_true", help="simulated LEDs as near point sources")
    p.add_argument("--brdf", default="mask", help="simulated material: mask (thesis: Cook-Torrance "
                   "sigma 0.05, n_i 1.2), bust (sigma 0.1, n_i 1.3) or lambert")
    p.add_argument("--faults", default="", help="simulated faults, e.g. 'biterr=1e-3,reset_at_shot=5'")
    p.add_argument("--speed", type=_positive(float), default=2000.0, help="simulated device clock (× real time)")
    p.add_argument("--sim-workdir", metavar="DIR", help="the simulated rig's folder (camera, device flash, and "
                   "the radiance it renders in bands: a later scan of the same scene and size reuses it); "
                   "default: a temporary one")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _connect(args):
    import facette

    if args.sim:
        # with a memory budget the simulator renders in bands too (it shares this process)
        bands = {}
        if args.memory:
            from facette.sim.bands import band_rows_for

            bands["render_rows"] = band_rows_for(args.raw_size[1] // 2)
        if args.sim_workdir:
            bands["workdir"] = args.sim_workdir
        return facette.connect("sim", scene=args.scene, raw_shape=args.raw_size, near=args.near,
                               brdf=args.brdf, faults=args.faults or None, speed=args.speed, **bands)
    from facette.cli._camera_options import real_rig_camera

    camera = real_rig_camera(args, Path(args.directory) / ".camera")
    return facette.connect(args.device, camera=camera)


def _preload_processing():
    """The processing chain's modules imported while the scan runs (~0.8 s that would
    otherwise come after the last frame)."""
    from facette.pipeline import preload

    preload()


def _arriving(outputs):
    """What `_process` does to each light, done as the scan's lights arrive (pipeline.ArrivingLights): the
    solve's channel too when photometric stereo will run."""
    from facette.pipeline import OUTPUTS, ArrivingLights, stages_needed

    return ArrivingLights(solve_channel="ps" in stages_needed(outputs or OUTPUTS))


def _process(scan, memory=None, outputs=None):
    """Run the processing chain on the scan just taken (the `ScanDirectory` `run_scan` returned,
    with the lights it merged held in memory unless a `memory` budget was given), with `facette
    process`'s defaults (and, with `memory`, those of `facette process --memory`), into
    SCAN/results; prints what `facette process` prints. Returns the results folder."""
    from facette.methods import PROCESS_DEFAULT, PS_DEFAULT
    from facette.pipeline import WHOLE_IMAGE_METHODS, process
    from facette.pipeline._tiled_process import STREAMED_OUTPUTS

    out = scan.path / "results"
    kw = {}
    if memory:
        kw = {"memory": memory, "outputs": list(outputs or STREAMED_OUTPUTS)}
        if PROCESS_DEFAULT in WHOLE_IMAGE_METHODS:
            kw["method"] = PS_DEFAULT
    elif outputs:
        kw["outputs"] = list(outputs)
    try:
        res = process(scan, out_dir=out, fit_options=dict(PROCESS_FIT_OPTIONS), **kw)
    finally:
        scan.release_held_lights()
    print_result(res)
    if "method" in kw:
        print(f"  note: --memory: photometric stereo with {PS_DEFAULT} (the default, {PROCESS_DEFAULT}, "
              "needs the whole image)")
    return out


def _check_directory(path):
    """The scan directory must be a folder (or not exist yet) under a folder we can write in."""
    from facette.errors import BadInputError

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise BadInputError(f"{path} is a file, not a scan directory",
                            hint="give a new folder name (or an existing scan directory to resume it)")
    parent = path if path.is_dir() else next((p for p in path.parents if p.exists()), Path("."))
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise BadInputError(f"cannot write the scan directory {path}: {parent} is not writable",
                            hint="choose a folder you can write to")


def _check_arguments(args):
    """Everything that can be checked before a rig (or its simulator) is started."""
    if args.press_button and not args.sim:
        raise SystemExit("--press-button needs --sim (a real rig's button is pressed by a person: "
                         "use --wait-button)")
    if not args.sim and not args.device:
        raise SystemExit("say which rig: --sim, or --device PORT (e.g. /dev/ttyACM0, socket://host:5020)")
    _check_directory(args.directory)
    if args.memory and not args.no_process:
        from facette.errors import BadInputError
        from facette.pipeline._tiles import BAND_FIXED_BYTES, PROCESS_BYTES, parse_memory

        least = PROCESS_BYTES + BAND_FIXED_BYTES           # whatever the image: libraries, one band's fixed part
        if parse_memory(args.memory) < least:               # found here, not after the whole scan
            raise BadInputError(f"--memory {args.memory} cannot hold the processing after the last frame: facette's "
                                f"libraries and one band take {least / 1e9:.2f} GB whatever the image",
                                hint=f"give --memory {math.ceil(least / 1e8) / 10:g}GB or more, or --no-process "
                                     "(and facette process later)")
    profile = args.profile
    if profile is None and args.sim:
        from facette._data import sim_profile_dir

        for candidate in (Path(DEFAULT_SIM_PROFILE), sim_profile_dir()):
            if candidate.is_dir():
                profile = str(candidate)
                break
    if profile is not None:
        from facette.calib import load

        profile = load(profile)        # a missing or damaged profile is named here (exit 2)
    return profile


def _scan_kept(exc, path):
    """A processing after the last frame that failed: the scan is complete and kept; the hint says
    so and gives the command that processes it (with what to change first)."""
    from facette.errors import BadInputError
    exc.message = f"the scan is complete and kept in {path}; its processing failed: {exc.message}"
    if isinstance(exc, BadInputError):                 # an option or a folder: the scan itself is fine
        exc.hint = (f"{exc.hint + '; then ' if exc.hint else ''}process it with: facette process {path} "
                    f"-o {Path(path) / 'results'}")
    return exc


def run(args):
    from facette.errors import FacetteError
    from facette.scan import ScanError

    profile = _check_arguments(args)
    if not args.no_process:
        threading.Thread(target=_preload_processing, daemon=True).start()
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
        try:
            hold = not args.no_process and not args.memory
            scan = rig.scan(args.directory, profile=profile, exposures=args.exposures, lights=args.lights,
                            light_current_mA=args.current, mode=args.mode, button=button,
                            progress=not args.quiet, merge_hdr=not args.no_process,
                            hold_hdr=hold, on_held=_arriving(args.outputs) if hold else None)
        except ScanError as exc:
            st = rig.device.stats
            if st["timeouts"]:
                exc.hint = f"{exc.hint or ''} (link: {st['requests']} requests, {st['timeouts']} timeouts)"
            raise
        sim_summary = rig.simulated_events()
        link = dict(rig.device.stats)
    finally:
        rig.close()
    t_acq = time.perf_counter() - t0
    m = scan.manifest
    print(f"scan: {len(m.frames)} frames in {scan.path} "
          f"(rig time {m.rig_time_s:.1f} s, wall time {t_acq:.1f} s)", flush=True)
    for line in scan.notes:
        print(f"  note: {line}", flush=True)
    if sim_summary and (sim_summary["missed"] or len(sim_summary["boots"]) > 1 or args.faults):
        print(f"simulated faults: {args.faults or '-'}; shots lost {sim_summary['missed']}, "
              f"boots {sim_summary['boots']}, link {link}")
    try:
        if not args.no_process:
            try:
                out = _process(scan, args.memory, args.outputs)
            except FacetteError as exc:
                raise _scan_kept(exc, scan.path) from None
            print(f"processing: facette process → {out}")
    finally:   # also when the processing stops: the scan is there
        print(f"results: {os.path.abspath(scan.path)}", flush=True)
    return 0
