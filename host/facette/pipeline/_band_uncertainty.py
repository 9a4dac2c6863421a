"""The normals' uncertainty (`recon.normal_uncertainty`, normal.exr's uncertainty_deg) over bands of
rows, the same values as from the images held whole, so that `process` gives the same normal.exr
with or without --memory.

`normal_uncertainty` reads two neighbourhoods besides each pixel's own values: the local fit,
above MAX_VALUES pixel-lights, runs on every s-th row and column (s from the whole mask's count) and
each coarse cell takes a 3 x 3 dilation of its neighbours where it has no normal; the curl gathers
the normals' loop sums over a Gaussian of CURL_SIGMA (4 sigma: 4 rows) and their 2 x 2 plaquettes.
Each band is therefore computed with HALO_ROWS (at least s) rows of context on either side, its
first row on the whole image's grid of s, with the whole image's stride imposed (`_max_values`),
and only its own rows kept.
"""
import time

import numpy as np

from facette._memory import disk_array, release
from facette.pipeline._confidence import UNCERTAINTY_CHANNEL, normal_channels, uncertainty_stage
from facette.recon import normal_uncertainty, uncertainty_summary
from facette.recon._uncertainty import MAX_VALUES, fit_stride

__all__ = ["uncertainty_over_bands", "uncertainty_of", "banded_uncertainty", "normal_image", "HALO_ROWS"]

# rows of context a band's curl needs: its plaquettes (1 row) and the Gaussian's reach (4 sigma, 4 rows)
HALO_ROWS = 8


def uncertainty_over_bands(read, normals, mask, m, rows, saturation=None, max_values=MAX_VALUES, on_disk=False):
    """(H, W) float32 deg: `normal_uncertainty` of the images read band by band, read(r0, r1) ->
    (images (m, r1 - r0, W, C) as the solve saw them, light directions (m, 3) or per pixel of those
    rows); normals (H, W, 3) (an array on disk too: read a band at a time); mask (H, W) bool;
    max_values: `normal_uncertainty`'s; on_disk: the map in a temporary file (`_memory.disk_array`)."""
    h = mask.shape[0]
    out = disk_array(mask.shape, np.float32) if on_disk else np.zeros(mask.shape, np.float32)
    has_n = np.empty(mask.shape, bool)
    for r0 in range(0, h, rows):            # its mask as normal_uncertainty makes it, a band at a time
        has_n[r0:r0 + rows] = np.linalg.norm(np.asarray(normals[r0:r0 + rows], np.float64), axis=2) > 0.5
        release(normals)                    # a map on disk: its pages read so far handed back
    s = fit_stride(int(np.count_nonzero(mask & has_n)) * m, max_values)
    halo = max(HALO_ROWS, s)
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        a, b = max(0, r0 - halo) // s * s, min(h, r1 + halo)
        images, dirs = read(a, b)
        values = int(np.count_nonzero(mask[a:b] & has_n[a:b])) * m
        # the whole image's stride s in this band: ceil(sqrt(values / (values / (s - 0.5)^2))) = s
        most = np.inf if s == 1 or values == 0 else values / (s - 0.5) ** 2
        band = normal_uncertainty(images, dirs, np.asarray(normals[a:b]), mask[a:b], saturation=saturation,
                                  max_values=most)
        out[r0:r1] = band[r0 - a:r1 - a]
        release(out)
        release(normals)
        del images, band
    return out


def uncertainty_of(res, direct, light_dirs, saturation):
    """res.uncertainty and its summary: from the images held whole (`_confidence.uncertainty_stage`), or,
    over bands, the summary of the map `uncertainty_over_bands` made (res.uncertainty already set)."""
    if res.uncertainty is None:
        uncertainty_stage(res, direct, light_dirs, saturation)
        return
    summary = uncertainty_summary(res.uncertainty, res.mask)
    if summary is not None:
        res.quality["normal_uncertainty"] = summary


def banded_uncertainty(res, read, m, rows, saturation):
    """res.uncertainty over bands (`uncertainty_over_bands`), its time in res.timings."""
    t0 = time.perf_counter()
    res.uncertainty = uncertainty_over_bands(read, res.normals, res.mask, m, rows, saturation, on_disk=True)
    res.timings["uncertainty"] = time.perf_counter() - t0


def normal_image(res, rows=256):
    """normal.exr's (image, channel names) as `_confidence.normal_channels`, but with the normals in a
    temporary file (over bands) the four channels joined in one too, a band at a time: the
    (H, W, 4) float32 image is 0.8 GB at 50 MP, more than a 2 GB budget has left."""
    if getattr(res, "uncertainty", None) is None or not isinstance(res.normals, np.memmap):
        return normal_channels(res)
    h, w = res.normals.shape[:2]
    out = disk_array((h, w, 4), np.float32)
    for r0 in range(0, h, rows):
        out[r0:r0 + rows, :, :3] = res.normals[r0:r0 + rows]
        out[r0:r0 + rows, :, 3] = res.uncertainty[r0:r0 + rows]
        release(out)
        release(res.normals)    # the sources' pages too: 16 bytes per pixel resident else (1.6 GB at 100 MP)
        release(res.uncertainty)
    return out, ("X", "Y", "Z", UNCERTAINTY_CHANNEL)
