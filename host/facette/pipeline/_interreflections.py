"""`process`'s inter-reflection step: whether it runs (the option, or for "auto" what the input
allows), the removal itself, and what it says in the notes and timings.

The removal needs the albedo as a reflectance (it decides how much light each wall sends): a scan
whose images are radiance factors (the calibration's Spectralon step, `PSInput.reflectance`) has
it; elsewhere (a DiLiGenT folder, an RTI capture, a scan without the Spectralon step) its scale is
estimated from the images (facette.recon._interreflect_scale: the scale at which the albedo no
longer grows with the light gathered). "auto" runs it on every input read whole (not the rig
simulator's, which renders none): on a calibrated scan with its scale; elsewhere where the images
identify the scale, decided on binned images before the method runs (`decide_lobe_free`): the
albedo's growth with the light the heights say each wall gathers is read on li_alternating's diffuse
albedo, its lobe modelled, and removing that light must take the growth away. Elsewhere the images
stay as they are (the normals those of --no-interreflections), with a note saying why. Read on the
Lambertian albedo, a rendered satin sphere on a plane (no inter-reflections) was identified and the
removal took its normals 0.54 -> 1.57 deg: a lobe whose share grows toward the rim shows as a
Lambertian albedo that grows with the gathered share. With the scale estimated whatever the data said,
DiLiGenT's crops got worse (reading, dark and glossy: 9.7 -> 12.9 deg; a dark glossy Mitsuba bowl
0.48 -> 4.62 deg). A convex object gathers no light: it is not identified.
"""
import time

import numpy as np

from facette.errors import NotAReflectance
from facette.fit import glossy_lobes_text, ps_li_alternating, ps_li_without_interreflections, start_model_of
from facette.methods import options_for
from facette.pipeline._options import IR_AUTO
from facette.pipeline._shadows import binned as _binned
from facette.recon import (IR_GRID, IR_MAX_FRACTION, estimate_reflectance_scale, ps_rank_trimmed, unidentified_info,
                           without_interreflections)
from facette.recon._interreflect_scale import DIFFUSE_CORRELATION, SCALE_EXPLAINED

__all__ = ["interreflections_wanted", "solve_without_interreflections", "decide_lobe_free", "SIM_INTERREFLECTIONS_NOTE"]

SIM_INTERREFLECTIONS_NOTE = ("--interreflections on a simulated scan: the simulator renders no inter-reflections, "
                             "so their removal takes away light that no wall gathered (errors against truth grow); "
                             "leave it out for simulated scans")
AUTO_OFF = "inter-reflections left in (interreflections 'auto'): "
# "auto" without a Spectralon: removed where the images identify the scale (decide_lobe_free)
AUTO_SCALE = "identified"
# the decision reads the images binned to at most this many pixels a side: the estimate works on the
# gather's cells (IR_GRID a side), each then still 2 x 2 binned pixels (a 12 MP capture: bins of
# 22 x 22, one robust pass and one li_alternating of 0.03 MP instead of 12); a cost parameter
DECIDE_SIDE = 2 * IR_GRID
# decide_lobe_free's li run on relative images: brought to this 99th percentile of the albedo (a
# reflectance's range, where li's K_d is not held at its bound of 1)
REFLECTANCE_P99 = 0.8
# the later li_alternating solves start from the decision's model choice (`reuse_model`) instead of
# making their own, where the decision's li solved the same pixels (images within DECIDE_SIDE: only
# brought to a reflectance's range). Mitsuba concave renders (128 px, 12 rig lights): process CPU s
# 13.5-16.5 -> 9.2-13.9 with paint, 5.3-7.1 -> 3.5-5.5 in plaster, the 8 at the same ratio to least
# squares. On binned images it is not reused: binning smears the lobe, and the DiLiGenT crops (96
# lights, decided at bins 2-4) went 6.25 -> 6.33 deg (cat +0.25, pot2 +0.36) for 1-3 CPU s of 20-30.
# Nor where nothing is removed: the normals stay those of --no-interreflections and of a run over
# bands (reused there, a satin sphere's error without its lights' gains corrected moved 0.57 -> 0.47 deg)
REUSE_DECISION_MODEL = True
# on binned images, where its model is not reused, the decision's li runs round 1 only (the model
# choice, the per-pixel solve, the neighbour starts): the decision reads its diffuse albedo, which a
# later round moves little, at the cost of a refit, its held-out check and a second per-pixel solve.
# Chosen on the Mitsuba concave renders (128 px, rig12 and 96 lights, plaster / paint 0.10 / dark paint
# 0.05; round 1 only forced at bin 1): the same decision on all 20, diffuse correlation within 0.03,
# its li's CPU the same to 2.3 s less; DiLiGenT crops (96 lights, bin 2): the same decisions (reading's
# correlation -0.024 -> -0.024; the others' round 2 kept the model: the same albedo), the same normals
# (bytes), the decision's li 1-3 CPU s less. A cost parameter
BINNED_ROUNDS = 1


def _decide_bin(mask):
    return max(1, -(-max(mask.shape) // DECIDE_SIDE))


def decide_lobe_free(images, light_dirs, mask, bag, saturation):
    """The albedo scale's estimate (recon.estimate_reflectance_scale) that "auto" decides by on relative
    images, read on the images binned to DECIDE_SIDE: a rank_trimmed pass for the cells' shape and the
    scale's slopes, and li_alternating's diffuse albedo K_d, its lobe modelled, for the albedo's growth
    with the gathered share (a lobe whose share grows toward a sphere's rim makes a Lambertian albedo
    grow there too: recon's DIFFUSE_CORRELATION). li runs on the binned images brought to a
    reflectance's range (REFLECTANCE_P99: relative images brighter than a reflectance hold K_d at its
    bound of 1, which tells nothing; round 1 only on binned images: BINNED_ROUNDS); the method then runs
    on the images as before.
    Returns (the estimate, li's model choice for the later solves or None: `fit.start_model_of`)."""
    f = _decide_bin(mask)
    small = _binned(images, light_dirs, mask, f)
    channel = bag.get("channel")
    first = ps_rank_trimmed(*small[:2], mask=small[2], saturation=saturation,
                            **({} if channel is None else {"channel": channel}))
    args = (*small[:2], first.normal, first.albedo, first.valid & small[2], saturation, channel)
    _, estimate = estimate_reflectance_scale(*args)
    if estimate["growth_kept"] is None:         # nothing gathered (a convex object): no lobe to model
        return estimate, None
    albedo = first.albedo[first.valid]
    k = np.float32(REFLECTANCE_P99 / max(float(np.percentile(albedo, 99)) if albedo.size else 1.0, 1e-12))
    options = options_for("li_alternating", bag) | {"mask": small[2]} | ({} if f == 1 else {"rounds": BINNED_ROUNDS})
    if options.get("saturation") is not None:       # in the scaled images' units
        options["saturation"] = options["saturation"] * k
    lobe = ps_li_alternating(small[0] * k, small[1], **options)
    _, estimate = estimate_reflectance_scale(*args, diffuse=np.where(lobe.valid[..., None], lobe.albedo, np.nan))
    return estimate, start_model_of(lobe) if f == 1 else None      # REUSE_DECISION_MODEL


def interreflections_wanted(o, inp, notes, whole=False):
    """Whether `process` runs the inter-reflection step: the option when True or False; for "auto",
    on every input read whole that is not the rig simulator's (on relative images the step removes them
    only where the images identify the albedo's scale, `decide_lobe_free`). A note in `notes`
    says why it is left out ("auto") or that a simulated scan has none to remove (True). whole: the
    images are held whole (the band loop's one band, whether or not --memory was given)."""
    simulated = inp.truth is not None and "sensor" in inp.truth      # the rig simulator's truth
    if o.interreflections is True and simulated:
        notes.append(SIM_INTERREFLECTIONS_NOTE)
    if o.interreflections != IR_AUTO:
        return o.interreflections
    why = ("the simulator renders none" if simulated else
           "--memory reads the images by bands and the removal needs them whole" if o.memory and not whole else None)
    if why:
        notes.append(AUTO_OFF + why)
    return why is None


def solve_without_interreflections(res, o, solve_in, light_dirs, mask, method_name, bag, reflectance_scale=1.0):
    """(images the method is to see, PSResult or None) after the removal: li_alternating solves
    itself (its lobe takes the glossy walls' light out too, facette.fit.ps_li_without_interreflections);
    the others get the images and, for rank_trimmed when nothing was removed, its first pass.
    Under "auto" an albedo that is no reflectance (a calibration gone wrong) leaves the removal
    out with a note; asked for explicitly, it raises (NotAReflectance, an InsufficientData).
    mask : (H, W) bool, or the PSInput (its mask; and reflectance_scale 1 when its images are
    reflectance-calibrated, else "auto": estimated from the images)."""
    if hasattr(mask, "reflectance"):       # "auto": only a scale the data identify (AUTO_SCALE)
        reflectance_scale = 1.0 if mask.reflectance else "auto" if o.interreflections is True else AUTO_SCALE
        mask = mask.mask
    out = _solve(res, o, solve_in, light_dirs, mask, method_name, bag, reflectance_scale)
    if res.interreflections is not None:      # the later solves start from the decision's model (reuse_model)
        res.interreflections["model_reused"] = "start_model" in bag
    return out


def _solve(res, o, solve_in, light_dirs, mask, method_name, bag, reflectance_scale):
    """solve_without_interreflections' work, on the mask (H, W) and a scale (a number, "auto" or AUTO_SCALE)."""
    t0, c0 = time.perf_counter(), time.process_time()
    found = None
    if reflectance_scale == AUTO_SCALE:     # decided before any removal (decide_lobe_free)
        estimate, start = decide_lobe_free(solve_in, light_dirs, mask, bag, o.saturation)
        if not estimate["identified"]:      # the images as they are (the normals --no-interreflections' too)
            info = unidentified_info(estimate["scale"], estimate) | {"cpu_seconds": round(time.process_time() - c0, 3)}
            note_interreflections(res, info, time.perf_counter() - t0)
            return solve_in, None
        reuse_model(bag, start)
        reflectance_scale, found = estimate["scale"], estimate     # identified: that scale (its lobe modelled)
    try:
        if method_name == "li_alternating":
            ps, direct, info = ps_li_without_interreflections(solve_in, light_dirs, reflectance_scale=reflectance_scale,
                                                              estimate=found, **options_for(method_name, bag))
            info["cpu_seconds"] = round(time.process_time() - c0, 3)
            _identified_on(info, found)
            note_interreflections(res, info, info["removal_seconds"])
            return direct, ps
        direct, first, info = without_interreflections(solve_in, light_dirs, mask, saturation=o.saturation,
                                                       channel=bag.get("channel"), reflectance_scale=reflectance_scale,
                                                       estimate=found)
    except NotAReflectance as exc:      # raised before any solve: nothing done is lost
        if o.interreflections is True:
            raise
        res.notes.append(AUTO_OFF + str(exc))
        return solve_in, None
    info["cpu_seconds"] = round(time.process_time() - c0, 3)
    _identified_on(info, found)
    note_interreflections(res, info, time.perf_counter() - t0)
    if not info["applied"]:
        return solve_in, (first if method_name == "rank_trimmed" else None)
    return direct, None


def reuse_model(bag, start):
    """The decision's li_alternating model choice (`decide_lobe_free`), where it identified light to
    remove, into `bag`, the options of every later solve of this run (the removal's, the shadow step's,
    the method's): li_alternating
    then starts from it instead of choosing again (its rounds still refit (σ, n_i) at full size)."""
    if start is not None and REUSE_DECISION_MODEL:
        bag["start_model"] = start


def _why_not_identified(est):
    """The condition of recon's estimate that failed, in words."""
    kept, follows = est.get("growth_kept"), est.get("diffuse_correlation")
    if follows is not None and follows < DIFFUSE_CORRELATION:
        return (f"li_alternating's diffuse albedo, its lobe modelled, does not follow the light the surface gathers: "
                f"correlation {follows:.2f} cell by cell, below {DIFFUSE_CORRELATION}")
    if kept is None or kept == float("inf"):
        return "the albedo does not grow with the light the surface gathers"
    if kept > 1.0 - SCALE_EXPLAINED:
        return f"the albedo grows with the light gathered, but removing it keeps {kept:.0%} of that growth"
    return "the albedo's growth goes only at the largest scales, as over-removal makes it go"


def _identified_on(info, found):
    """What "auto" found in the images (None: the option or a calibrated scan decided) into info."""
    if found is not None:
        info["identified_on"] = {k: found[k] for k in ("scale", "gather_correlation", "diffuse_correlation",
                                                       "growth_kept")}


def note_interreflections(res, info, seconds):
    """The removal's info, seconds and note into `res`."""
    res.interreflections = info
    res.timings["interreflections"] = seconds
    if info.get("scale_identified") is False:
        res.notes.append(AUTO_OFF + "the images do not tell the albedo's scale to a reflectance ("
                         + _why_not_identified(info["scale_estimate"]) + "); --interreflections removes it with "
                         "the scale estimated anyway")
        return
    how = (f"{info['median_fraction']:.1%} of the median value, {info['p95_fraction']:.1%} at the 95th "
           f"percentile, on {info['grid'][1]}x{info['grid'][0]} cells, {len(info['passes'])} pass(es)")
    if not info["applied"]:
        res.notes.append(f"inter-reflections: {how}; too little to matter, the images are used as they are")
        return
    capped = f"; {info['capped']} values limited to {IR_MAX_FRACTION:.0%} removed" if info["capped"] else ""
    scale = ("" if "scale_estimate" not in info else
             f"; the albedo's scale to a reflectance estimated from the images: {info['reflectance_scale']:.3g}")
    found = info.get("identified_on")
    if found:               # "auto" without a Spectralon: what the images showed
        scale += (f" (found by 'auto': li_alternating's diffuse albedo, its lobe modelled, follows the light the "
                  f"surface gathers, correlation {found['diffuse_correlation']:.2f} cell by cell, and removing it "
                  f"leaves {max(found['growth_kept'], 0):.0%} of that growth)")
    res.notes.append(f"inter-reflections removed before photometric stereo: {how}{capped}{scale}")
    glossy = info.get("glossy")
    if glossy:
        res.notes.append(f"glossy inter-reflections removed with the lobes li_alternating found "
                         f"({glossy_lobes_text(glossy)}): {glossy['median_fraction']:.1%} "
                         f"of the median value, {glossy['p95_fraction']:.1%} at the 95th percentile, "
                         "then li_alternating again")
