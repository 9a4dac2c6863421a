"""`process`'s light-gains step: whether it runs (the option, or for "auto" what the input and the
method allow), the gains read from the photographs (facette.fit.estimate_light_gains), the images
divided by them, and what it says in the notes and process.json.

"auto" runs it on folders (DiLiGenT-style, RTI captures: intensities from a file, or none) solved
with li_alternating, whose model the gains are read against, under lights few enough that their
intensities matter (MIN_TILT) and spread enough that a 1 % intensity error tilts the normals by at
most TILT_NOTE_ABOVE (pipeline._quality): under lights bunched near the axis (DiLiGenT-Π's five,
8-18° off it) a pattern of intensities and a tilt of the normals make nearly the same images. A
scan's intensities were measured on the Spectralon at the calibration, a reference target whose
reflectance is known, which the object is not; the rig simulator's are exact. Over bands (--memory,
a capture that does not fit whole) the same gains from one more pass over the bands
(`fit.light_gains_over_bands`: each band binned as it comes), and each band divided by them.
"""
import numpy as np

from facette.fit import light_gains_over_bands
from facette.pipeline._options import GAINS_AUTO
from facette.pipeline._quality import RIG_TILT, TILT_NOTE_ABOVE, intensity_tilt

__all__ = ["light_gains_wanted", "light_gains_of_bands", "divided", "gained", "MIN_TILT"]

# under lights where a 1 % intensity error tilts the normals by less than half the rig's (DiLiGenT's
# 96: 0.22°), the step is left out: there it gave 6.26 -> 6.16° over the five crops for a second
# solve (2-3 s a crop, the whole `process` past 10 s on three of them); under the rig's 12 lights,
# 7.07 -> 6.90°
MIN_TILT = RIG_TILT / 2


def light_gains_wanted(o, inp, method_name, notes):
    """Whether `process` reads the lights' gains: the option when True or False; for "auto", a
    folder's images read whole, solved with li_alternating, under lights spread enough (else a
    note says why not)."""
    if o.light_gains != GAINS_AUTO:
        return bool(o.light_gains)
    if inp.kind == "scan" or method_name != "li_alternating":
        return False
    tilt = intensity_tilt(inp.light_dirs) if inp.light_dirs.ndim == 2 else np.inf
    if tilt < MIN_TILT:
        notes.append(f"light gains: not read (under these lights a 1 % intensity error tilts the normals by "
                     f"{tilt:.2f}° only; --light-gains reads them)")
        return False
    if not tilt <= TILT_NOTE_ABOVE:
        notes.append(f"light gains: the given intensities are kept (under these lights a 1 % intensity error "
                     f"tilts the normals by {tilt:.2f}°: the photographs cannot tell the intensities from a tilt)")
        return False
    return True


def light_gains_of_bands(res, o, inp, method_name, read, rows, bag):
    """The gains (m,) float32 to divide each band by, or None (the step not wanted, or the gains not
    applied: a note says why), read over bands of `rows` rows (read(r0, r1) -> (the images the solve sees, light directions)), the same gains
    as from the images held whole (`fit.light_gains_over_bands`)."""
    if not light_gains_wanted(o, inp, method_name, res.notes):
        return None
    gains, info = light_gains_over_bands(read, inp.mask.shape, inp.mask, rows, channel=bag.get("channel"),
                                         saturation=bag.get("saturation"), seed=bag.get("seed", 0))
    return _said(res, gains, info)


def _said(res, gains, info):
    """The gains as float32 (None when not applied); res.light_gains, its time and its note."""
    res.light_gains = info
    res.timings["light_gains"] = info["seconds"]
    if gains is None:
        res.notes.append(f"light gains: the given intensities are kept ({info['why']})")
        return None
    res.notes.append(f"light gains: the photographs put the given intensities {info['rms_percent']:.1f} % RMS "
                     f"off (at most {info['max_percent']:.1f} %); the images were divided by the gains read from "
                     "them (process.json light_gains; --no-light-gains keeps the given ones)")
    return np.asarray(gains, np.float32)


def divided(images, solve, gains):
    """(images, solve) divided by the lights' `gains` (m,) in place (as given when None): the images are
    the run's own (read for it; a folder of 12 photographs at 50 MP holds 7 GB of them), the solve's
    stack a copy of its own unless it is the images."""
    if gains is None:
        return images, solve
    g = np.asarray(gains, np.float32)[:, None, None, None]
    if solve is not images:
        solve /= g
    images /= g
    return images, solve


def gained(read, gains):
    """A band reader read(r0, r1) -> (images, ...) whose images are divided by `gains` (None: `read`)."""
    if gains is None:
        return read

    def read_gained(r0, r1):
        images, *rest = read(r0, r1)
        return (divided(images, images, gains)[0], *rest)
    return read_gained
