"""Which samples of a photograph are usable: known (not saturated: NaN) and above the noise —
signal >= MIN_SNR standard deviations of its own variance (scans, from the HDR merge's _var.exr),
or >= MIN_LEVELS grey levels of the file's bit depth (PNG folders, RTI captures). Each capture
reader marks its samples with these (pipeline._quality judges the counts)."""
import numpy as np

__all__ = ["MIN_SNR", "MIN_LEVELS", "usable_from_variance", "usable_from_levels", "usable_from_green"]


MIN_SNR = 3.0              # signal / noise standard deviation of a usable sample


MIN_LEVELS = 2             # grey levels of a PNG above which a sample is not dark noise


def usable_from_variance(image, variance):
    """(H, W) bool: known (finite) and >= MIN_SNR standard deviations, on the green channel.
    image, variance : (H, W, 3) radiance and its variance (any consistent unit)."""
    return usable_from_green(image[..., 1], variance[..., 1])


def usable_from_levels(levels):
    """Known and at least MIN_LEVELS grey levels of the image's bit depth, elementwise (`levels`:
    values in grey levels; images without a variance, PNG folders and RTI captures, whose noise
    floor is their quantisation)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(levels) & (levels >= MIN_LEVELS)


def usable_from_green(g, v):
    """`usable_from_variance` of the green channel alone: g, v (H, W) radiance and variance.
    In one compiled pass for two float32 maps, as the HDR loader has them (12 MP: 0.01 s
    instead of 0.1 s per light)."""
    if g.ndim == 2 and g.shape == v.shape and g.dtype == v.dtype == np.float32:
        from facette.capture._pixels_jit import usable_green
        return usable_green(g, v, MIN_SNR, np.empty(g.shape, bool))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.isfinite(g) & np.isfinite(v) & (g > 0) & (g * g >= MIN_SNR ** 2 * v)
