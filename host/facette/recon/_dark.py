"""The additive dark level of each photograph: what a pixel reads when its light is behind it.

A light behind the surface (n · s < 0: attached shadow) sends no direct light to the pixel, so
whatever the pixel reads there is added to every pixel of that photograph: the camera's black
level left in the data, ambient light in the room, flare. Models that predict exactly 0 in attached
shadow and little near the terminator (the LI model) read that offset as light, and bend the
normals towards it. On the 16-bit DiLiGenT ball such pixels read a median 37 DN (green; 0.8 % of
the lit median, 4 756 DN) by the true normals; its 8-bit crops lose it in their floor(v / 256).

    dark_offsets(images, light_dirs, normals, valid) -> (offsets (m, C), info)

Estimated per photograph and channel as the lower quartile (DARK_QUANTILE) of the readings of the
valid pixels whose initial normal puts the light at least DARK_BELOW behind the surface
(n · s < −0.2: about 12° of normal error still leaves the pixel in attached shadow), unsaturated
and finite. A floor, not the median: whatever else reaches those pixels only adds light
(inter-reflections in a concavity, a wrong initial normal that is in fact lit), so the level all
but the lowest quarter read is the offset; a concave object whose dark pixels are half lit by its
own walls (DiLiGenT reading: median 25 % of the lit median, lower quartile 0) gets none, where a
uniform level (the 16-bit ball: 1.0 % at the lower quartile, 1.3 % at the median) stays. The
lower quartile must also be at least DARK_UNIFORM of the median, the sign of one level common to
the dark pixels (pedestal plus noise: p25 ≈ level − 0.67 σ); else the photograph's channel keeps
its values (DiLiGenT reading's blue: lower quartile 0.0036, 10 % of its lit median, at a few grey
levels of its 8 bits, spread up to its inter-reflections). A photograph with fewer
than DARK_MIN_PIXELS such pixels (a light near the camera's axis has none behind any visible
normal) keeps its values: the images come divided by each light's intensity, so one level in the
camera's counts is a different offset in each photograph (DiLiGenT's ball: 6× between its
grazing and its axial lights), and the others' would be the wrong one. Never negative.
"""
import numpy as np

__all__ = ["dark_offsets", "dark_level_notes", "DARK_BELOW", "DARK_MIN_PIXELS", "DARK_QUANTILE", "DARK_UNIFORM",
           "DARK_MAX_RELATIVE"]

DARK_BELOW = -0.2        # n · s below this: attached shadow even with ~12° of normal error
DARK_MIN_PIXELS = 50     # fewer dark pixels than this in a photograph: no offset taken out of it
DARK_QUANTILE = 25       # percentile of the dark pixels' readings taken as the level (a floor)
DARK_UNIFORM = 0.5       # ... when it is at least this fraction of their median (one common level)
DARK_MAX_RELATIVE = 0.05  # ... and at most this fraction of the lit pixels' median (else: not a pedestal)
LIT_SAMPLE = 2000         # lit pixels (n · s > 0.5) whose median that is compared with, at most


def dark_offsets(images, light_dirs, normals, valid, saturation=None):
    """(m, C) float32 offsets to subtract from each photograph and channel, and an info dict:
    "estimated": photographs given a level; "pixels": dark pixels read; "median": the levels'
    median per channel (over those photographs); "relative": the largest over the channels of
    that over the lit pixels' median value; "spread", "too_high": photograph-channels whose dark
    pixels were read and left as they are (no common level; above DARK_MAX_RELATIVE).

    images : (m, H, W, C) float; light_dirs : (m, 3) or (H, W, m, 3); normals : (H, W, 3) the
    initial solution; valid : (H, W) bool; saturation : values at or above it are not read."""
    m, h, w, c = images.shape
    idx = np.flatnonzero(valid.ravel())
    offsets = np.zeros((m, c), np.float32)
    info = {"estimated": 0, "pixels": 0, "median": [0.0] * c, "relative": 0.0, "spread": 0, "too_high": 0}
    if idx.size == 0:
        return offsets, info
    n = normals.reshape(-1, 3)[idx].astype(np.float32)
    per_pixel = None if light_dirs.ndim == 2 else light_dirs.reshape(-1, m, 3)

    def dots(k):     # n · s of light k at the valid pixels (one light at a time: no (N, m) array)
        if per_pixel is None:
            return n @ np.asarray(light_dirs[k], np.float32)
        return np.einsum("nk,nk->n", n, per_pixel[idx, k].astype(np.float32))

    flat = images.reshape(m, h * w, c)
    lit_med = np.full((m, c), np.nan)

    def readable(k, rows):     # the values of photograph k at those valid pixels, finite and unsaturated
        v = flat[k, idx[rows], :]
        ok = np.all(np.isfinite(v), axis=1)
        if saturation is not None:
            ok &= np.all(v < saturation, axis=1)
        return v[ok]

    for k in range(m):
        d = dots(k)
        rows = np.flatnonzero(d < DARK_BELOW)
        if rows.size < DARK_MIN_PIXELS:
            continue
        dark = readable(k, rows)
        lit = np.flatnonzero(d > 0.5)
        if len(dark) < DARK_MIN_PIXELS or lit.size == 0:
            continue
        lit = readable(k, lit[::max(1, lit.size // LIT_SAMPLE)])     # a median to compare with: a sample does
        if len(lit) == 0:
            continue
        low, mid = np.percentile(dark, [DARK_QUANTILE, 50], axis=0)
        lit_med[k] = np.median(lit, axis=0)
        common = low >= DARK_UNIFORM * mid
        small = low <= DARK_MAX_RELATIVE * lit_med[k]
        offsets[k] = np.where(common & small, np.maximum(low, 0), 0)
        info["pixels"] += len(dark)
        info["spread"] += int((~common & (mid > 0)).sum())
        info["too_high"] += int((common & ~small).sum())
    have = offsets.any(axis=1)
    if have.any():
        med = np.median(offsets[have], axis=0)
        info.update(estimated=int(have.sum()), median=[float(x) for x in med],
                    relative=float(np.nanmax(med / np.maximum(np.nanmedian(lit_med[have], axis=0), 1e-12))))
    return offsets, info


def dark_level_notes(info):
    """The lines a report and the command line give of `dark_offsets`' info (none when it read
    nothing to say)."""
    if not info:
        return []
    out = []
    if info.get("applied"):
        out.append(f"dark level taken out of {info['estimated']} photograph(s) before the BRDF-aware solve: "
                   f"{100 * info['relative']:.1f} % of the lit median (what pixels read with their light behind "
                   "them: black level, ambient light, flare)")
    if info.get("too_high"):
        out.append(f"pixels with their light behind them read more than {DARK_MAX_RELATIVE:.0%} of the lit median "
                   f"in {info['too_high']} photograph channel(s): left in (inter-reflections, or a room that was "
                   "not dark: photograph in the dark for the best normals)")
    return out
