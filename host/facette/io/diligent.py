"""DiLiGenT-style photometric-stereo folders (Shi et al. 2016/2019).

A folder holds `filenames.txt` (one image file per line), `light_directions.txt` (one unit
vector per line, camera frame x right, y up, z towards the camera), `light_intensities.txt`
(R G B per line; images are divided by them), `mask.png`, and 16-bit PNG images.
"""
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facette._threads import run_blocks
from facette.io.lights import check_lights, photograph_paths
from facette.io.png import read_mask, read_png, write_png, write_mask

__all__ = ["DiligentData", "is_diligent_dir", "read_diligent", "read_diligent_lights", "png_radiance", "size_mismatch",
           "write_diligent"]


@dataclass
class DiligentData:
    """images (m, H, W, 3) float32 in [0, 1] divided by the light intensities, NaN where the
    PNG value was saturated; light_dirs (m, 3);
    light_intensities (m, 3); mask (H, W) bool; names (m,) file names; bit_depth 8 or 16, of
    the PNG files (truth normals are not read here); notes: what was left out and why (lights
    below the horizon)."""
    images: np.ndarray
    light_dirs: np.ndarray
    light_intensities: np.ndarray
    mask: np.ndarray
    names: list
    bit_depth: int = 16
    notes: list = field(default_factory=list)


def is_diligent_dir(path):
    path = Path(path)
    return (path / "filenames.txt").is_file() and (path / "light_directions.txt").is_file()


def _table(path, m=None, what=""):
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; a DiLiGenT folder needs {path.name} ({what})")
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = [float(v) for v in line.split()]
        except ValueError:
            row = None
        if row is None or len(row) != 3 or not all(np.isfinite(row)):
            raise ValueError(f"{path}, line {n}: {line.strip()!r} is not 3 finite numbers ({what})")
        rows.append(row)
    if m is not None and len(rows) != m:
        raise ValueError(f"{path} holds {len(rows)} lines of 3 numbers; filenames.txt lists {m} "
                         f"images ({what}: one line per image)")
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def read_diligent_lights(folder, select=None):
    """The light tables of a DiLiGenT-style folder, without its images: (names, light_dirs (m, 3)
    unit, light_intensities (m, 3), notes), lights below the horizon left out as `read_diligent`
    leaves them out (and said in notes); `select` as in `read_diligent`."""
    folder = Path(folder)
    names = [l.strip() for l in (folder / "filenames.txt").read_text().splitlines() if l.strip()]
    if not names:
        raise ValueError(f"{folder / 'filenames.txt'} lists no images")
    m = len(names)
    # the checks every capture's lights pass (io.lights): a photograph listed twice or outside the folder
    paths, notes = photograph_paths(folder, names, folder / "filenames.txt", first_line=1)
    names = [p.relative_to(folder).as_posix() for p in paths]
    dirs = _table(folder / "light_directions.txt", m, "unit light directions")
    norms = np.linalg.norm(dirs, axis=1)
    if np.any(norms <= 0):
        raise ValueError(f"{folder / 'light_directions.txt'}, line {int(np.argmin(norms)) + 1}: a zero "
                         "direction (every light needs a direction)")
    dirs = dirs / norms[:, None]
    keep, light_notes = check_lights(dirs, "light_directions.txt")
    notes += light_notes
    inten_path = folder / "light_intensities.txt"
    inten = _table(inten_path, m, "R G B intensity per light") if inten_path.is_file() else np.ones((m, 3))
    if np.any(inten <= 0):
        raise ValueError(f"{inten_path}, line {int(np.argmin(inten.min(axis=1))) + 1}: a non-positive "
                         "intensity; every light must be > 0")
    if select is not None:
        select = np.asarray(select, dtype=int).ravel()
        if select.size == 0 or select.min() < 0 or select.max() >= m:
            raise ValueError(f"select must hold image indices in 0..{m - 1} for the {m} images of "
                             f"{folder}; got {select.tolist()}")
        names, dirs, inten = [names[i] for i in select], dirs[select], inten[select]
        keep = np.flatnonzero(dirs[:, 2] >= 0)
    names, dirs, inten = [names[i] for i in keep], dirs[keep], inten[keep]
    return names, dirs, inten, notes


def size_mismatch(name, shape, first_name, first_shape):
    """The error text for a photograph `name` of (H, W, ...) `shape` in a folder whose first,
    `first_name`, is `first_shape`: what differs and what to do."""
    return (f"{name} is {shape[1]}x{shape[0]}, {first_name} is {first_shape[1]}x{first_shape[0]}: every "
            "photograph of a folder must have one size (export or crop them alike)")


def png_radiance(arr, intensity, out):
    """Stored PNG integers (H, W) grey or (H, W, 3|4) -> `out` (H, W, 3) float: divided by the
    full scale (65535 or 255) and by the light's R G B `intensity`, NaN where the value is at the
    top of the range (clipped: unknown)."""
    if arr.ndim == 2:
        arr = np.repeat(arr[..., None], 3, axis=2)
    scale = 65535.0 if arr.dtype == np.uint16 else 255.0
    rgb = arr[..., :3]
    out[...] = rgb / (scale * np.asarray(intensity))
    out[rgb >= scale] = np.nan
    return out


def read_diligent(folder, dtype=np.float32, select=None):
    """Read a DiLiGenT-style folder. Returns `DiligentData` (images divided by intensities,
    scaled so that 65535 -> 1 before the division; values at the top of the range (saturated)
    become NaN, which photometric stereo treats as missing).

    select : optional indices (0-based, into filenames.txt) of the images to read, in that
    order; the light tables are cut to match (default: every image)."""
    folder = Path(folder)
    names, dirs, inten, notes = read_diligent_lights(folder, select)
    m = len(names)
    first = read_png(folder / names[0])
    h, w = first.shape[:2]
    images = np.empty((m, h, w, 3), dtype)

    def one(i):
        arr = first if i == 0 else read_png(folder / names[i])
        if arr.shape[:2] != (h, w):
            raise ValueError(size_mismatch(names[i], arr.shape, names[0], (h, w)))
        png_radiance(arr, inten[i], images[i])

    # the PNG decoder gives the GIL up: two images at once (the 16-bit ball, 96 × 612×512:
    # 1.39 -> 0.87 s)
    run_blocks(one, range(m))
    mask_path = folder / "mask.png"
    mask = read_mask(mask_path) if mask_path.is_file() else np.ones((h, w), bool)
    if mask.shape != (h, w):
        raise ValueError(f"mask.png is {mask.shape[1]}x{mask.shape[0]}, images are {w}x{h}")
    return DiligentData(images, dirs, inten, mask, names, 16 if first.dtype == np.uint16 else 8, notes)


def write_diligent(folder, images_uint16, light_dirs, light_intensities=None, mask=None):
    """Write a DiLiGenT-style folder (for tests and exchange): images (m, H, W, 3) uint16."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    images_uint16 = np.asarray(images_uint16)
    m = len(images_uint16)
    names = [f"{i + 1:03d}.png" for i in range(m)]
    for name, img in zip(names, images_uint16):
        write_png(folder / name, img)
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    np.savetxt(folder / "light_directions.txt", np.asarray(light_dirs), fmt="%.8f")
    if light_intensities is not None:
        np.savetxt(folder / "light_intensities.txt", np.asarray(light_intensities), fmt="%.8f")
    if mask is not None:
        write_mask(folder / "mask.png", mask)
