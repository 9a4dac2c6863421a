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
"""
import time

import numpy as np

from facette.methods import photometric_stereo
from facette.pipeline._options import SHADOWS_AUTO
from facette.recon import hidden_lights
from facette.recon._shadows import HORIZON_PIXELS

__all__ = ["alternation_bin", "binned", "upsampled", "shadows_wanted", "solve_with_shadows", "with_shadows",
           "SHADOW_MARGIN_DEG", "SHADOW_MIN_SHARE", "SHADOW_PIXELS", "SHADOW_ROUNDS"]

# a light is hidden when the horizon is above it less this (degrees). Negative: integrated heights round
# a wall's rim off, so the horizon comes out low (the analytic groove's true heights: truly hidden lights
# down to -1.4 deg; least squares on it 2.72 deg with the margin at +2, 1.14 at 0, 0.42 at -1.5, 0.03 at
# -2 where 3 % of the found are not hidden). Mitsuba's concave scenes (96 lights) gain monotonically
# from +3 to -3 (least squares on the grooves 4.88 -> 4.53 deg; rank_trimmed 5.10 -> 4.90)
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


def shadows_wanted(o, light_dirs, notes):
    """Whether `process` runs the step: "off" never; "on" and "auto" on images read whole (with
    --memory a note says why not). Near lights take each light's mean direction."""
    if o.shadows == "off":
        return False
    if o.memory is not None:
        notes.append("shadows: left out with --memory (the horizon test needs the whole normal map)")
        return False
    return True


def with_shadows(res, o, direct, light_dirs, mask, method_name, bag, ps=None):
    """`process`'s call: `ps` (None: not solved yet) replaced by `solve_with_shadows`' result when the
    step runs and applies."""
    if not shadows_wanted(o, light_dirs, res.notes):
        return ps
    return solve_with_shadows(res, o, direct, light_dirs, mask, method_name, bag, first=ps) or ps


def _distant(light_dirs):
    """(m, 3): the lights' directions (per-pixel ones averaged, renormalised)."""
    L = np.asarray(light_dirs, np.float64)
    if L.ndim == 4:
        L = L.reshape(-1, L.shape[-2], 3).mean(axis=0)
    return L / np.linalg.norm(L, axis=-1, keepdims=True)


def _without(images, hidden, method_name):
    """The images with the hidden values taken out (module doc, step 2); hidden (m, H, W)."""
    out = np.array(images, dtype=np.float32, copy=True)
    gone = hidden if out.ndim == 3 else hidden[..., None]
    np.copyto(out, np.float32(0 if method_name in ZERO_IS_SHADOW else np.nan),
              where=np.broadcast_to(gone, out.shape))
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


def upsampled(hidden, f, mask):
    """(m, H, W) bool: hidden lights (m, H // f, W // f) of f x f bins, at the size of `mask`
    (the rows and columns past the last whole bin take the nearest bin's), on the mask only."""
    if f == 1:
        return hidden & mask[None]
    h, w = mask.shape
    rows = np.minimum(np.arange(h) // f, hidden.shape[1] - 1)
    cols = np.minimum(np.arange(w) // f, hidden.shape[2] - 1)
    return hidden[:, rows[:, None], cols[None, :]] & mask[None]


def _first_normals(first, f):
    """(normals, valid) of a given first PSResult on the f-binned grid."""
    if f == 1:
        return first.normal, first.valid
    h, w = first.valid.shape
    hc, wc = h // f, w // f
    n = np.where(first.valid[..., None], first.normal, 0)[:hc * f, :wc * f]
    valid = first.valid[:hc * f, :wc * f].reshape(hc, f, wc, f).all(axis=(1, 3))
    return n.reshape(hc, f, wc, f, 3).mean(axis=(1, 3)), valid


def solve_with_shadows(res, o, direct, light_dirs, mask, method_name, bag, first=None):
    """The method's PSResult with cast shadows left out (module doc), or None when "auto" finds
    too few (then the caller solves as before). first : a PSResult whose normals start the
    alternation (e.g. the inter-reflection step's), else a rank_trimmed pass. Notes, timings
    ("shadows") and res.quality["shadows"] (the figures, which process.json records) are filled in.
    "auto" decides on the images binned to at most SHADOW_PIXELS pixels of the object (a convex
    object pays one small robust pass and horizon test); the alternation on the images binned as the
    horizon test bins its heights (`alternation_bin`), the method's solve at full size."""
    t0, c0 = time.perf_counter(), time.process_time()
    L = _distant(light_dirs)

    def hidden_of(images, dirs, m, f, given=None):       # a robust pass (or `given`'s normals), its hidden lights
        if given is not None:
            normal, valid = _first_normals(given, f)
        else:
            ps = photometric_stereo(images, dirs, method="rank_trimmed", options=bag if f == 1 else {**bag, "mask": m})
            normal, valid = ps.normal, ps.valid
        hidden, _ = hidden_lights(normal, m & valid, L, SHADOW_MARGIN_DEG)
        return hidden, _lit_share(hidden, normal, valid, L)

    # the decision, on the images binned to at most SHADOW_PIXELS object pixels
    f = max(1, int(np.ceil(np.sqrt(np.count_nonzero(mask) / SHADOW_PIXELS))))
    coarse, coarse_dirs, coarse_mask = binned(direct, light_dirs, mask, f)
    hidden, share = hidden_of(coarse, coarse_dirs, coarse_mask, f, first)
    info = {"margin_deg": SHADOW_MARGIN_DEG, "decided_on": round(share, 5), "bin": f, "hidden_share": []}
    res.quality["shadows"] = info
    if o.shadows == SHADOWS_AUTO and share < SHADOW_MIN_SHARE:
        info.update(applied=False, cpu_seconds=round(time.process_time() - c0, 3))
        res.timings["shadows"] = time.perf_counter() - t0
        res.notes.append(f"shadows: the surface hides {share:.2%} of the lit samples from itself; "
                         "too few to matter, the images are used as they are")
        return None
    rounds = info["hidden_share"]
    fa = alternation_bin(mask)
    info["alternation_bin"] = fa
    images, dirs, m = binned(direct, light_dirs, mask, fa) if fa != f else (coarse, coarse_dirs, coarse_mask)
    if fa != f:
        hidden, share = hidden_of(images, dirs, m, fa, first)
    rounds.append(round(share, 5))
    for _ in range(SHADOW_ROUNDS - 1):
        hidden, share = hidden_of(_without(images, hidden, "rank_trimmed"), dirs, m, fa)
        rounds.append(round(share, 5))
    del images
    hidden = upsampled(hidden, fa, mask)
    t1, c1 = time.perf_counter(), time.process_time()
    ps = photometric_stereo(_without(direct, hidden, method_name), light_dirs, method=o.method, options=bag)
    ps.shadow |= np.moveaxis(hidden, 0, -1) & ps.valid[..., None]
    # the step's own cost is what comes before the method's solve (which runs in any case)
    info.update(applied=True, seconds_before_solve=round(t1 - t0, 3), cpu_seconds_before_solve=round(c1 - c0, 3))
    res.timings["shadows"] = time.perf_counter() - t0
    res.notes.append(f"shadows: the surface's own heights hide {rounds[-1]:.2%} of the lit samples (lights "
                     f"under the horizon + {-SHADOW_MARGIN_DEG:g}°); those values were left out of the normals "
                     f"({len(rounds)} robust passes, then {method_name})")
    return ps
