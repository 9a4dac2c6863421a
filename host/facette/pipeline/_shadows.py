"""`process`'s cast-shadow step: the lights the surface hides from itself, alternated with the normals.

A wall hides the lights behind it from the floor of a groove, a crater, a cup; what reaches the
floor from those lights is not the direct light photometric stereo models but what the walls send
(inter-reflections), so such a value is no sample for that pixel, whatever its value. Darkness
alone does not tell it (a lit wall fills the shadow). The step:

1. a first, robust pass (rank_trimmed) gives normals; least squares integrates them on the mask
   (facette.recon.heights_in_pixels) and a horizon test on the heights finds each pixel's hidden
   lights (facette.recon.hidden_lights, SHADOW_MARGIN_DEG);
2. the hidden values are taken out (0 for the methods that read a dark value as a shadow and
   never keep it, rank_trimmed and li_alternating; missing, NaN, for the others), the robust
   pass again, heights, hidden lights again (SHADOW_ROUNDS in all);
3. the chosen method solves once on the images without the hidden values. Its `shadow` map
   gains them (the reflectance samples leave them out).

"auto" decides first, on the images binned to at most SHADOW_PIXELS object pixels (a rank_trimmed
pass, an integration and the horizon test there): under SHADOW_MIN_SHARE of the lit samples hidden,
the images are used as they are (a convex object hides nothing, and pays that small pass only).
The alternation (steps 1-2) runs on the images binned as the horizon test bins its heights
(recon.HORIZON_PIXELS cells: 3 x 3 on a 3 MP scan, none on a DiLiGenT crop), since the hidden
lights are found per bin in any case; only the method's solve (step 3) sees every pixel.

Both passes read binned images only, so the step runs the same over bands (`hidden_over_bands`:
each band binned as it is read, its first row on a multiple of both bins, so that the bins are
the whole image's; `hidden_of_bins` on the joined stacks; each band's solve then leaves out its
rows of the hidden lights, `without_hidden`): the hidden lights of the images held whole, and the
same normals (tests/pipeline/test_process_shadows.py). The binned stacks hold at most
HORIZON_PIXELS + SHADOW_PIXELS cells x m lights x C channels (12 lights, RGB + the solve's
channel: 80 MB), the images themselves when the mask has fewer pixels than that.
"""
import time
from dataclasses import dataclass, replace

import numpy as np

from facette.methods import photometric_stereo
from facette.pipeline._options import SHADOWS_AUTO
from facette.recon import hidden_lights
from facette.recon._shadows import HORIZON_PIXELS

__all__ = ["alternation_bin", "binned", "binned_pass", "Binned", "decision_bin", "flag_hidden", "hidden_of_bins",
           "hidden_over_bands", "joined", "without_hidden",
           "upsampled", "shadows_wanted", "solve_with_shadows", "with_shadows",
           "SHADOW_MARGIN_DEG", "SHADOW_MIN_SHARE", "SHADOW_PIXELS", "SHADOW_ROUNDS"]

# a light is hidden when the horizon is above it less this (degrees). Negative: integrated heights round
# a wall's rim off, so the horizon comes out low (the analytic groove's true heights: truly hidden lights
# down to -1.4 deg; least squares on it 2.72 deg with the margin at +2, 1.14 at 0, 0.42 at -1.5, 0.03 at
# -2 where 3 % of the found are not hidden). Mitsuba's concave scenes (96 lights) gain monotonically
# from +3 to -3 (least squares on the grooves 4.88 -> 4.53 deg; rank_trimmed 5.10 -> 4.90). Kept after
# `bench lights --shadow-rates` (hit: the share of the truly hidden lit samples found; false: lit samples found
# hidden that are not, of the lit): the 1500x1000 relief under 60 dome lights, whose slopes hide 3.99 %, -1.5:
# hit 100 %, false 1.28 %; 0: 99.0 %, 0.13 % (its integrated heights are good: the margin's soft edge is all its
# false hidden); bench concave's bowl and grooves under 96 lights, -1.5: hit 37.5 % and 1.9 %, false 0; 0: 16.2 %
# and 0.8 % (their walls' heights come out low); the analytic groove and bowl (tests/shadow_scenes.py): -1.5:
# 100 %, 98.8 % (false 0.08 %, 0.21 %); 0: 84.5 %, 87.4 %
SHADOW_MARGIN_DEG = -1.5
SHADOW_ROUNDS = 2          # robust passes with hidden lights before the method's solve
# "auto" decides on the images binned to at most this many object pixels (a DiLiGenT crop of 45 k pixels
# 2 x 2): a cost parameter (a convex dome of 31 k pixels under 96 lights: 4.3 CPU s of the step before,
# 1.3 now; at full size its integrated silhouette hid 0.34 % of the lit samples, binned 0.09 %: left as
# it is). The alternation runs at the horizon test's bin (`alternation_bin`), not this one: on images
# binned to this it cost the cat crop 0.23 deg. At the horizon's bin (3 x 3 on the 4288x2848 scan) the
# step before the solve went 23.3 -> 15.7 CPU s, then 6.4 with the heights by multigrid
# (recon._shadows.HEIGHTS_RTOL); the scan's normals 6.4865 -> 6.4862 deg, heights 1.879 -> 1.881 mm RMS
SHADOW_PIXELS = 20_000
SHADOW_MIN_SHARE = 0.002   # "auto": fewer hidden lit samples than this share leave the images as they are
ZERO_IS_SHADOW = ("rank_trimmed", "li_alternating")    # methods that read a 0 as a shadow, never kept


def shadows_wanted(o):
    """Whether `process` runs the step: "off" never; "on" and "auto" on images read whole or over
    bands (`hidden_over_bands`)."""
    return o.shadows != "off"


def with_shadows(res, o, direct, light_dirs, mask, method_name, bag, ps=None):
    """`process`'s call: `ps` (None: not solved yet) replaced by `solve_with_shadows`' result when the
    step runs and applies."""
    if not shadows_wanted(o):
        return ps
    return solve_with_shadows(res, o, direct, light_dirs, mask, method_name, bag, first=ps) or ps


def _distant(light_dirs):
    """(m, 3): the lights' directions (per-pixel ones averaged, renormalised)."""
    L = np.asarray(light_dirs, np.float64)
    if L.ndim == 4:
        L = L.reshape(-1, L.shape[-2], 3).mean(axis=0)
    return L / np.linalg.norm(L, axis=-1, keepdims=True)


def _without(images, hidden, method_name, in_place=False):
    """A copy of the images with the hidden values taken out (module doc, step 2), or, `in_place`, the
    images themselves (float32, their own: no second stack); hidden (m, H, W)."""
    from facette.recon._shadows_jit import without_kernel
    im = np.asarray(images, np.float32)
    out = im if in_place else np.empty(im.shape, np.float32)
    without_kernel(im if im.ndim == 4 else im[..., None], np.asarray(hidden, bool),
                   np.float32(0 if method_name in ZERO_IS_SHADOW else np.nan), out if out.ndim == 4 else out[..., None])
    return out


def _lit_share(hidden, normals, valid, L):
    """Share of the lit samples (s·n > 0 on valid pixels) that are hidden."""
    lit = (np.einsum("hwd,md->mhw", normals, L.astype(np.float32)) > 0) & valid[None]
    n = int(lit.sum())
    return float((hidden & lit).sum()) / n if n else 0.0


def binned(direct, light_dirs, mask, f):
    """(images, light directions, mask) binned f x f (the mean of each block's values that are not
    missing; a block is on the mask when all its pixels are); f 1: as given."""
    if f == 1:
        return direct, light_dirs, mask
    from facette.recon._shadows_jit import bin_mean_kernel
    h, w = mask.shape
    hc, wc = h // f, w // f
    im = np.asarray(direct, np.float32)
    out = np.empty((im.shape[0], hc, wc, *im.shape[3:]), np.float32)
    # one pass over the stack, no copy of it (numpy's nanmean: 3.2 CPU s on 12 lights of 3 MP RGB, this 0.1)
    bin_mean_kernel(im if im.ndim == 4 else im[..., None], f, out if out.ndim == 4 else out[..., None])
    L = np.asarray(light_dirs)
    if L.ndim == 4:             # per-pixel directions: the block's mean, renormalised
        L = L[:hc * f, :wc * f].reshape(hc, f, wc, f, *L.shape[2:]).mean(axis=(1, 3))
        L = L / np.linalg.norm(L, axis=-1, keepdims=True)
    return out, L, mask[:hc * f, :wc * f].reshape(hc, f, wc, f).all(axis=(1, 3))


def alternation_bin(mask):
    """The bin factor of the alternation: the horizon test's own (at most HORIZON_PIXELS cells of the
    mask), so that its robust passes solve no more pixels than the heights it integrates."""
    return max(1, int(np.ceil(np.sqrt(np.count_nonzero(mask) / HORIZON_PIXELS))))


def upsampled(hidden, f, mask, r0=0):
    """(m, H, W) bool: hidden lights (m, H // f, W // f) of f x f bins, at the size of `mask`
    (the rows and columns past the last whole bin take the nearest bin's), on the mask only.
    r0: the image row of mask's first (a band's rows: `mask` is the band's)."""
    h, w = mask.shape
    if f == 1:
        return hidden[:, r0:r0 + h] & mask[None]
    from facette.recon._shadows_jit import upsample_kernel
    out = np.empty((hidden.shape[0], h, w), bool)
    upsample_kernel(np.ascontiguousarray(hidden, bool), int(f), int(r0), np.ascontiguousarray(mask, bool), out)
    return out




def decision_bin(mask):
    """The bin factor of "auto"'s decision: at most SHADOW_PIXELS cells of the mask."""
    return max(1, int(np.ceil(np.sqrt(np.count_nonzero(mask) / SHADOW_PIXELS))))


@dataclass
class Binned:
    """The images of one of the step's passes binned f x f (`binned`): images (m, H // f, W // f, ...),
    their light directions, the mask (a bin is on it when all its pixels are) and the mask the robust
    pass solves (at f 1 the solve's own, what the capture cannot use left out)."""
    f: int
    images: np.ndarray
    dirs: np.ndarray
    mask: np.ndarray
    solve_mask: np.ndarray


def binned_pass(direct, light_dirs, mask, solve_mask, f):
    """`Binned` of the images held whole, or of one band of them (its rows a multiple of f from a
    multiple of f: the bins are then the whole image's)."""
    images, dirs, m = binned(direct, light_dirs, mask, f)
    return Binned(f, images, dirs, m, solve_mask if f == 1 else m)


def joined(parts):
    """The bands' `Binned` (top to bottom) as the whole image's."""
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    dirs = first.dirs if np.ndim(first.dirs) == 2 else np.concatenate([p.dirs for p in parts])
    return Binned(first.f, np.concatenate([p.images for p in parts], axis=1), dirs,
                  np.concatenate([p.mask for p in parts]), np.concatenate([p.solve_mask for p in parts]))


def _first_normals(first, f):
    """(normals, valid) of a given first PSResult on the f-binned grid."""
    if f == 1:
        return first.normal, first.valid
    h, w = first.valid.shape
    hc, wc = h // f, w // f
    n = np.where(first.valid[..., None], first.normal, 0)[:hc * f, :wc * f]
    valid = first.valid[:hc * f, :wc * f].reshape(hc, f, wc, f).all(axis=(1, 3))
    return n.reshape(hc, f, wc, f, 3).mean(axis=(1, 3)), valid


def hidden_of_bins(res, o, decision, alternation, method_name, bag, first=None, started=None,
                   margin_deg=SHADOW_MARGIN_DEG):
    """(the hidden lights of the alternation's bins (m, H // fa, W // fa), fa), or None when "auto" finds
    too few (module doc, steps 1-2). decision: `Binned` at `decision_bin`; alternation(): `Binned` at
    `alternation_bin`, made when needed. first : a PSResult whose normals start the alternation (e.g.
    the inter-reflection step's), else a rank_trimmed pass. The lights' mean directions are the
    decision's bins'. Notes, and res.quality["shadows"] (the figures, which process.json records);
    started: (perf, process) clocks; margin_deg: the horizon test's (`bench lights --shadow-rates` varies it)."""
    t0, c0 = started or (time.perf_counter(), time.process_time())
    L = _distant(decision.dirs)

    def hidden_of(level, given=None):       # a robust pass (or `given`'s normals), its hidden lights
        if given is not None:
            normal, valid = _first_normals(given, level.f)
        else:
            ps = photometric_stereo(level.images, level.dirs, method="rank_trimmed",
                                    options={**bag, "mask": level.solve_mask})
            normal, valid = ps.normal, ps.valid
        hidden, _ = hidden_lights(normal, level.mask & valid, L, margin_deg)
        return hidden, _lit_share(hidden, normal, valid, L)

    hidden, share = hidden_of(decision, first)
    info = {"margin_deg": margin_deg, "decided_on": round(share, 5), "bin": decision.f, "hidden_share": []}
    res.quality["shadows"] = info
    if o.shadows == SHADOWS_AUTO and share < SHADOW_MIN_SHARE:
        info.update(applied=False, cpu_seconds=round(time.process_time() - c0, 3))
        res.timings["shadows"] = time.perf_counter() - t0
        res.notes.append(f"shadows: the surface hides {share:.2%} of the lit samples from itself; "
                         "too few to matter, the images are used as they are")
        return None
    rounds = info["hidden_share"]
    level = alternation()
    info["alternation_bin"] = level.f
    if level.f != decision.f:
        hidden, share = hidden_of(level, first)
    rounds.append(round(share, 5))
    for _ in range(SHADOW_ROUNDS - 1):
        hidden, share = hidden_of(replace(level, images=_without(level.images, hidden, "rank_trimmed")))
        rounds.append(round(share, 5))
    # the step's own cost is what comes before the method's solve (which runs in any case)
    info.update(applied=True, seconds_before_solve=round(time.perf_counter() - t0, 3),
                cpu_seconds_before_solve=round(time.process_time() - c0, 3))
    res.notes.append(f"shadows: the surface's own heights hide {rounds[-1]:.2%} of the lit samples (lights "
                     f"under the horizon + {-margin_deg:g}°); those values were left out of the normals "
                     f"({len(rounds)} robust passes, then {method_name})")
    return hidden, level.f


def solve_with_shadows(res, o, direct, light_dirs, mask, method_name, bag, first=None):
    """The method's PSResult with cast shadows left out (module doc), or None when "auto" finds
    too few (then the caller solves as before): `hidden_of_bins` on the images held whole, then the
    method's solve at full size without the hidden values. Timings ("shadows") filled in."""
    started = t0, _ = time.perf_counter(), time.process_time()
    solve_mask = bag.get("mask", mask)
    f = decision_bin(mask)
    decision = binned_pass(direct, light_dirs, mask, solve_mask, f)
    found = hidden_of_bins(res, o, decision, lambda: decision if alternation_bin(mask) == f else
                           binned_pass(direct, light_dirs, mask, solve_mask, alternation_bin(mask)),
                           method_name, bag, first, started)
    if found is None:
        return None
    del decision
    images, hidden = without_hidden(direct, found, mask, 0, method_name)
    ps = flag_hidden(photometric_stereo(images, light_dirs, method=o.method, options=bag), hidden)
    res.timings["shadows"] = time.perf_counter() - t0
    return ps


def hidden_over_bands(res, o, read, mask, rows, method_name, bag):
    """`hidden_of_bins` over bands, or None (the step not wanted, or too few hidden): each band binned as
    it is read, on the whole image's bins (bands of a multiple of both bins' rows, near `rows`), so that
    the binned images, and then the hidden lights, are those of the images held whole. read(r0, r1) ->
    (the band's images as the solve sees them, its light directions, the mask its solve takes).
    Each band's solve then leaves out `upsampled(hidden, fa, its mask, r0)` (`without_hidden`)."""
    if not shadows_wanted(o):
        return None
    started = time.perf_counter(), time.process_time()
    f, fa = decision_bin(mask), alternation_bin(mask)
    step = int(np.lcm(f, fa))
    rows = max(step, rows // step * step)
    parts = {f: [], fa: []}
    for r0 in range(0, mask.shape[0], rows):
        r1 = min(mask.shape[0], r0 + rows)
        images, dirs, solve_mask = read(r0, r1)
        for k, done in parts.items():          # the decision's bins and the alternation's (once when the same)
            done.append(binned_pass(images, dirs, mask[r0:r1], solve_mask, k))
        del images
    levels = {k: joined(done) for k, done in parts.items()}
    found = hidden_of_bins(res, o, levels[f], lambda: levels[fa], method_name, bag, None, started)
    res.timings["shadows"] = time.perf_counter() - started[0]
    return found


def without_hidden(images, found, mask, r0, method_name, in_place=False):
    """(a band's images without its hidden values, its hidden lights (m, rows, W)) for a band of rows
    r0.. whose mask is `mask`; found: `hidden_over_bands`' (None: as given, None). in_place: the
    values taken out of `images` itself (a float32 stack of the caller's own, e.g. the solve's channel
    appended: 6.2 CPU s of the 6 MP x 60 dome capture's 184 went to the copies and their pages)."""
    if found is None:
        return images, None
    hidden = upsampled(*found, mask, r0)
    return _without(images, hidden, method_name, in_place and images.dtype == np.float32), hidden


def flag_hidden(ps, hidden):
    """ps.shadow gains the `hidden` lights (m, H, W) of its valid pixels (the samples leave them out)."""
    if hidden is not None:
        ps.shadow |= np.moveaxis(hidden, 0, -1) & ps.valid[..., None]
    return ps
