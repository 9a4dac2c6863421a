"""Quality gates: a result is called "ok" only when the data can carry it.

A sample (one pixel under one light) is *usable* when it is known (not saturated in every
exposure: NaN), and above the noise: signal >= MIN_SNR standard deviations of its own
variance (scans, from the HDR merge's _var.exr), or >= MIN_LEVELS grey levels of the
image's bit depth (DiLiGenT-style PNG folders). Photometric stereo needs MIN_LIGHTS usable
lights per pixel; when fewer than MIN_PIXEL_FRACTION of the object's pixels have them, the
data cannot give shapes, and processing stops with `InsufficientData` (exit code 3) saying
what to change (exposure, current, mask), unless the lit samples stand far above the rest
(SPARSE_CONTRAST): an object dark by its nature between its highlights (a bare metal) is processed,
its unlit pixels' normals interpolated. A BRDF fit needs MIN_FIT_CELLS filled cells of the
hemisphere sensor.

Thresholds measured on simulated scans (32x24 px object, see the note of issue 14): good
scans (12 lights × the thesis bracket, 4 lights × 2 exposures) have 99.9-100 % of their
pixels with >= 3 usable lights; `--exposures 1us` 0 %; `--exposures 15@1000` 43 % (57 % of
the pixels saturated under every light).
"""
import numpy as np

from facette.capture.usable import MIN_LEVELS, MIN_SNR, usable_from_green, usable_from_levels, usable_from_variance
from facette.errors import InsufficientData

__all__ = ["MIN_SNR", "MIN_LEVELS", "MIN_LIGHTS", "MIN_PIXEL_FRACTION", "MIN_FIT_CELLS", "SPARSE_CONTRAST",
           "LIT_PERCENTILE", "MIN_SPARSE_FRACTION", "TILT_NOTE_ABOVE", "lit_contrast", "carried", "intensity_tilt",
           "light_geometry", "usable_from_variance", "usable_from_green", "usable_from_levels", "check_samples",
           "check_fit_cells", "sample_counts", "add_counts", "check_counts", "truth_errors"]

MIN_LIGHTS = 3             # usable lights per pixel for a normal
MIN_PIXEL_FRACTION = 0.5   # of the object's pixels that need MIN_LIGHTS usable lights
SPARSE_LIGHT = 0.05        # a light usable on fewer of the object's pixels is named in a note
MIN_FIT_CELLS = 10         # filled hemisphere cells for a BRDF fit (the li model has 5 parameters)
# a scan below MIN_PIXEL_FRACTION whose lit samples stand this far above the others (`lit_contrast`)
# is dark by its nature, not its exposure: processed, the rest filled (pipeline._filled). 12 lights,
# unit noise (LIT_PERCENTILE's value): a matte sphere 3 σ bright gives 1.7 (10 σ: 3.7), a
# Blinn-Phong lobe (exponent 100) 3000 σ / 300 σ high 799 / 84; Mitsuba's bare gold sphere written
# as 8-bit PNGs with read and shot noise 111 (aluminium 183)
SPARSE_CONTRAST = 30.0
# the lit samples' value lit_contrast reads: their 90th percentile, not their median. Where the
# noise crosses the usable threshold now and then, those crossings sit among a metal's lit samples
# and pull their median down to the noise (the 8-bit gold sphere: median 17.5, refused with "lengthen
# the exposures"; the 300 σ lobe: 10); the upper tail is its highlights. A dim scan has none (1.7).
LIT_PERCENTILE = 90
MIN_SPARSE_FRACTION = 0.1  # ... provided this much of the object still has MIN_LIGHTS usable lights
# the normals' tilt for a 1 % error in each light's intensity (`intensity_tilt`): 0.74° under the
# thesis rig's 12 lights (15° and 30° from the view), 0.22° under DiLiGenT's 96 (4-43°), 1.19° under
# the Goldman-Seitz set's 12 (6-39°), 2.42° under DiLiGenT-Π's first 5 (8-18°), whose flat coins came
# out 66-70° tilted, least squares and li_alternating alike, with their intensities unknown (ones).
# A note above twice the rig's.
RIG_TILT = 0.74
TILT_NOTE_ABOVE = 2 * RIG_TILT
COUNT_ROWS = 32 * 8        # rows `check_samples` counts at a time: a multiple of CONTRAST_STEP (the same values)
CONTRAST_STEP = 8          # lit_contrast reads every 8th row and column (12 MP x 12: 2.3 M values, not 147 M)


def check_samples(images, usable, object_mask, mask_source, light_names=None):
    """Raise InsufficientData when the data cannot give normals; else return notes (list of str)
    and a summary dict.

    images : (m, H, W, C) with NaN where unknown (saturated); usable : (m, H, W) bool;
    object_mask : (H, W) bool, the pixels that should get a result (the given mask, or the
    lit pixels plus those saturated under some light); mask_source : words for the mask
    ("mask.png", "--mask FILE", "the lit pixels"); light_names : m labels for notes.
    """
    if images.shape[0] <= MIN_LIGHTS or not np.any(object_mask):    # said before any count
        return check_counts({"m": images.shape[0], "object": int(np.count_nonzero(object_mask))}, mask_source)
    counts = None              # by bands of rows: the (m, H, W) flags of one band at a time (16 x 12 MP: 0.45 GB less)
    for r0 in range(0, images.shape[1], COUNT_ROWS):
        r1 = r0 + COUNT_ROWS
        counts = add_counts(counts, sample_counts(images[:, r0:r1], usable[:, r0:r1], object_mask[r0:r1]))
    return check_counts(counts, mask_source, light_names)


def lit_contrast(counts):
    """How far the object's samples above the noise stand above those below it, from the value
    samples of `sample_counts`: the LIT_PERCENTILE-th percentile of the usable ones over the 90th
    percentile of the others (green; inf when those are all 0, nan when either set is empty). A
    dim scan's lit samples sit just above the noise (a few times the rest); a bare metal's include
    its highlights, far above a rest that no exposure would light."""
    lit, dark = counts.get("lit_values", np.empty(0)), counts.get("dark_values", np.empty(0))
    if lit.size == 0 or dark.size == 0:
        return float("nan")
    floor = float(np.percentile(dark, 90))
    return float(np.percentile(lit, LIT_PERCENTILE)) / floor if floor > 0 else float("inf")


def intensity_tilt(light_dirs):
    """Degrees the normal facing the camera tilts (RMS) when each light's intensity is 1 % off,
    independently: least squares' g = S⁺ e moves by S⁺ δe with δe_j = 0.01 e_j ξ_j. Distant lights
    (m, 3); nan when fewer than three light that normal or they do not span 3-D. It grows as the
    lights close in on the view: they then differ little, and a normal is read from small
    differences between them."""
    s = np.asarray(light_dirs, np.float64)
    if s.ndim != 2 or s.shape[1] != 3:
        return float("nan")
    s = s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)
    lit = s[:, 2] > 0
    if lit.sum() < 3 or np.linalg.matrix_rank(s[lit], tol=1e-6) < 3:
        return float("nan")
    p = np.linalg.pinv(s[lit])
    return float(np.degrees(0.01 * np.sqrt(np.sum((p[:2] * s[lit, 2]) ** 2))))


def light_geometry(light_dirs, summary):
    """Notes on the lights' geometry (list of str); `summary` (a dict, e.g. the quality summary)
    gets `normal_tilt_per_intensity_percent_deg` (`intensity_tilt`)."""
    tilt = intensity_tilt(light_dirs)
    summary["normal_tilt_per_intensity_percent_deg"] = round(tilt, 3) if np.isfinite(tilt) else None
    if not tilt > TILT_NOTE_ABOVE:
        return []
    s = np.asarray(light_dirs, np.float64)
    off = np.degrees(np.arccos(np.clip(s[:, 2] / np.linalg.norm(s, axis=1), -1, 1)))
    return [f"the lights lie {off.min():.0f}-{off.max():.0f}° from the view: a 1 % error in one light's "
            f"intensity tilts the normals by about {tilt:.1f}° ({RIG_TILT}° under the rig's 12 lights), so "
            "the intensities must be known better than that (light_intensities.txt, or the calibration's "
            "Spectralon step); lights farther from the view lower it"]


def carried(mask, usable):
    """The pixels of `mask` whose data can carry a normal, MIN_LIGHTS samples above the noise
    (usable: (m, H, W) bool, `PSInput.usable` or a band's; the whole mask when None). Photometric
    stereo solves these (whole images and bands alike), the others are filled (pipeline._filled).
    A solver judges its pixels by their own values, so it reads noise as light where every value
    is noise: a Mitsuba gold sphere with noise at 1/10⁴ of its highlights got li_alternating's lobe
    fit on noise (σ 0.001, n_i 1.0) and 58° over the sphere; 8.4° with this. DiLiGenT (at least 2
    grey levels, MIN_LEVELS): 96 lights 6.31° → 6.27°, 12 lights 7.24° → 7.14°."""
    if usable is None:
        return mask
    return mask & (np.count_nonzero(usable, axis=0) >= MIN_LIGHTS)


def sample_counts(images, usable, object_mask):
    """The counts `check_samples` judges, over the object: {object, known (m,), usable (m,),
    known_dark, enough} (pixels, known samples per light, usable samples per light, known
    samples below the noise, pixels with MIN_LIGHTS usable lights). Counts of row bands add up
    (`add_counts`) to those of the whole image."""
    # counts over the object on the whole maps: no (m, n_obj) gathers (12 MP: 0.22 -> 0.14 s)
    obj = np.asarray(object_mask, bool)
    u = usable & obj                                                 # (m, H, W)
    g = images[..., 1 if images.shape[-1] > 1 else 0]
    known = np.isfinite(g) & obj
    every = np.s_[:, ::CONTRAST_STEP, ::CONTRAST_STEP]               # lit_contrast's values
    return {"m": images.shape[0], "object": int(obj.sum()), "known": np.count_nonzero(known, axis=(1, 2)),
            "usable": np.count_nonzero(u, axis=(1, 2)), "known_dark": int(np.count_nonzero(known & ~u)),
            "enough": int(np.count_nonzero(carried(obj, usable))),
            "lit_values": g[every][u[every]], "dark_values": np.abs(g[every][(known & ~u)[every]])}


def add_counts(a, b):
    """The `sample_counts` of two parts of an image together (a may be None)."""
    if a is None:
        return dict(b)
    out = {}
    for k in a:
        if k == "m":
            out[k] = a[k]
        elif k.endswith("_values"):        # lit_contrast's value samples: joined
            out[k] = np.concatenate([a[k], b[k]])
        else:                              # counts: summed
            out[k] = a[k] + b[k]
    return out


def check_counts(counts, mask_source, light_names=None):
    """`check_samples` on its `sample_counts`: raise InsufficientData, or return (notes, summary)."""
    m, n_obj = counts["m"], counts["object"]
    if m <= MIN_LIGHTS:
        raise InsufficientData(f"photometric stereo needs at least {MIN_LIGHTS + 1} lights ({MIN_LIGHTS} "
                               f"to solve, one more to check the fit); the data has {m}",
                               hint="capture with more lights (--lights)")
    names = light_names or [f"light {i}" for i in range(m)]
    if n_obj == 0:
        if mask_source == "the lit pixels":
            raise InsufficientData("no pixel of the images is lit: they are black under every light",
                                   hint="lengthen the exposures or raise the LED current, and check "
                                        "that the lights fire (facette device --port PORT status)")
        raise InsufficientData(f"{mask_source} holds no pixel of the object (it is all zero)",
                               hint="draw the object in the mask (non-zero = object), or process "
                                    "without --mask")
    known_per_light = counts["known"]
    saturated = float(m * n_obj - known_per_light.sum()) / (m * n_obj)
    dark = float(counts["known_dark"]) / (m * n_obj)
    frac = float(counts["enough"]) / n_obj
    per_light = counts["usable"] / n_obj
    summary = {"object_pixels": n_obj, "pixels_with_enough_lights": frac,
               "saturated_samples": saturated, "samples_below_noise": dark,
               "usable_per_light": [round(float(x), 4) for x in per_light],
               "min_snr": MIN_SNR, "min_lights": MIN_LIGHTS}
    contrast = lit_contrast(counts) if frac < MIN_PIXEL_FRACTION else float("nan")
    own_dark = frac >= MIN_SPARSE_FRACTION and dark > saturated and contrast >= SPARSE_CONTRAST
    if frac < MIN_PIXEL_FRACTION and not own_dark:
        if saturated >= dark:
            todo = "shorten the exposures or lower the LED current (--exposures, --current)"
        else:
            todo = "lengthen the exposures or raise the LED current (--exposures, --current)"
        raise InsufficientData(
            f"the data cannot carry a result: {100 * frac:.0f} % of the object's {n_obj} pixels "
            f"({mask_source}) have {MIN_LIGHTS} lights with a usable sample; of all samples "
            f"{100 * saturated:.0f} % are saturated and {100 * dark:.0f} % below the noise",
            hint=todo + (", or give a mask of the object (--mask)" if mask_source == "the lit pixels"
                         else ""))
    notes = []
    if frac < MIN_PIXEL_FRACTION:
        notes.append(f"only {100 * frac:.0f} % of the object's pixels have {MIN_LIGHTS} usable lights and "
                     f"{100 * dark:.0f} % of the samples are below the noise, but those above it stand "
                     f"{contrast:.3g} times above the rest: the object sends light back only near its "
                     "highlights (a bare metal, a mirror-like finish), which no longer exposure changes; "
                     "more lights (a dome) would measure the rest")
    elif frac < 0.9:
        notes.append(f"only {100 * frac:.0f} % of the object's pixels have {MIN_LIGHTS} usable lights "
                     f"({100 * saturated:.0f} % of the samples saturated, {100 * dark:.0f} % below "
                     "the noise): the others get no normal")
    for i in np.flatnonzero(per_light < SPARSE_LIGHT):
        sat_i = float(n_obj - known_per_light[i]) / n_obj
        notes.append(f"{names[i]} gives a usable sample on {100 * per_light[i]:.0f} % of the object "
                     f"({'saturated' if sat_i >= 0.5 else 'too dark'} there)")
    return notes, summary


def check_fit_cells(filtered):
    """Raise InsufficientData when the hemisphere sensor has fewer than MIN_FIT_CELLS filled cells."""
    filled = int((filtered.count >= 1).sum())
    if filled < MIN_FIT_CELLS:
        raise InsufficientData(
            f"a BRDF fit needs {MIN_FIT_CELLS} filled cells of the hemisphere sensor; the samples "
            f"fill {filled}",
            hint="capture with more lights or a curved object (more angles), enlarge the mask, or "
                 "leave brdf out of --outputs")
    return filled


def truth_errors(inp, res):
    """{name: value} of `res` against the input's truth (a simulated scan's truth.npz): the normals'
    mean, median and 95th-percentile angular error (deg), the heights' RMS (mm, mean taken out)."""
    t = inp.truth
    out = {}
    if not t or "normals" not in t or t["normals"].shape != res.normals.shape:
        return out
    sel = res.mask & t.get("mask", np.ones(res.mask.shape, bool)).astype(bool)
    if sel.any():
        dot = np.clip(np.sum(res.normals[sel] * t["normals"][sel], -1), -1, 1)
        err = np.degrees(np.arccos(dot))
        out.update(normal_mean_deg=float(err.mean()), normal_median_deg=float(np.median(err)),
                   normal_p95_deg=float(np.percentile(err, 95)))
        if res.height is not None and "height_mm" in t:
            d = res.height[sel] - t["height_mm"][sel]
            out["height_rms_mm"] = float(np.sqrt(np.mean((d - d.mean()) ** 2)))
    return out
