"""The lights' relative intensities read from the photographs themselves (semi-calibrated
photometric stereo, with the LI model instead of Lambert's).

    estimate_light_gains(images, light_dirs, mask, channel, saturation) -> (gains (m,) or None, info)

A folder's `light_intensities.txt` (DiLiGenT's, an RTI dome's) is a measurement too, and under few
lights near the axis a 1 % error in one light tilts the normals by about 0.7° (the rig's 12 lights;
`pipeline._quality.intensity_tilt`). Given the lights' directions, the images fix each light's
intensity up to one common scale as soon as the object's normals vary (Cho et al., "Semi-calibrated
photometric stereo", TPAMI 2018: for a Lambertian object, a factorisation unique up to scale). Here:

1. The default solve (`ps_li_alternating`) on the images binned to at most GAIN_PIXELS valid
   pixels (a quarter of a DiLiGenT crop's time): normals, the material's model (σ, n_i, its
   diffuse part) or Lambert's where it found no lobe.
2. At each pixel of its better-explained half (relative residual), K_d solved in closed form over
   the lights it did not flag as cast shadows, and the model's value predicted for every light.
3. Each light's gain: the median over those pixels of observed / predicted, where the prediction
   is at least MIN_SHARE of the pixel's brightest (away from the attached shadow's edge); the gains
   are scaled to a geometric mean of 1 (the albedo keeps its scale).

One such step, not an alternation to convergence: the Mitsuba renders with 2 % errors in their
intensities gained as much from one step as from two (mean 2.53 -> 2.43 -> 2.47° over the first
half of the scenes, 1.96 -> 1.89 -> 1.87° over the second), and a second step costs a second solve.

The gains are applied only where they can be told from noise and from a tilt (`info["why"]`
otherwise): not for a metal's lobe (no diffuse part under every light: a render of gold with exact
intensities got gains 6 % off), not when the pixels' normals spread less than MIN_SPREAD_DEG in some
direction (a flat object: a tilt of all its normals and a pattern of intensities make the same
images), not when the correction is within SIGNIFICANT times what two halves of the pixels
disagree by or under MIN_RMS (the model's own misfit on exact renders), not above MAX_RMS, and not
when the gains read on two halves of the object, split by where its normals point, do not agree
(MIN_AGREEMENT): a light's intensity is the same from any part of the object, a misfit is not.
Chosen on the renders (2 % errors; exact intensities must come out unchanged), confirmed on DiLiGenT:
its five crops under the rig's 12 lights 7.07 -> 6.90° (`pipeline._light_gains` decides where the
step runs).
"""
import time

import numpy as np

from facette.brdf import li_shading_terms
from facette.recon import dark_offsets

from ._li_model import is_metal
from ._ps_li import ps_li_alternating
from ._ps_li_coarse import bin_inputs, coarse_factor

__all__ = ["estimate_light_gains", "light_gains_over_bands", "GAIN_PIXELS", "MAX_RMS", "MIN_AGREEMENT", "MIN_RMS", "MIN_SPREAD_DEG"]

GAIN_PIXELS = 10_000     # the first solve's valid pixels at most (binned f × f above)
MIN_SHARE = 0.2          # a light's ratio is read where the model gives it ≥ this share of the pixel's brightest
MIN_PIXELS = 20          # a light with fewer such pixels keeps its intensity (gain 1)
MIN_SPREAD_DEG = 5.0     # the normals' spread (RMS tilt, least-varying direction) a gain needs
SIGNIFICANT = 3.0        # the gains' RMS must exceed this many times the half-split noise
# and this much: on the Mitsuba renders, whose intensities are exact, the model's own misfit reads as
# gains of 0.003-0.15 % RMS (and the glaze sphere, at 0.15 %, went 0.69 -> 1.28° when they were applied)
MIN_RMS = 0.005
# the gains read on two halves of the object must correlate this much (renders with 2 % errors:
# 0.78-1.00; the Goldman-Seitz photographs' cat, owl and horse, whose gains moved their normals by
# 4-12°: 0.00-0.36; DiLiGenT's crops under 12 lights: buddha 0.90, cat 0.69, pot2 0.52, reading 0.38)
MIN_AGREEMENT = 0.5
# a light off by this much RMS is no calibration's error but the model's misfit (the gold relief,
# taken for a dielectric: 71 %); DiLiGenT's pot2, the largest of its five, 5 %
MAX_RMS = 0.15


def light_gains_over_bands(read, shape, mask, rows, channel=None, saturation=None, seed=0):
    """`estimate_light_gains` of an image read band by band, never whole: read(r0, r1) -> images
    (m, r1 - r0, W, C) of those rows as `estimate_light_gains` takes them. Each band (a multiple of
    the binning factor's rows: the same blocks as the whole image's) is binned as it comes; the
    binned image is what the estimate reads, so the gains are the whole image's, bit for bit. An
    image the estimate does not bin (at most GAIN_PIXELS valid pixels) is read as one band."""
    h = shape[0]
    mask = np.asarray(mask, bool)
    f = coarse_factor(int(np.count_nonzero(mask)), GAIN_PIXELS, 1)
    if f is None:
        images, light_dirs = read(0, h)
        return estimate_light_gains(images, light_dirs, mask, channel, saturation, seed)
    step = max(f, int(rows) // f * f)
    parts = []
    for r0 in range(0, h, step):
        r1 = min(h, r0 + step)
        images, light_dirs = read(r0, r1)
        parts.append(bin_inputs(images, light_dirs, mask[r0:r1], f, saturation))
        del images
    binned = (np.concatenate([p[0] for p in parts], axis=1), parts[0][1], np.concatenate([p[2] for p in parts]), f)
    return estimate_light_gains(None, parts[0][1], mask, channel, saturation, seed, binned=binned)


def estimate_light_gains(images, light_dirs, mask, channel=None, saturation=None, seed=0, binned=None):
    """(gains (m,) float64 to divide the images by, or None where they are not applied; info dict:
    "applied", "why" (when not), "gains", "rms_percent", "max_percent", "noise_percent",
    "halves_agreement", "spread_deg", "pixels", "factor", "seconds").

    images : (m, H, W, C) linear, divided by the given intensities; light_dirs : (m, 3) unit
    vectors (directional lights only); mask : (H, W) bool; channel : the channel solved on.
    binned : (images, light_dirs, mask, f) already binned f x f (`light_gains_over_bands`)."""
    t0 = time.perf_counter()
    if binned is not None:
        ci, cl, cm, f = binned
        images = ci
    images = np.asarray(images)
    m = images.shape[0]
    info = {"applied": False}
    if np.ndim(light_dirs) != 2:
        return _done(None, info, t0, "near lights: their fall-off, not only their intensities, decides the values")
    ch = images.shape[-1] - 1 if channel is None else channel
    if binned is None:
        f = coarse_factor(int(np.count_nonzero(mask)), GAIN_PIXELS, 1)
        ci, cl, cm = (images, light_dirs, mask) if f is None else bin_inputs(images, light_dirs, mask, f, saturation)
    ps = ps_li_alternating(ci, cl, mask=cm, channel=ch, saturation=None if f else saturation,
                           coarse_pixels=None, seed=seed, neighbour_deg=0)
    info["factor"] = f or 1
    mats = ps.info.get("materials") or []
    if not mats or not ps.valid.any():
        return _done(None, info, t0, "no pixel was solved")
    mat = mats[0]
    if mat.get("n_i") is not None and is_metal(mat["n_i"]):
        return _done(None, info, t0, "a metal's lobe: no diffuse part lit by every light to compare them")
    offsets, dark = dark_offsets(ci, cl, ps.normal, ps.valid, None if f else saturation)
    values = ci[..., ch] - (offsets[:, None, None, ch] if dark["relative"] >= 1e-3 else 0)
    good = ps.valid & (ps.residual <= np.nanmedian(ps.residual[ps.valid]))
    n = ps.normal[good].astype(np.float32)
    e = values[:, good].T.astype(np.float64)                       # (N, m)
    if mat.get("brdf_step") and mat.get("sigma") is not None:
        a, b = li_shading_terms(n, cl, mat["sigma"], mat["n_i"], volume_model=mat["volume_model"])
    else:                                                          # no lobe found: Lambert's
        a, b = np.zeros((n.shape[0], m), np.float32), np.clip(n @ cl.T.astype(np.float32), 0, None)
    ok = np.isfinite(e) & ~ps.shadow[good] & (b > 0)
    kappa = np.sum(np.where(ok, b * (e - a), 0), 1) / np.maximum(np.sum(np.where(ok, b * b, 0), 1), 1e-12)
    pred = a + b * kappa[:, None]
    top = np.max(np.where(ok, pred, 0), axis=1, keepdims=True)
    ok &= (pred > MIN_SHARE * top) & (kappa[:, None] > 0)
    ratio = np.where(ok, e / np.where(ok, pred, 1), np.nan)
    info["pixels"] = int(n.shape[0])
    info["spread_deg"] = round(_spread_deg(n), 2)
    gains = _gains(ratio)
    halves = np.random.default_rng(seed).random(n.shape[0]) < 0.5
    diff = np.log(_gains(ratio[halves])) - np.log(_gains(ratio[~halves]))
    noise = float(np.std(diff) / 2)                    # each half has half the pixels: σ_full ≈ σ_diff / 2
    rms = float(np.sqrt(np.mean(np.log(gains) ** 2)))
    agreement = _halves_agreement(ratio, n)
    info.update(gains=[round(float(g), 5) for g in gains], rms_percent=round(100 * rms, 3),
                max_percent=round(100 * float(np.max(np.abs(gains - 1))), 3), noise_percent=round(100 * noise, 3),
                halves_agreement=round(agreement, 3))
    if rms > MAX_RMS:
        return _done(None, info, t0, f"the gains ({100 * rms:.0f} % RMS) are too large for a calibration's error: "
                                     "the model does not explain the object; check light_intensities.txt")
    if info["spread_deg"] < MIN_SPREAD_DEG:
        return _done(None, info, t0, f"the object's normals spread {info['spread_deg']:.1f}° only (under "
                                     f"{MIN_SPREAD_DEG:.0f}°): a flat object's tilt and its lights' intensities "
                                     "make the same images")
    if rms <= max(SIGNIFICANT * noise, MIN_RMS):
        return _done(None, info, t0, f"the gains ({100 * rms:.2f} % RMS) are within what the model's misfit and "
                                     f"two halves of the pixels' disagreement ({100 * noise:.2f} %) give: the "
                                     "given intensities stand")
    if not agreement >= MIN_AGREEMENT:
        return _done(None, info, t0, f"the gains read on the object's two halves (split by where its normals point) "
                                     f"disagree (correlation {agreement:.2f}, under {MIN_AGREEMENT}): they are the "
                                     "model's misfit, not the lights'")
    info["applied"] = True
    return _done(gains, info, t0, None)


def _gains(ratio):
    """(m,) each light's median ratio over its pixels (1 where it has fewer than MIN_PIXELS),
    scaled to a geometric mean of 1."""
    count = np.sum(np.isfinite(ratio), axis=0)
    with np.errstate(all="ignore"):
        med = np.nanmedian(np.where(count[None] >= MIN_PIXELS, ratio, 1.0), axis=0)
    med = np.where(np.isfinite(med) & (med > 0), med, 1.0)
    return med / np.exp(np.mean(np.log(med)))


def _halves_agreement(ratio, n):
    """The lower over x and y of the correlation between the log gains read on the pixels whose normal
    points below and above its median along that axis: a light's intensity is the same seen from
    any part of the object, the model's misfit is not."""
    out = 1.0
    for axis in (0, 1):
        side = n[:, axis] < np.median(n[:, axis])
        a, b = np.log(_gains(ratio[side])), np.log(_gains(ratio[~side]))
        if np.std(a) > 0 and np.std(b) > 0:
            out = min(out, float(np.corrcoef(a, b)[0, 1]))
    return out


def _spread_deg(n):
    """The normals' RMS tilt about their mean in their least-varying direction (degrees)."""
    if n.shape[0] < 3:
        return 0.0
    lam = np.linalg.eigvalsh(np.cov(n[:, :2].astype(np.float64), rowvar=False))
    return float(np.degrees(np.arcsin(np.sqrt(np.clip(lam[0], 0, 1)))))


def _done(gains, info, t0, why):
    if why:
        info["why"] = why
    info["seconds"] = round(time.perf_counter() - t0, 3)
    return gains, info
