"""`facette process DIR -o OUT`: shape, reflectance samples and report from a scan or a
DiLiGenT-style folder.

Exit codes: 0 done, 2 a bad argument or input folder, 3 data that cannot give the result
asked for (too dark, saturated, an empty mask, too few filled cells for a BRDF fit).
"""
import argparse
import math
from types import MappingProxyType

# the BRDF fit asked for without --brdf-model/--fit-method; the scan's own processing asks for
# the same (facette.cli._scan), so that a later `facette process SCAN -o SCAN/results` finds
# one run, not another one. "auto": the model photometric stereo's evidence prefers for the main
# material, the others too when it is off, and a verdict either way (facette.fit.fit_cells_verdict)
PROCESS_FIT_OPTIONS = MappingProxyType({"model": "auto", "method": "least_squares"})


def brdf_model_choices():
    """--brdf-model's choices: "auto" and every BRDF model's name."""
    from facette.brdf import MODELS
    return ["auto", *MODELS.names()]


def _number(kind, lo=None, hi=None, lo_open=False, what="value"):
    """An argparse type: a `kind` number within [lo, hi] (lo excluded when lo_open)."""
    def parse(text):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {'whole ' if kind is int else ''}number") from None
        if not math.isfinite(v) or (lo is not None and (v <= lo if lo_open else v < lo)) \
                or (hi is not None and v > hi):
            rng = f"{'>' if lo_open else '>='} {lo:g}" if hi is None else \
                f"in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
            raise argparse.ArgumentTypeError(f"{what} must be {rng}, got {text}")
        return v
    return parse


def _size(text):
    """--memory: a size (facette._memory.parse_size: units, > 0, within this machine's memory),
    kept as written."""
    from facette._memory import parse_size
    try:
        parse_size(text, "--memory")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def _scheduler(text):
    """--scheduler: a scheduler's address (tcp://HOST:PORT), its form checked here."""
    from facette.errors import BadInputError
    from facette.pipeline._scheduler import scheduler_address
    try:
        scheduler_address(text)
    except BadInputError as exc:
        raise argparse.ArgumentTypeError(exc.message) from None
    return text


def _outputs(text):
    from facette.pipeline import ALL_OUTPUTS

    out = [o.strip() for o in text.split(",") if o.strip()]
    bad = [o for o in out if o not in ALL_OUTPUTS]
    if bad or not out:
        raise argparse.ArgumentTypeError(f"unknown output(s) {', '.join(bad) or '(none given)'}; "
                                         f"choose from {','.join(ALL_OUTPUTS)}")
    return out


def register(sub):
    from facette.brdf import MODELS
    from facette.fit import METHODS
    from facette.methods import PS_DEFAULT, PS_METHODS
    from facette.pipeline import CHANNELS, OUTPUTS, ProcessOptions
    from facette.recon import INTEGRATION_METHODS
    d = ProcessOptions()            # the defaults: defined once, there
    p = sub.add_parser("process", help="process a scan, a DiLiGenT-style folder or an RTI capture",
                       description=__doc__.splitlines()[0])
    p.add_argument("source", help="scan directory (scan.json, hdr/), DiLiGenT-style folder, or RTI capture "
                                  "(photographs with an .lp file, or with a mirror sphere in view)")
    p.add_argument("-o", "--out", required=True, help="output directory (created)")
    p.add_argument("--outputs", type=_outputs, default=list(OUTPUTS),
                   help=f"comma-separated subset of {','.join(OUTPUTS)} (default: all), or relight-web "
                        "(Relight's web format for openlime, asked for by name); only the stages they need run")
    p.add_argument("--method", default=None, choices=list(PS_METHODS),
                   help=f"photometric stereo (default {d.method}: BRDF-aware, the LI model fitted per "
                        "material and the normals re-estimated against it where the data show a lobe; "
                        f"{PS_DEFAULT}: robust Lambertian, a few times faster); "
                        f"with --memory the default is {PS_DEFAULT}, a per-pixel method")
    p.add_argument("--init", default=None,
                   choices=[m for m in PS_METHODS if m != "li_alternating"],
                   help=f"initial normals of --method li_alternating (default its own, {PS_DEFAULT}; the "
                        "hierarchy is better on satins); the other methods take none")
    p.add_argument("--channels", default=d.channels, choices=list(CHANNELS),
                   help=f"colour channels the normals are solved on (default {d.channels}, chosen on renders: mean "
                        "of R, G, B; weighted: by mean/variance, the noise estimated from the images; green, "
                        "the thesis's); "
                        "the albedo stays per channel")
    p.add_argument("--interreflections", action=argparse.BooleanOptionalAction, default=None,
                   help="take the light a concave surface gathers from itself out of the images first "
                        "(craters, grooves, a vase's neck); with li_alternating also what glossy walls mirror "
                        "into each other. Default: on a reflectance-calibrated scan read whole, off elsewhere "
                        "(a note says why); asked for on a folder or capture, the albedo's scale is estimated "
                        "from the images; --no-interreflections: never")
    p.add_argument("--shadows", choices=("auto", "on", "off"), default="auto",
                   help="leave out the lights the surface hides from itself (a horizon test on its heights, "
                        "alternated with the normals); auto (default): where they hide enough samples")
    p.add_argument("--light-gains", action=argparse.BooleanOptionalAction, default=None,
                   help="read each light's relative intensity from the photographs and correct the given "
                        "ones (light_intensities.txt, or none) before the normals. Default: for folders "
                        "solved with the default method under lights whose intensities weigh and can be "
                        "told from a tilt (a 1 %% error tilting the normals by 0.37-1.48 deg: a rig's 12, "
                        "not DiLiGenT's 96 nor five near the axis), not for scans (their intensities come "
                        "from the Spectralon); a note says what was done or why not; --no-light-gains: never")
    p.add_argument("--integration", default=d.integration, choices=list(INTEGRATION_METHODS),
                   help=f"normal integration (default {d.integration}: the object needs a flat "
                        "margin around it, as for frankot_chellappa1988, the thesis's; least_squares "
                        "integrates the mask only)")
    p.add_argument("--t-ombre", type=_number(float, 0, math.pi / 2, True, "--t-ombre"), default=d.t_ombre,
                   help="shadow angle threshold, rad, in (0, pi/2] (1.5)")
    p.add_argument("--t-spec", type=_number(float, 0, None, True, "--t-spec"), default=d.t_spec,
                   help="specular variance threshold (0.25)")
    p.add_argument("--t-source", type=_number(float, 0, None, True, "--t-source"), default=d.t_source,
                   help="max |entry| of a triplet's inverse (10)")
    p.add_argument("--t-residual", type=_number(float, 0, None, False, "--t-residual"), default=d.t_residual,
                   help="LS residual under which a pixel skips the hierarchy (0.03; 0 = never)")
    p.add_argument("--theta0", type=_number(float, 0, 90, True, "--theta0"), default=d.theta0_deg,
                   help="hemisphere cell size, deg (3)")
    p.add_argument("--mask", help="mask PNG (non-zero = object)")
    p.add_argument("--pixel-pitch", type=_number(float, 0, None, True, "--pixel-pitch"),
                   help="object-side pixel size in mm, > 0 (overrides the scan)")
    p.add_argument("--far-light", action="store_true",
                   help="ignore light positions: one direction per light for every pixel")
    p.add_argument("--mesh-step", type=_number(int, 1, None, False, "--mesh-step"),
                   help="mesh vertex every N pixels, >= 1 (default: <= ~1e6 vertices)")
    p.add_argument("--ascii-ply", action="store_true", help="write mesh.ply as ASCII")
    p.add_argument("--brdf-model", default=PROCESS_FIT_OPTIONS["model"], choices=brdf_model_choices(),
                   help="model fitted for brdf.json (default auto: the one photometric stereo's evidence "
                        "prefers, the others too when it fits badly, and a verdict)")
    p.add_argument("--fit-method", default=PROCESS_FIT_OPTIONS["method"], choices=list(METHODS.names()),
                   help="fit method")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="process a scan that is not complete (every output then says so)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of an earlier run with other options in OUT")
    p.add_argument("--encoding", choices=("srgb", "linear"),
                   help="RTI capture: how the photographs encode light (default: srgb for 8-bit files, "
                        "linear for 16-bit and float ones)")
    p.add_argument("--sphere", help="RTI capture without .lp: the mirror sphere as cx,cy,r (px) or a mask PNG "
                                    "(default: found in the photographs)")
    p.add_argument("--reference", help="RTI capture: x0,y0,x1,y1 (px) of a white or grey patch in every "
                                       "photograph; each photograph is divided by its level there")
    p.add_argument("--memory", metavar="SIZE", type=_size, default=d.memory,
                   help="a memory budget such as 2GB or 3GiB for the whole process: photometric stereo runs over "
                        "bands of rows in what the libraries (0.45 GB) and the maps kept at the image's size leave "
                        "(a per-pixel --method); a scan's or DiLiGenT folder's images are read band by band, never "
                        "whole (default: untiled)")
    p.add_argument("--scheduler", metavar="ADDRESS", type=_scheduler, default=d.scheduler,
                   help="with --memory: a running dask.distributed scheduler, e.g. tcp://host:8786, whose workers "
                        "run the bands (they must see the same paths; the same flag as facette batch)")
    p.add_argument("--hsh-order", type=int, default=d.hsh_order, choices=(2, 3),
                   help="hemispherical-harmonics order of relight.rti (2: 4 terms, 3: 9 terms)")
    p.add_argument("--ptm-format", default=d.ptm_format, choices=("auto", "lrgb", "rgb"), help="relight.ptm: lrgb "
                   "(luminance x colour), rgb (per channel, 2x the bytes), auto (the smaller leave-one-light-out error)")
    p.add_argument("--rti-encoding", default=d.rti_encoding, choices=("auto", "srgb", "linear"),
                   help="values of relight.ptm, relight.rti and relight_web: auto (default: as photographed, "
                        "the photographs' scale and encoding; an HDR scan sRGB at an exposure that clips "
                        "<= 0.1 %% of the object), srgb (display values) or linear (proportional to radiance)")
    return p


def _check_out(out):
    """The output folder: a folder (or absent) under one we can write in, checked before any work."""
    import os
    from pathlib import Path

    from facette.errors import BadInputError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise BadInputError(f"-o {out} is a file, not a folder", hint="give a new folder for the results")
    parent = out if out.is_dir() else next((p for p in out.parents if p.exists()), Path("."))
    if parent.exists() and not parent.is_dir():
        raise BadInputError(f"cannot write the results to {out}: {parent} is a file, not a folder",
                            hint="give a folder path for -o")
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise BadInputError(f"cannot write the results to {out}: {parent} is not writable",
                            hint="choose a folder you can write to (-o)")


def _capture(args):
    """The RTI capture options of `process` from --encoding, --sphere, --reference."""
    from facette.capture.rti import parse_box, parse_circle

    return {"encoding": args.encoding,
            "sphere": parse_circle(args.sphere) if args.sphere else None,
            "reference": parse_box(args.reference) if args.reference else None}


def _method(args):
    """--method, or its default: PROCESS_DEFAULT, or with --memory PS_DEFAULT when the former needs
    the whole image (li_alternating)."""
    from facette.methods import PROCESS_DEFAULT, PS_DEFAULT
    from facette.pipeline import WHOLE_IMAGE_METHODS

    if args.method is not None:
        return args.method
    return PS_DEFAULT if args.memory and PROCESS_DEFAULT in WHOLE_IMAGE_METHODS else PROCESS_DEFAULT


def options(args):
    """The ProcessOptions of parsed `facette process` arguments."""
    from facette.pipeline import GAINS_AUTO, IR_AUTO, ProcessOptions

    return ProcessOptions(
        method=_method(args), integration=args.integration, t_ombre=args.t_ombre, t_spec=args.t_spec,
        t_source=args.t_source, t_residual=args.t_residual, theta0_deg=args.theta0, mask=args.mask,
        pixel_pitch_mm=args.pixel_pitch, near_light=not args.far_light, mesh_step=args.mesh_step,
        ascii_ply=args.ascii_ply, fit_options={"model": args.brdf_model, "method": args.fit_method},
        hsh_order=args.hsh_order, ptm_format=args.ptm_format,
        rti_encoding=args.rti_encoding, allow_incomplete=args.allow_incomplete, overwrite=args.overwrite,
        interreflections=IR_AUTO if args.interreflections is None else args.interreflections,
        light_gains=GAINS_AUTO if args.light_gains is None else args.light_gains, shadows=args.shadows,
        capture=_capture(args), memory=args.memory,
        scheduler=args.scheduler, channels=args.channels,
        ps_options={"init": args.init} if args.init else None)     # li_alternating takes it, the others leave it


def _stopped_scan(source):
    """(lights with a frame, lights planned) of a scan that stopped before its last light, or None."""
    from pathlib import Path

    from facette.scan import ScanDirectory
    if not (Path(source) / "scan.json").is_file():
        return None
    try:
        m = ScanDirectory(source).manifest
    except (ValueError, OSError):
        return None
    taken = len({f.light for f in m.frames})
    return (taken, len(m.lights)) if taken < len(m.lights) else None


def _resume_advice(exc, source):
    """Too few lights in a scan that stopped: the advice is to resume it, not to plan more lights."""
    stopped = _stopped_scan(source)
    if stopped and "lights" in exc.message:
        exc.hint = (f"the scan stopped at {stopped[0]} of its {stopped[1]} lights: run the facette scan command that "
                    f"made it again (the same directory: it resumes), then process it")
    return exc


def run(args):
    from facette.errors import InsufficientData
    from facette.methods import PROCESS_DEFAULT
    from facette.pipeline import process

    _check_out(args.out)
    opts = options(args)                          # every option checked before the scheduler is asked
    if args.scheduler is not None:
        from facette.pipeline._scheduler import check_scheduler
        check_scheduler(args.scheduler)           # something listens there, within seconds
    try:
        res = process(args.source, outputs=args.outputs, out_dir=args.out, options=opts)
    except InsufficientData as exc:
        raise _resume_advice(exc, args.source) from None
    print_result(res)
    if _method(args) != PROCESS_DEFAULT and args.method is None:
        print(f"  note: --memory: photometric stereo with {_method(args)} (the default, {PROCESS_DEFAULT}, needs "
              "the whole image; --method chooses another per-pixel one)")
    return 0


def print_result(res):
    """What `process` did, for a person: the input, its figures, the notes, the files."""
    h, w = res.mask.shape[:2]
    print(f"{res.inputs.kind} {res.inputs.source}: {len(res.inputs.light_dirs)} lights, {w}x{h} px, "
          f"{int(res.mask.sum())} valid pixels, object {int(res.object_mask.sum())} "
          + (f"({res.options['method']})" if res.ps is not None else "(no photometric stereo: not needed)"))
    ir = res.interreflections
    if ir is not None and "scale_identified" in ir and not ir["applied"]:     # "auto" without a Spectralon
        # "auto" removes wherever the scale is identified: left in means it was not
        print("  inter-reflections left in: the images do not tell the albedo's scale (see the notes)")
    elif ir is not None:
        print(f"  inter-reflections: {100 * ir['median_fraction']:.1f} % of the median value, "
              f"{100 * ir['p95_fraction']:.1f} % at the 95th percentile"
              + (f" (removed in {len(ir['passes'])} pass(es))" if ir["applied"] else " (too little: left in)")
              + f", {ir['seconds']:.1f} s")
        if ir.get("glossy"):
            g = ir["glossy"]
            from facette.fit import glossy_lobes_text
            print(f"  glossy inter-reflections ({glossy_lobes_text(g)}): "
                  f"{100 * g['median_fraction']:.1f} % of the median value, {100 * g['p95_fraction']:.1f} % "
                  f"at the 95th percentile, {g['seconds']:.1f} s")
    lg = res.light_gains
    if lg is not None and lg["applied"]:
        print(f"  light gains: the given intensities {lg['rms_percent']:.1f} % RMS off (at most "
              f"{lg['max_percent']:.1f} %), corrected; {lg['seconds']:.1f} s")
    info = res.ps.info if res.ps is not None else {}
    if "skipped_fraction" in info:
        print(f"  least squares explained {100 * info['skipped_fraction']:.1f} % of the pixels "
              "(hierarchy skipped there)")
    for k, v in res.errors.items():
        print(f"  against truth: {k} = {v:.3f}")
    for k, v in res.fit_errors.items():
        print(f"  relighting against the images: {k} = {v:.4f}")
    print("  times: " + ", ".join(f"{k} {v:.2f} s" for k, v in res.timings.items()))
    if res.brdf is not None:
        print(f"  brdf: {res.brdf}")
    for note in res.notes:
        print(f"  note: {note}")
    for o, path in res.files.items():
        print(f"  wrote {path}")
