"""The checks every capture's lights pass, whoever read them (a scan's scan.json, a DiLiGenT
folder's light_directions.txt, an RTI capture's .lp or its mirror sphere): one owner, one wording,
here in the layer of the file formats so that each reader (`io.diligent`, `capture.scan`,
`capture.rti`) calls the same checks.

- a photograph listed twice (two lights, one file): refused, the lines named;
- a photograph outside the capture's folder (an .lp's absolute path, as RTIBuilder writes them,
  or '..'): the file of that name in the capture's folder is read instead, said in a note naming
  the folder; refused when the folder has none (never another capture's photographs);
- lights below the horizon (z < 0): left out, said; every light below: refused (another frame);
- lights sharing one direction (within SAME_DEG): kept (a repeated photograph is data), said;
- fewer than three distinct directions, or all in one plane through the object: refused
  (photometric stereo cannot separate the normal from the albedo).
Every figure in a note is finite (never "nan°")."""
from pathlib import Path, PureWindowsPath

import numpy as np

from facette.errors import BadInputError

__all__ = ["MIN_SPREAD", "SAME_DEG", "check_lights", "photograph_paths"]

# the smallest singular value over the largest of the directions' matrix under which the
# lights do not span three dimensions (all from one direction, or all in one plane through
# the object): photometric stereo cannot separate the normal from the albedo
MIN_SPREAD = 1e-3
# two lights closer than this (degrees) share one direction
SAME_DEG = 0.5


def _listed(labels, idx, limit=8):
    """'lines 3, 6' (labels None: the 1-based lines) or 'a.jpg, b.jpg', at most `limit` named."""
    more = "..." if len(idx) > limit else ""
    if labels is None:
        return ("line " if len(idx) == 1 else "lines ") + ", ".join(str(i + 1) for i in idx[:limit]) + more
    return ", ".join(str(labels[i]) for i in idx[:limit]) + more


def check_lights(dirs, where, labels=None):
    """(indices of the lights kept, notes) after the checks above; BadInputError otherwise.

    dirs : (m, 3) light directions (unit or not; zero or non-finite: refused), camera frame.
    where : what the lights were read from, as the notes name it ("light_directions.txt").
    labels : how a light is named in the messages (default "line k", 1-based)."""
    dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
    m = len(dirs)
    named = None if labels is None else [str(x) for x in labels]
    norms = np.linalg.norm(dirs, axis=1)
    bad = np.flatnonzero(~np.isfinite(norms) | (norms <= 0))
    if len(bad):
        raise BadInputError(f"{where}: light(s) {_listed(named, bad)} have no direction (zero or not a number)",
                            hint="every light needs a finite, non-zero direction x y z")
    unit = dirs / norms[:, None]
    below = np.flatnonzero(unit[:, 2] < 0)
    if len(below) == m:
        raise BadInputError(f"{where}: every light has z < 0, below the horizon (facette's frame: x right, y up, "
                            "z towards the camera)",
                            hint="the file is in another frame: flip the sign of z (and of y for a y-down frame)")
    notes = []
    if len(below):
        notes.append(f"{where}: {len(below)} light(s) below the horizon (z < 0; {_listed(named, below)}) left out: "
                     "they cannot light a surface the camera sees")
    keep = np.flatnonzero(unit[:, 2] >= 0)
    u = unit[keep]
    cos = np.clip(u @ u.T, -1.0, 1.0)
    same = np.triu(cos >= np.cos(np.radians(SAME_DEG)), 1)
    twins = sorted({int(j) for j in np.flatnonzero(same.any(axis=0))})
    distinct = len(keep) - len(twins)
    s = np.linalg.svd(u, compute_uv=False)
    if distinct < 3 or s[2] < MIN_SPREAD * s[0]:
        what = (f"give {distinct} distinct direction(s)" if distinct < 3 else "lie in one plane through the object")
        if distinct == 1:
            what = "all share one direction"
        raise BadInputError(f"{where}: the {len(keep)} lights {what}: photometric stereo needs lights from at least "
                            "three directions that are not in one plane",
                            hint=f"check {where} (one direction per photograph, in the photographs' order)")
    if twins:
        name = (lambda k: f"line {k + 1}") if named is None else (lambda k: named[k])
        pairs = [f"{name(keep[i])} = {name(keep[j])}" for i, j in zip(*np.nonzero(same))]
        notes.append(f"{where}: {len(twins)} light(s) share a direction with another (within {SAME_DEG:g}°: "
                     f"{', '.join(pairs[:6])}{'...' if len(pairs) > 6 else ''}): kept, as repeated photographs")
    return keep, notes


def photograph_paths(folder, names, where, first_line=2):
    """The files a capture's light table names, each in `folder`: (paths, notes). A name listed
    twice is refused (two lights, one photograph: another is then never read); a name outside
    the folder (absolute, as RTIBuilder writes them, or with '..') is read from the folder by its
    file name, with a note naming the folder, or refused when the folder has no such file; a
    missing photograph is refused. first_line: the file's line of the first name (an .lp's count
    is its line 1)."""
    folder = Path(folder)
    root = folder.resolve()
    paths, outside = [], []
    for line, name in enumerate(names, start=first_line):
        p = Path(name)
        inside = not (p.is_absolute() or PureWindowsPath(name).is_absolute() or "\\" in name) and \
            (folder / p).resolve().is_relative_to(root)
        if inside:
            q = folder / p
        else:
            q = folder / PureWindowsPath(name).name if "\\" in name else folder / p.name
            outside.append(name)
        if not q.is_file():
            where_found = "" if inside else f" (the .lp names {name}; facette reads a capture's own folder only)"
            raise BadInputError(f"{where} line {line}: {q.name} is not in {folder}{where_found}",
                                hint="the light table must name the photographs of its folder")
        paths.append(q)
    seen = {}
    for line, p in enumerate(paths, start=first_line):
        seen.setdefault(p.resolve(), []).append(line)
    twice = {p: lines for p, lines in seen.items() if len(lines) > 1}
    if twice:
        p, lines = next(iter(twice.items()))
        others = f" (and {len(twice) - 1} other photograph(s) more than once)" if len(twice) > 1 else ""
        raise BadInputError(f"{where}: {p.name} is listed {len(lines)} times (lines {', '.join(map(str, lines))})"
                            f"{others}: one photograph cannot be taken under two lights",
                            hint="give each photograph once, with its own light")
    notes = []
    if outside:
        notes.append(f"{where} names {len(outside)} photograph(s) outside the capture's folder (as {outside[0]}): "
                     f"read from {folder}, by their file names")
    return paths, notes
