"""`process`'s normals where photometric stereo measured none (no light above the noise: a bare
metal between its highlights, a cavity's floor): interpolated from the measured ones around them
(`facette.recon.fill_normals`) when an output shows the shape, and said in the notes. mask.png
marks them grey (128, `facette.io.png.write_mask`: the object, its normal interpolated; 255 measured;
0 outside). The reflectance samples and the BRDF fit read photometric stereo's own valid pixels,
never these.
"""
import time

from facette.recon import fill_normals

__all__ = ["normals_of", "SHAPE_OUTPUTS"]

SHAPE_OUTPUTS = frozenset({"normals", "mask", "height", "mesh", "gltf", "report"})   # what shows the shape


def normals_of(res, inp, ps):
    """res.normals, albedo, mask and filled from photometric stereo's result `ps` (a PSResult) on
    `inp` (a PSInput): res.mask the measured pixels of the input mask and the filled ones, res.filled
    the (H, W) bool map of the filled ones (None when none were)."""
    measured = ps.valid & inp.mask
    res.normals, res.albedo, res.filled = ps.normal, ps.albedo, None
    if SHAPE_OUTPUTS & set(res.options.get("outputs", SHAPE_OUTPUTS)):
        t0 = time.perf_counter()
        normals, filled = fill_normals(ps.normal, measured, inp.mask)
        if filled.any():
            res.normals, res.filled = normals, filled
            res.timings["fill"] = time.perf_counter() - t0
            n = int(filled.sum())
            res.notes.append(
                f"normals interpolated at {n:,} pixels ({100 * n / max(int(inp.mask.sum()), 1):.1f} % of the object) "
                "that no light reached above the noise (a bare metal between its highlights, shadow in every "
                "photograph): harmonic from the measured normals around them, grey in mask.png, left out of "
                "the reflectance samples and the BRDF fit")
    res.mask = measured if res.filled is None else measured | res.filled
