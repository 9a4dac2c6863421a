"""`facette relight FILE`: open a PTM (.ptm) or HSH (.rti) file as RTIViewer and Relight read
it, and write the picture it shows under a light as a PNG."""
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
    p = sub.add_parser("relight", help="render a .ptm or .rti file under a light, as RTIViewer shows it",
                       description=__doc__.splitlines()[0])
    p.add_argument("file", help="a PTM (PTM_FORMAT_LRGB or PTM_FORMAT_JPEG_LRGB) or an HSH .rti file")
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

    from facette.errors import BadInputError
    from facette.io.png import write_png
    from facette.io.ptm import read_ptm
    from facette.io.rti import read_hsh_rti
    from facette.pipeline._record import SOFTWARE, claim_file

    path = Path(args.file)
    if not path.is_file():
        raise BadInputError(f"{path} is not a file", hint="give a .ptm or .rti file")
    out = Path(args.out) if args.out else path.with_suffix(".png")
    claim_file(out, [path], overwrite=args.overwrite)
    if out.suffix.lower() != ".png":
        raise BadInputError(f"-o {out}: relight writes PNG pictures, not {out.suffix or 'files without an extension'}",
                            hint=f"give a .png file, e.g. -o {out.with_suffix('.png')}")
    az, el = args.light
    a, e = np.radians(az), np.radians(el)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    with open(path, "rb") as fh:          # the signature only: the reader reads the file once
        head = fh.read(8)
    if head.startswith(b"PTM_1."):
        f = read_ptm(path)
        picture = f.relight(light, rtiviewer=args.rtiviewer)
        what = f"{f.format}, {f.width}x{f.height}"
    elif head.startswith(b"#HSH1.2"):
        f = read_hsh_rti(path)
        picture = f.relight(light)
        what = f"HSH {f.terms} terms, {f.width}x{f.height}, {f.encoding}"
    else:
        raise BadInputError(f"{path} is neither a PTM nor an HSH .rti file (it starts {head!r})")
    write_png(out, np.round(picture * 255).astype(np.uint8),
              text={"Software": f"{SOFTWARE} relight", "Source": str(path.resolve())})
    print(f"{path}: {what}; light azimuth {az:g}°, elevation {el:g}° -> {out}")
    return 0
