"""`process` when no output asked for needs the normals (relight.ptm, relight.rti, relight_web/ alone):
the photographs read band by band, fitted (`_rti_bands.relight_bands`) and spilled, no photometric
stereo.

These files need the photographs, their scale and the object's mask only (`_stages.STAGES_FOR`): the
whole reading (`_whole.whole_process`) already skipped photometric stereo for them, the band loop
(`_streamed`) did not (12 MP, 16 JPEGs, `--outputs rti,ptm`: 241 s of a 572 s run). Here the capture
is opened as the band loop opens it (`capture.open_capture`: the masks' maps band by band, the
photographs never held whole), the object's mask is the whole reading's (the input's mask, less the
table around the object), and one pass of bands fits the files (two for an HDR scan: its exposure
first): the whole reading's bytes. The quality counts (`_quality.sample_counts`) add up over the
first reading of each band and are judged after the bands, as the band loop judges them.

Whether they run so: `relight_only_budget`, after the default budget (`_budget.with_default_budget`).
A capture's folder is read over bands whatever its size: nothing needs the photographs whole, and over
bands the run holds its budget's bands (at most BANDS_MAX_BYTES) where the whole reading holds every
photograph (12 MP, 16 JPEGs: 2.3 GB of float32 values).
"""
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from facette._memory import hand_back
from facette.capture import object_of, open_capture, source_path
from facette.pipeline._budget import BANDS_MAX_BYTES, default_budget
from facette.pipeline._quality import add_counts, check_counts, light_geometry, sample_counts
from facette.pipeline._rti_bands import BYTES_PER_PIXEL, BYTES_PER_PIXEL_LIGHT, band_reader, relight_bands
from facette.pipeline._tiles import PROCESS_BYTES

__all__ = ["relight_only", "relight_only_budget", "relight_only_bands", "relight_band_rows"]


def relight_only(stages):
    """True when no stage asked for needs photometric stereo (`_stages.stages_needed`)."""
    return "ps" not in stages and "load" in stages


def relight_only_budget(source, o, stages, free=None):
    """(options, notes) when no output asked for needs the normals and the source is a capture's folder:
    `o` with the budget its bands take (--memory when given, else the default budget's, at most
    BANDS_MAX_BYTES) and the note that says so; None otherwise (the default budget decides:
    `_budget.with_default_budget`). free: the free memory (bytes; None: the machine's)."""
    if not relight_only(stages):
        return None
    try:
        if not source_path(source).is_dir():
            return None
    except TypeError:
        return None
    if o.memory is not None:
        return o, []
    budget = default_budget(free)
    bands = min(BANDS_MAX_BYTES, budget or BANDS_MAX_BYTES)
    said = (f"memory: the relighting files alone need no photometric stereo and no photograph whole: read band "
            f"by band in {bands / 1e9:.1f} GB" + ("" if budget is None else f" (a budget of {budget / 1e9:.1f} GB "
                                                                              "from the free memory; --memory to set it)"))
    return replace(o, memory=str(bands)), [said]


def relight_band_rows(memory, w, h, m, maps_bytes):
    """Rows of a fit band within `memory` bytes (the process's own PROCESS_BYTES and the maps it holds
    at the image's size, `maps_bytes` a pixel, counted in it): `_rti_bands`' working set per row, even, >= 2."""
    left = int(memory) - PROCESS_BYTES - (int(maps_bytes) + 4) * int(w) * int(h)
    rows = left // (int(w) * (BYTES_PER_PIXEL_LIGHT * int(m) + BYTES_PER_PIXEL))
    return max(2, int(rows) // 2 * 2)


def relight_only_bands(source, o, res, outputs, claim):
    """(inp, light directions as the stages after photometric stereo take them, the claim's previous
    record, the `RelightBands` of the files asked for): fills res (inputs, mask, object mask, quality,
    notes, timings load and relight). claim(inp): the results folder's, before any work."""
    t0 = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix="facette-relight-"))
    relight, counts, counted = None, None, set()
    try:
        inp, bands, top, n = open_capture(
            source, work, lambda w, h, m, maps_bytes: relight_band_rows(o.memory_bytes, w, h, m, maps_bytes),
            None, o.allow_incomplete, o.pixel_pitch_mm, o.mask, o.capture, lambda: hand_back(o.memory_bytes))
        try:
            previous = claim(inp)
            res.inputs = inp
            res.notes.extend(inp.notes)
            res.mask = inp.mask             # as the whole reading without photometric stereo (`_whole`)
            res.object_mask = inp.mask if inp.background_mask() is None else \
                inp.mask & object_of(None, inp.mask, inp.material_mask, top=top)
            del top
            res.timings["load"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            h, w = inp.mask.shape
            near = None
            if o.near_light and inp.positions_mm is not None:
                near = (np.asarray(inp.positions_mm), (h, w), inp.pixel_pitch_mm)
                res.notes.append("near lights: per-pixel directions and 1/r^2 fall-off from the light positions")

            class Counted:          # the band reader, the quality counts taken on each band's first reading
                def read(self, r0, r1):
                    nonlocal counts
                    images, usable = bands.read(r0, r1)
                    if (r0, r1) not in counted:
                        counted.add((r0, r1))
                        counts = add_counts(counts, sample_counts(images, usable, inp.object_mask[r0:r1]))
                    return images, usable
            read = band_reader(Counted(), near, None if near else inp.light_dirs)
            relight = relight_bands(read, res.object_mask, outputs, o, None, len(inp.light_dirs), inp, rows=n)
        finally:
            bands.close()
        if counts is not None:       # the check's verdict (InsufficientData) as the whole reading's, after the bands
            notes, res.quality = check_counts(counts, inp.mask_source)
            res.notes.extend(notes + light_geometry(inp.light_dirs, res.quality))
    except BaseException:
        if relight is not None:
            relight.close()
        raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    hand_back(o.memory_bytes)
    if o.scheduler is not None:
        res.notes.append(f"--scheduler {o.scheduler}: not used (no photometric stereo: the files are fitted here)")
    res.notes.append(f"--memory {o.memory}: no photometric stereo (no output asked for needs the normals); the "
                     f"relighting files fitted over bands of {min(n, inp.mask.shape[0])} rows, the images read band by "
                     "band (never held whole)")
    res.timings["relight_bands"] = time.perf_counter() - t0
    return inp, (None if near else inp.light_dirs), previous, relight
