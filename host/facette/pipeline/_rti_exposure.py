"""relight.ptm, relight.rti and the web planes as photographed: their scale, encoding and clipping.

A capture of display-encoded photographs (8-bit JPEGs, an RTI folder's PNGs or TIFFs, DiLiGenT's
PNGs) has a scale of its own: the top of the photographs' range is full brightness. The files are
fitted to the photographs as they are (RTIBuilder's way): the images `process` holds multiplied
back by what it divided them by (the light intensities given, a reference patch, the light gains
it read), at that scale, in the photographs' encoding (sRGB for 8-bit files, linear for 16-bit
ones, `--encoding`), clipped where the photographs clip (a value at the top of the range, which
`process` holds as unknown, is shown at full brightness). Relit at a captured light, a viewer shows
that photograph.

An HDR scan (radiance) has no natural white: its exposure is chosen so that at most
CLIP_PERCENT of the object's samples (pixels x lights, the brightest channel; the saturated ones
count as clipped) are above it, and written in relight.rti's header and process.json.
"""
from dataclasses import dataclass

import numpy as np

from facette.io.diligent import read_diligent_lights

__all__ = ["Exposure", "exposure_of", "exposure_note", "record_exposure", "HDRWhite", "CLIP_PERCENT", "photographed_of"]

CLIP_PERCENT = 0.1       # an HDR scan's files: the share (%) of the object's samples that may clip
ROWS = 256               # image rows of the whole images looked at a time (the HDR white)


@dataclass
class Exposure:
    """white: the images' value shown at full brightness (their unit); encoding "srgb" or "linear";
    gains (m, 3) float32 or None: each light's factor from `process`'s images back to the
    photographs (None: none); source "photographs" (their own scale) or "hdr" (chosen);
    clipped_percent: the object's samples at or above white (HDR), else None."""
    white: float
    encoding: str
    gains: object = None
    source: str = "photographs"
    clipped_percent: object = None

    def record(self):
        """What process.json says of it (its `rti_exposure`)."""
        out = {"white": self.white, "encoding": self.encoding, "scale": self.source}
        if self.source == "hdr":
            out["clipped_percent"] = self.clipped_percent
            out["max_clipped_percent"] = CLIP_PERCENT
        if self.gains is not None:
            out["light_factors"] = "the images multiplied back by the light intensities, reference or gains divided out"
        return out

    def comment(self):
        """relight.rti's header line on its scale."""
        if self.source == "photographs":
            return (f"scale: as photographed (1.0 = the photographs' full scale, clipped where they clip), "
                    f"encoding {self.encoding}")
        return (f"scale: HDR exposure, 1.0 = {self.white:.6g} in the HDR images' unit "
                f"({self.clipped_percent:.3f} % of the object's samples clip, at most {CLIP_PERCENT} %), "
                f"encoding {self.encoding}")

    def photographs(self, images):
        """The images (m, ...,  3) as photographed: multiplied back by the gains (a copy), or as given."""
        if self.gains is None:
            return images
        g = self.gains.reshape((len(self.gains),) + (1,) * (np.ndim(images) - 2) + (3,))
        return np.multiply(images, g, dtype=np.float32)


def photographed_of(inp, light_gains=None):
    """(encoding, gains (m, 3) or None) of an input whose photographs have a scale of their own, or
    None (an HDR scan). An RTI capture says it (`inp.photographed`); a DiLiGenT folder's PNGs are
    linear, divided by its light_intensities.txt. light_gains: process.json's light_gains when
    the step divided the images too."""
    own = getattr(inp, "photographed", None)
    if own is not None:
        encoding, gains = own["encoding"], own.get("gains")
    elif inp.kind == "diligent":
        encoding, gains = "linear", read_diligent_lights(inp.source)[2]
    else:
        return None
    m = len(inp.light_dirs)
    g = np.ones((m, 3)) if gains is None else np.broadcast_to(np.asarray(gains, float).reshape(m, -1), (m, 3))
    if light_gains and light_gains.get("applied"):
        g = g * np.asarray(light_gains["gains"], float)[:, None]
    return encoding, (None if np.all(g == 1.0) else g.astype(np.float32))


class HDRWhite:
    """The exposure of an HDR scan's files from its images band by band: `add(images band (m, b, W, 3),
    object mask band (b, W))`, then `value()` -> (white, clipped percent): the smallest white with at
    most CLIP_PERCENT of the object's samples (brightest channel, NaN = saturated) above it."""

    def __init__(self, most):
        self.keep = int(np.ceil(CLIP_PERCENT / 100 * most)) + 2
        self.n = self.unknown = 0
        self.top = np.empty(0)

    def add(self, images, mask):
        from facette.recon._rti_jit import brightest_above     # numba loads only when this runs
        sel = np.asarray(mask, bool)
        count = int(np.count_nonzero(sel))
        if not count:
            return
        e = np.asarray(images)
        # a sample at or below the keep-th largest kept cannot change the top `keep` values: not copied
        floor = float(self.top.min()) if self.top.size >= self.keep else 0.0
        buf = np.empty(len(e) * count, e.dtype)
        k, n, unknown = brightest_above(e, sel, floor, buf)     # NaN where any channel is unknown: counted
        self.n += n
        self.unknown += unknown
        top = np.concatenate([self.top, buf[:k]])
        if top.size > self.keep:
            top = np.partition(top, top.size - self.keep)[top.size - self.keep:]
        self.top = top

    def value(self):
        if self.n == 0 or self.top.size == 0:
            return 1.0, 0.0
        allowed = int(np.floor(CLIP_PERCENT / 100 * self.n)) - self.unknown   # finite samples that may clip
        ranked = np.sort(self.top)[::-1]
        white = float(ranked[min(max(allowed, 0), ranked.size - 1)])
        above = int((self.top > white).sum())
        return white, 100.0 * (above + self.unknown) / self.n


def exposure_of(inp, encoding_option, light_gains=None, images=None, mask=None, white=None):
    """The `Exposure` of `process`'s relighting files. encoding_option: "auto" (the photographs'
    own; sRGB for an HDR scan), "srgb" or "linear". An HDR scan's white: `white` when given (a band
    pass made it: `HDRWhite`), else from images (m, H, W, 3) over the object mask (H, W)."""
    own = photographed_of(inp, light_gains)
    if own is not None:
        enc = own[0] if encoding_option == "auto" else encoding_option
        return Exposure(1.0, enc, own[1], "photographs")
    enc = "srgb" if encoding_option == "auto" else encoding_option
    if white is None:
        top = HDRWhite(len(images) * int(np.count_nonzero(mask)))
        for r0 in range(0, mask.shape[0], ROWS):
            top.add(images[:, r0:r0 + ROWS], mask[r0:r0 + ROWS])
        white = top.value()
    white, clipped = white
    return Exposure(float(white), enc, None, "hdr", float(clipped))


def exposure_note(e):
    """`process`'s note on the relighting files' scale."""
    if e.source == "photographs":
        return (f"relight.ptm / relight.rti: as photographed (the photographs' own scale, {e.encoding} as they are, "
                "clipped where they clip): relit at a captured light, RTIViewer shows that photograph"
                + (" (the light intensities or gains `process` divided out multiplied back)" if e.gains is not None
                   else ""))
    return (f"relight.ptm / relight.rti: an HDR scan at the exposure 1.0 = {e.white:.4g} (at most {CLIP_PERCENT} % "
            f"of the object's samples clip: {e.clipped_percent:.3f} %), {e.encoding} values "
            "(process.json quality.rti_exposure)")


def record_exposure(res):
    """`process`'s note on the files' scale and process.json's quality.rti_exposure, when they were fitted."""
    if res.rti_exposure is not None and (res.ptm is not None or res.hsh is not None):
        res.notes.append(exposure_note(res.rti_exposure))
        res.quality["rti_exposure"] = res.rti_exposure.record()
