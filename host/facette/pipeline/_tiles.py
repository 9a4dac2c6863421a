"""Photometric stereo over tiles (row bands) of a DiLiGenT-style folder, in bounded memory.

The per-pixel methods give each pixel's normal from that pixel's values alone, so a band of
rows solved on its own gives the same normals as the whole image. `ps_tiled` stages the PNG
photographs once (two at a time, each decoded and written to a raw scratch file: OpenCV decodes whole
images only), then reads the m lights' values of one band at a time and runs the method on it.
Peak memory: two decoded photographs (H x W x 3 x 2 bytes each, while staging), then the outputs
kept (up to 32 bytes per pixel, or none when each band is handed to `on_band` as it comes)
and one band's working set (`rows_per_tile`); not the m x H x W x 3 float32 images (1.7 GB at
12 MP, 14 GB at 100 MP).
"""
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from facette._memory import parse_size
from facette.capture.diligent import _Staged
from facette.io.diligent import read_diligent_lights
from facette.io.png import png_size, read_mask
from facette.methods import PS_DEFAULT, PS_METHODS
from facette.recon import PSResult

__all__ = ["WHOLE_IMAGE_METHODS", "TILED_METHODS", "BANDED_METHODS", "FIELD_BYTES", "PROCESS_BYTES", "parse_memory", "rows_per_tile", "ps_tiled"]

# Methods that need every pixel at once, and why: they cannot run over tiles.
WHOLE_IMAGE_METHODS = {
    "rpca_wu2010": "its RPCA makes the lights x pixels matrix of the whole image low-rank: every "
                   "pixel's normal depends on the others",
}

# A band's working set per pixel and per light (float32 RGB images of the band, the green
# channel's copy, usable flags, the method's temporaries and its band result), in bytes:
# tracemalloc peaks on the relief slab (bench/_large.py), 12 lights, 512k-pixel bands:
# woodham1980 38.5, rank_trimmed 43, hierarchical 62, st14 48 (at 131k pixels 39, 59, 148, 53:
# the block-wise stages hold a fixed part, BAND_FIXED_BYTES), rounded up; others: the largest.
# consensus_higo2010 40.5 (131k pixels: 40.5; the same measure gave woodham1980 38.6, st14 47.4):
# its kernel holds blocks of 1024 pixels only
BYTES_PER_PIXEL_LIGHT = {"woodham1980": 40, "rank_trimmed": 48, "hierarchical_tautzia2016": 66,
                         "bipolynomial_shi2014": 52, "bivariate_ikehata2014": 66, "consensus_higo2010": 42,
                         "li_alternating": 100}
BAND_FIXED_BYTES = 256 * 2 ** 20
# The `facette` command's own resident memory once photometric stereo has run (Python, numpy,
# scipy, numba and its compiled kernels, OpenEXR): 0.45 GB on the DiLiGenT cat crop with
# --memory; a `process --memory` counts it in its budget (the process's, not only the bands')
PROCESS_BYTES = 450 * 10 ** 6
# Bytes per pixel of each output `ps_tiled` can keep at the image's size.
FIELD_BYTES = {"normal": 12, "albedo": 12, "valid": 1, "residual": 4, "n_triplets": 2, "skipped": 1}
MIN_ROWS = 1
# a band's photographs with the solve's channel appended (pipeline._channels.with_solve_channel: the
# (m, rows, W, 4) float32 copy, 16 bytes, and the method's fourth channel in its temporaries)
SOLVE_CHANNEL_BYTES = 24
# The per-pixel methods: a pixel's normal from its own values only (tests check each tiled).
TILED_METHODS = ("woodham1980", "hierarchical_tautzia2016", "rank_trimmed", "bipolynomial_shi2014",
                 "bivariate_ikehata2014", "consensus_higo2010")
# What `process` runs over bands: the per-pixel methods, and li_alternating, whose material model
# is fitted once on a sample drawn across the bands and held fixed in each (fit._ps_li_bands)
BANDED_METHODS = TILED_METHODS + ("li_alternating",)

def parse_memory(text):
    """'2GB', '1.5 GB', '512MB', '3GiB', '1TB' or a number of bytes -> bytes (int): facette._memory's
    one size parser (ValueError for what is not a size, or more than this machine's memory)."""
    return parse_size(text, "memory")


def rows_per_tile(width, height, lights, memory, method=PS_DEFAULT, keep=tuple(FIELD_BYTES),
                  per_light_flags=False, held=0, extra_per_pixel_light=0):
    """Rows of a band so that `ps_tiled` stays within `memory` (bytes, or a text for
    `parse_memory`). Staging (two decoded RGB photographs at once, 12 bytes per pixel at 16
    bits) comes first; then `held` (bytes the caller holds besides: the process's libraries and
    its maps at the image's size, so that the budget is the whole process's), the outputs kept
    whole (`keep`, FIELD_BYTES each, and 2 x lights bytes per pixel with `per_light_flags`), the
    mask, the band's fixed part and the band's rows, each the method's BYTES_PER_PIXEL_LIGHT x
    lights x width bytes (plus `extra_per_pixel_light`: the solve's channel appended, SOLVE_CHANNEL_BYTES).

    Raises ValueError when even one row does not fit."""
    memory = parse_memory(memory)
    width, height, lights = int(width), int(height), int(lights)
    _check_keep(keep)
    per_out = sum(FIELD_BYTES[k] for k in keep) + (2 * lights if per_light_flags else 0)
    pixels = width * height
    staging = pixels * (3 * 2 * 2 + 1)
    fixed = int(held) + pixels * (per_out + 1) + BAND_FIXED_BYTES
    per_pixel_light = BYTES_PER_PIXEL_LIGHT.get(PS_METHODS.canonical(method),
                                                max(BYTES_PER_PIXEL_LIGHT.values()))
    per_row = width * lights * (per_pixel_light + extra_per_pixel_light)
    if memory < staging or memory - fixed < per_row * MIN_ROWS:
        need = max(staging, fixed + per_row * MIN_ROWS) / 1e9
        besides = f" ({held / 1e9:.2f} GB held besides: libraries and maps)" if held else ""
        raise ValueError(f"{memory / 1e9:.2f} GB cannot hold the outputs kept of a {width}x{height} "
                         f"image and one band of {lights} lights{besides}: give at least {need:.2f} GB, or "
                         "keep fewer outputs")
    return int(max(MIN_ROWS, min(height, (memory - fixed) // per_row)))


def _check_keep(keep):
    """ValueError unless every name of `keep` is an output of FIELD_BYTES."""
    unknown = set(keep) - set(FIELD_BYTES)
    if unknown:
        raise ValueError(f"keep names outputs of {', '.join(FIELD_BYTES)}; got {sorted(unknown)}")


def _check_method(method):
    name = PS_METHODS.canonical(method)
    if name not in TILED_METHODS:
        why = WHOLE_IMAGE_METHODS.get(name, "each tile would fit its own material model (`process --memory` "
                                            "fits one across the bands)" if name in BANDED_METHODS
                                            else "it is not known to be per-pixel")
        raise ValueError(f"{name} cannot run over tiles: {why}; use a "
                         f"per-pixel method ({', '.join(TILED_METHODS)}) or the untiled photometric_stereo")
    return name


def ps_tiled(folder, method=PS_DEFAULT, memory="2GB", rows=None, mask=None, keep=tuple(FIELD_BYTES),
             per_light_flags=False, on_band=None, work_dir=None, **kwargs):
    """Photometric stereo of a DiLiGenT-style folder over row bands, in bounded memory.

    folder : a DiLiGenT-style folder (filenames.txt, light_directions.txt, optional
        light_intensities.txt and mask.png, PNG photographs).
    method : a per-pixel name of facette.methods.PS_METHODS (not those of WHOLE_IMAGE_METHODS: ValueError).
    memory : the budget (bytes or '2GB') from which `rows_per_tile` chooses the band height.
    rows : the band height in rows instead (tests force small tiles with it).
    mask : (H, W) bool, default the folder's mask.png (all pixels without one).
    keep : the outputs kept at the image's size (names of FIELD_BYTES); the others are
        returned with no pixels, shape (0, ...).
    per_light_flags : keep the (H, W, m) shadow and specular flags (2 x m bytes per pixel);
        False: they are (H, W, 0).
    on_band : called as on_band(r0, r1, part) with each band's `PSResult` (rows r0..r1) as it
        comes, e.g. to write it out: with keep=() memory is then set by the band alone.
    work_dir : where the staged raw photographs go (m x H x W x 3 x 2 bytes; default a
        temporary folder, removed at the end).
    kwargs : the method's options (saturation, thresholds, ...).
    Returns a `PSResult` as the untiled method's (normals equal within float32 rounding);
    info: method, pixels, tiles, rows_per_tile, notes (lights left out), seconds spent staging the photographs
    (staging_s), reading the bands (read_s) and in the method (ps_s, `on_band` included), and
    the first tile's other info.
    """
    folder = Path(folder)
    name = _check_method(method)
    fn = PS_METHODS[name]
    names, dirs, inten, notes = read_diligent_lights(folder)
    m = len(names)
    _check_keep(keep)
    if rows is None:               # before any work: a budget too small is said at once
        w, h = png_size(folder / names[0])
        rows = rows_per_tile(w, h, m, memory, name, keep, per_light_flags)
    rows = int(rows)
    if rows < 1:
        raise ValueError(f"rows must be >= 1, got {rows}")
    work = Path(tempfile.mkdtemp(prefix="facette-tiles-", dir=work_dir))
    try:
        t0 = time.perf_counter()
        staged = _Staged(folder, names, work)
        t_staged = time.perf_counter()
        read_s = 0.0
        h, w, _ = staged.shape
        if mask is None:
            mask = read_mask(folder / "mask.png") if (folder / "mask.png").is_file() else np.ones((h, w), bool)
        mask = np.asarray(mask, bool)
        if mask.shape != (h, w):
            raise ValueError(f"the mask is {mask.shape[1]}x{mask.shape[0]}, the images are {w}x{h}")
        k = m if per_light_flags else 0

        def full(field, tail, dtype):
            return np.zeros(((h, w) if field in keep else (0, 0)) + tail, dtype)
        res = PSResult(normal=full("normal", (3,), np.float32), albedo=full("albedo", (3,), np.float32),
                       valid=full("valid", (), bool), n_triplets=full("n_triplets", (), np.int16),
                       shadow=np.zeros((h, w, k), bool), specular=np.zeros((h, w, k), bool),
                       residual=full("residual", (), np.float32), skipped=full("skipped", (), bool),
                       method=name)
        info, pixels, tiles = {}, 0, 0
        for r0 in range(0, h, rows):
            r1 = min(h, r0 + rows)
            tiles += 1
            if not mask[r0:r1].any():
                continue       # outputs stay zero; on_band is not called for an empty band
            t_read = time.perf_counter()
            band = staged.band(r0, r1, inten)
            read_s += time.perf_counter() - t_read
            part = fn(band, dirs, mask=mask[r0:r1], **kwargs)
            del band
            for field in keep:
                getattr(res, field)[r0:r1] = getattr(part, field)
            if per_light_flags:
                res.shadow[r0:r1], res.specular[r0:r1] = part.shadow, part.specular
            if on_band is not None:
                on_band(r0, r1, part)
            pixels += int(part.info.get("pixels", 0))
            info = info or dict(part.info)
            del part
        res.info = dict(info, method=name, pixels=pixels, tiles=tiles, rows_per_tile=rows, notes=notes,
                        staging_s=t_staged - t0, read_s=read_s,
                        ps_s=time.perf_counter() - t_staged - read_s)
        return res
    finally:
        shutil.rmtree(work, ignore_errors=True)
