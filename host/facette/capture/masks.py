"""The masks a capture's photographs give: the lit pixels, the object's material against a dark
table or cloth (Otsu's split of log luminance), the object grown into its dark rims, the margin
around it. From the whole images (`auto_masks`) or from the two maps a band-by-band reading
computes (`masks_from`)."""
import numpy as np
from scipy import ndimage

__all__ = ["OBJECT_OVER_TABLE", "MARGIN_BORDER", "MASK_ROWS", "auto_masks", "masks_from", "object_of", "margin_of"]


# `object_of`: an object pixel is lit, under its brightest light, at least this many times the
# table's median brightest value (simulated demo: 116,003 object pixels found of the truth's
# 116,082, 19 of the table taken; Otsu's class alone: 109,841, the sphere's dark rim left out)
OBJECT_OVER_TABLE = 2.0


# The dark class is a margin (a table, a cloth) only where it surrounds the object: at least
# this share of the lit pixels on the image's border.
MARGIN_BORDER = 0.9


# `masks_from` reads its two maps this many rows at a time
MASK_ROWS = 512


def auto_masks(images, min_contrast=4.0):
    """Two masks, (lit, material), each (H, W) bool.

    lit : pixels lit above 2 % of the bright end (99th percentile of the per-pixel maximum
        over the lights): where photometric stereo and integration run. A dark table under
        the object stays in, so heights keep one reference plane across separate objects.
    material : the lit pixels on the bright side of Otsu's threshold on log luminance when
        the scene has a dark background (black velvet, the simulator's table); else `lit`.
        The reflectance samples, hence the BRDF fit, come from these pixels only: a
        background is another material and drags the fit away (on the simulated sphere, with
        the table in, σ came out 1.43 instead of 0.05).

    The background is cut only when the two classes' mean luminances differ by more than
    `min_contrast` times: a slab that fills the frame keeps every lit pixel. The luminance for
    that split is the median over the lights (highlights and shadows do not move it).
    """
    ch = images[..., 1] if images.shape[-1] == 3 else images.mean(axis=-1)
    lum = np.fmax.reduce(ch, axis=0)      # NaN-ignoring max over the lights
    from facette.capture._pixels_jit import median_over_lights
    med = np.empty(lum.shape, ch.dtype)  # pixels unknown under every light: NaN, dropped below
    median_over_lights(ch, med, slice(None), workers=2)
    return masks_from(lum, med, min_contrast)


def masks_from(top, med, min_contrast=4.0, rows=MASK_ROWS):
    """`auto_masks` from its two maps of the green channel over the lights, (H, W) each: `top`
    the NaN-ignoring maximum, `med` the median of the known values (NaN where none); a tiled
    reading computes them band by band (pipeline._tiled_process). Read `rows` rows at a time:
    besides the two masks nothing is made at the image's size (at 100 MP the whole-image
    temporaries were ~1.7 GB on top of the two maps); the same masks for any `rows`."""
    h = top.shape[0]
    bands = [slice(r0, r0 + rows) for r0 in range(0, h, rows)]
    sub = np.nan_to_num(top.ravel()[::7], nan=0.0)            # a quantile needs no full sort
    ref = float(np.quantile(sub, 0.99)) if sub.size else 0.0
    if not ref > 0:
        return np.zeros(top.shape, bool), np.zeros(top.shape, bool)
    lit = np.empty(top.shape, bool)
    lo, hi, n_ok = None, None, 0

    def log_ok(b):        # log of the median where it is known and positive on a lit pixel
        with np.errstate(invalid="ignore"):
            ok = lit[b] & np.isfinite(med[b]) & (med[b] > 0)
        return ok, np.log(med[b][ok])
    for b in bands:
        with np.errstate(invalid="ignore"):
            lit[b] = np.nan_to_num(top[b], nan=0.0) > 0.02 * ref
        ok, logl = log_ok(b)
        if logl.size:
            lo = logl.min() if lo is None else min(lo, logl.min())
            hi = logl.max() if hi is None else max(hi, logl.max())
            n_ok += logl.size
    if n_ok < 16:
        return lit, lit
    hist, edges = 0, None            # np.histogram(all, 256) has the range (min, max): same bins
    for b in bands:
        part, edges = np.histogram(log_ok(b)[1], bins=256, range=(lo, hi))
        hist = hist + part
    w0 = np.cumsum(hist)                                     # Otsu: maximise the between-class variance
    w1 = w0[-1] - w0
    centres = 0.5 * (edges[1:] + edges[:-1])
    s0 = np.cumsum(hist * centres)
    with np.errstate(divide="ignore", invalid="ignore"):
        m0, m1 = s0 / w0, (s0[-1] - s0) / w1
        between = np.where((w0 > 0) & (w1 > 0), w0 * w1 * (m0 - m1) ** 2, -1.0)
    k = int(np.argmax(between))
    if between[k] <= 0 or m1[k] - m0[k] < np.log(min_contrast):
        return lit, lit
    material = np.zeros(top.shape, bool)
    for b in bands:
        ok, logl = log_ok(b)
        material[b][ok] = logl > edges[k + 1]
    return lit, material


def object_of(images, lit, material, factor=OBJECT_OVER_TABLE, top=None):
    """The object (H, W) bool: `material` (Otsu's bright class of `auto_masks`) grown into the
    lit pixels connected to it that are brighter, under their brightest light, than `factor`
    times the table's median (the dark rims and grooves of an object, which the median over the
    lights puts on the table's side). `lit` itself when there is no table (material == lit).
    top : that brightest value (H, W), NaN-ignoring maximum of the green channel over the lights,
    when it is at hand (then `images` is not read and may be None)."""
    lit, material = np.asarray(lit, bool), np.asarray(material, bool)
    table = lit & ~material
    if not table.any() or not material.any():
        return material.copy()
    if top is None:
        ch = images[..., 1] if images.shape[-1] == 3 else images.mean(axis=-1)
        top = np.fmax.reduce(ch, axis=0)             # NaN-ignoring; all-NaN (saturated): NaN
    floor = factor * float(np.median(np.nan_to_num(top[table], nan=0.0)))
    with np.errstate(invalid="ignore"):
        bright = lit & ((top > floor) | np.isnan(top))
    labels, _ = ndimage.label(bright | material)
    keep = np.zeros(labels.max() + 1, bool)
    keep[np.unique(labels[material])] = True
    keep[0] = False
    return keep[labels]


def margin_of(lit, material):
    """The lit pixels outside the object's material (the dark table or cloth it lies on) when
    they surround it, else None: no dark class, or a dark class that is part of the object (a
    slab filling the frame with a dark matrix: less than MARGIN_BORDER of the image's lit border
    pixels in it). lit, material : (H, W) bool, as `auto_masks` gives them."""
    lit = np.asarray(lit, bool)
    bg = lit & ~np.asarray(material, bool)

    def border(a):
        return np.concatenate([a[0], a[-1], a[1:-1, 0], a[1:-1, -1]])

    if not bg.any() or border(bg).sum() < MARGIN_BORDER * max(1, border(lit).sum()):
        return None
    return bg
