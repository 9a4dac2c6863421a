"""`facette relight FILE`: open what `facette process` writes for relighting (relight.ptm, relight.rti,
a relight_web/ folder, relight_model.npz) as its viewer shows it, and write the picture under a light
as a PNG: a PTM or HSH file as RTIViewer and Relight read it, a web folder as openlime does, the
relighting model as the report's viewer draws it."""
import argparse
import math


def _light(text):
    """--light AZ,EL: finite degrees, the elevation in [0, 90] (a light below the horizon
    lights nothing the camera sees; RTIViewer's light is on the hemisphere too)."""
    try:
        az, el = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not AZ,EL in degrees, e.g. 0,20") from None
    if not (math.isfinite(az) and math.isfinite(el)):
        raise argparse.ArgumentTypeError(f"{text!r}: the angles must be finite degrees")
    if not 0 <= el <= 90:
        raise argparse.ArgumentTypeError(f"elevation {el:g}° is outside [0, 90] (0: grazing, 90: along the "
                                         f"camera's axis); e.g. {az:g},{min(max(abs(el), 0), 90):g}")
    return az, el


def register(sub):
    p = sub.add_parser("relight", help="render a .ptm, .rti, relight_web folder or relight_model.npz under a light",
                       description=" ".join(__doc__.split("\n\n")[0].split()))
    p.add_argument("file", help="a PTM (PTM_FORMAT_LRGB or PTM_FORMAT_JPEG_LRGB), an HSH .rti file, a Relight web "
                                "folder (info.json + planes, deep zoom included) or process's relight_model.npz")
    p.add_argument("--light", type=_light, default="0,90", metavar="AZ,EL",
                   help="light azimuth and elevation in degrees (azimuth 0 = from the right, 90 = "
                        "from the top of the picture; elevation 0-90, 90 = along the camera's axis); default 0,90")
    p.add_argument("-o", "--out", help="PNG to write (default: FILE with .png); an existing file only if facette "
                                       "made it, or with --overwrite; never FILE itself")
    p.add_argument("--overwrite", action="store_true", help="replace an existing -o file that facette did not make")
    p.add_argument("--rtiviewer", action="store_true",
                   help="PTM: integer coefficients, as RTIViewer keeps them (default: Relight's floats)")
    return p


def run(args):
    from pathlib import Path

    import numpy as np

    from facette.cli._relight_open import relit_picture
    from facette.errors import BadInputError
    from facette.io.png import write_png
    from facette.pipeline._record import SOFTWARE, claim_file

    path = Path(args.file)
    if not path.exists():
        raise BadInputError(f"{path} does not exist", hint="give a .ptm, .rti, relight_web folder or relight_model.npz")
    out = Path(args.out) if args.out else path.with_suffix(".png")
    claim_file(out, [path], overwrite=args.overwrite)
    if path.is_dir() and path.resolve() in out.resolve().parents:
        raise BadInputError(f"-o {out} is inside the folder {path} (facette never writes into its inputs)",
                            hint=f"choose a file outside it, e.g. -o {path.with_suffix('.png')}")
    if out.suffix.lower() != ".png":
        raise BadInputError(f"-o {out}: relight writes PNG pictures, not {out.suffix or 'files without an extension'}",
                            hint=f"give a .png file, e.g. -o {out.with_suffix('.png')}")
    az, el = args.light
    a, e = np.radians(az), np.radians(el)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    picture, what = relit_picture(path, light, args.rtiviewer)
    write_png(out, np.round(picture * 255).astype(np.uint8),
              text={"Software": f"{SOFTWARE} relight", "Source": str(path.resolve())})
    print(f"{path}: {what}; light azimuth {az:g}°, elevation {el:g}° -> {out}")
    return 0
