"""What `facette relight` opens: the picture a relighting file shows under a light, read as its viewer
reads it (`relit_picture`)."""
from pathlib import Path

from facette.errors import BadInputError

__all__ = ["relit_picture"]

OPENS = "a .ptm, a .rti, a relight_web folder (with info.json) or a relight_model.npz"


def _folder_hint(path):
    """What a folder that is not a web folder holds that relight opens (process's output folder)."""
    found = [p for p in (path / "relight_web", path / "relight_model.npz", path / "relight.rti", path / "relight.ptm")
             if (p / "info.json").is_file() or p.is_file()]
    if found:
        return "it holds " + ", ".join(str(p) for p in found) + ": give one of them"
    return f"give {OPENS} (`facette process --outputs relight-web` writes OUT/relight_web)"


def relit_picture(path, light, rtiviewer=False):
    """(picture (H, W, 3) in [0, 1] as the file's viewer shows it under `light` (3,), unit, x right,
    y up, z to the camera; a line saying what was read). A PTM as Relight reads it (`rtiviewer`:
    RTIViewer's integer coefficients), an HSH .rti as RTIViewer, a Relight web folder as openlime,
    relight_model.npz as the report's viewer (display values). BadInputError for anything else."""
    path = Path(path)
    if path.is_dir():
        if not (path / "info.json").is_file():
            raise BadInputError(f"{path} is a folder without info.json: not a Relight web folder",
                                hint=_folder_hint(path))
        from facette.io.relight_web import read_relight_web
        web = read_relight_web(path)
        layout = "deep zoom" if (path / "plane_0.dzi").is_file() else "one JPEG per plane"
        return web.relight(light), f"Relight web {web.kind.upper()} {web.terms} terms, {web.width}x{web.height}, {layout}"
    if not path.is_file():
        raise BadInputError(f"{path} is neither a file nor a folder", hint=f"give {OPENS}")
    with open(path, "rb") as fh:          # the signature only: the reader reads the file once
        head = fh.read(8)
    if head.startswith(b"PTM_1."):
        from facette.io.ptm import read_ptm
        f = read_ptm(path)
        return f.relight(light, rtiviewer=rtiviewer), f"{f.format}, {f.width}x{f.height}"
    if head.startswith(b"#HSH1.2"):
        from facette.io.rti import read_hsh_rti
        f = read_hsh_rti(path)
        return f.relight(light), f"HSH {f.terms} terms, {f.width}x{f.height}, {f.encoding}"
    if head.startswith(b"PK"):               # an .npz is a zip
        from facette.recon import load_relight_model
        model = load_relight_model(path)
        h, w = model.mask.shape
        planes = 0 if model.planes is None else model.planes.shape[-1]
        return model.display(light), (f"relighting model {w}x{h}, Blinn-Phong exponent {model.shininess:g}, "
                         f"{'cast shadows, ' if model.heights is not None else ''}{planes} residual planes")
    raise BadInputError(f"{path} is neither a PTM nor an HSH .rti file, nor a relighting model (it starts {head!r})",
                        hint=f"give {OPENS}")
