"""Read and write the RTI world's ``.lp`` light-position files.

Format (RTIBuilder, relight, PTM fitter): the first line is the number of lights,
then one line per light ``filename x y z`` (whitespace separated; a file name may
contain spaces, the last three fields are the numbers). Vectors are in the
camera frame x right, y up, z towards the camera, as in facette (docs/conventions.md);
most tools write unit vectors (directions), domes sometimes positions.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facette.calib.profile import Lights

__all__ = ["read_lp", "write_lp", "lights_from_lp", "write_profile_lp"]


def read_lp(path, normalize=True):
    """Read an .lp file. Returns (filenames [str] * m, vectors (m, 3) float64).

    With `normalize` the vectors are scaled to unit length (directions). Raises
    ValueError naming the line when the count or a line is malformed.
    """
    path = Path(path)
    lines = [ln.strip() for ln in path.read_text().splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise ValueError(f"{path} is empty: an .lp file starts with the number of lights")
    try:
        count = int(lines[0].split()[0])
    except ValueError:
        raise ValueError(f"{path}: the first line must be the number of lights, got {lines[0]!r}")
    body = lines[1:]
    if len(body) != count:
        raise ValueError(f"{path} announces {count} lights but lists {len(body)}")
    names, vecs = [], []
    for i, ln in enumerate(body, start=2):
        parts = ln.rsplit(None, 3)
        try:
            if len(parts) != 4:
                raise ValueError
            v = [float(p) for p in parts[1:]]
        except ValueError:
            raise ValueError(f"{path} line {i}: expected 'filename x y z', got {ln!r}") from None
        if not np.all(np.isfinite(v)) or not np.any(v):
            raise ValueError(f"{path} line {i}: the vector must be finite and non-zero, got {v}")
        names.append(parts[0])
        vecs.append(v)
    vecs = np.array(vecs, dtype=np.float64).reshape(-1, 3)
    if normalize:
        vecs /= np.linalg.norm(vecs, axis=1, keepdims=True)
    return names, vecs


def write_lp(path, filenames, vectors):
    """Write an .lp file: count, then ``filename x y z`` per light (9 decimals)."""
    v = np.asarray(vectors, float)
    if v.ndim != 2 or v.shape[1] != 3 or len(filenames) != len(v):
        raise ValueError(f"need one (x, y, z) per file name: {len(filenames)} names, vectors {v.shape}")
    bad = [f for f in filenames if not str(f).strip() or len(str(f).split()) != 1]
    if bad:
        # Relight's loader splits a line on whitespace and wants exactly 4 fields
        raise ValueError(f"file names must be non-empty and hold no spaces (Relight reads 4 fields a "
                         f"line), got {bad[:3]}")
    if len(v) > 1000:
        raise ValueError(f"{len(v)} lights: Relight's loader takes at most 1000")
    text = [str(len(v))] + [f"{f} {x:.9f} {y:.9f} {z:.9f}" for f, (x, y, z) in zip(filenames, v)]
    Path(path).write_text("\n".join(text) + "\n")
    return Path(path)


def lights_from_lp(path):
    """`facette.calib.Lights` from an .lp file: its unit directions, unit intensities
    (an .lp file carries no intensity). Returns (Lights, filenames)."""
    names, dirs = read_lp(path)
    return Lights(dirs, np.ones((len(dirs), 3))), names


def write_profile_lp(profile, path, filenames=None):
    """Write a profile's light directions as an .lp file (default file names
    ``hdr/light_XX.exr``, the HDR images of a facette scan)."""
    m = len(profile.lights)
    names = filenames or [f"hdr/light_{i:02d}.exr" for i in range(m)]
    return write_lp(path, names, profile.lights.directions)
