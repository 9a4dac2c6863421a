"""The memory budget `process` runs in when none is given: the memory the machine has free
(MemAvailable), less a margin, said in a note. A capture whose photographs, held whole, fit in
it is read whole as before; one that does not is read band by band in that budget (as
`--memory`), so that a capture too large for the machine runs without a flag instead of being
killed by the system with no word."""
import os
from dataclasses import replace

from facette.capture import capture_size
from facette.methods import PS_DEFAULT, PS_METHODS
from facette.pipeline._tiled_process import streamed
from facette.pipeline._tiles import BANDED_METHODS, PROCESS_BYTES, WHOLE_IMAGE_METHODS

__all__ = ["FREE_SHARE", "RESERVE_BYTES", "BANDS_MAX_BYTES", "WHOLE_BYTES_PER_PIXEL_LIGHT", "free_memory",
           "default_budget", "with_default_budget", "whole_bytes"]

# of the free memory, the share a run takes, and what it leaves besides (the system, a viewer): half,
# because the free memory is a reading of one moment on a machine others use too (6 engineers on 24 GB:
# MemAvailable went 22 -> 12 GB within minutes), and the whole reading's peak comes minutes after it
FREE_SHARE = 0.5
RESERVE_BYTES = 1 * 10 ** 9
# a capture read band by band needs no more than this: larger bands buy no speed (12 MP, 12 lights,
# li_alternating: --memory 2GB 94.1 s / 1.07 GB against 120.6 s / 9.56 GB read whole), and a run that
# holds 4 GB survives what a run that holds most of the free memory does not
BANDS_MAX_BYTES = 4 * 10 ** 9
# the whole reading's peak per pixel and light (float32 RGB photographs, their usable flags, the
# channel chosen for the solve, the light gains' copy, the method's temporaries), less the process's
# own PROCESS_BYTES: the 12 MP relief slab of `facette bench size`, 12 lights, normals and height,
# max RSS 9.68 GB with the default li_alternating (63 bytes), 4.52 GB with rank_trimmed (28); issue
# 49's every output, 7 GB (46); rounded up from the largest
WHOLE_BYTES_PER_PIXEL_LIGHT = 66


def whole_bytes(m, h, w):
    """The whole reading's peak (bytes) for m photographs of w x h pixels."""
    return PROCESS_BYTES + WHOLE_BYTES_PER_PIXEL_LIGHT * m * h * w


def free_memory():
    """Bytes the machine can give without swapping (Linux: MemAvailable), or None."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def default_budget(free=None):
    """FREE_SHARE of the free memory less RESERVE_BYTES (at least 1 GB), or None when unknown."""
    free = free_memory() if free is None else free
    return None if free is None else int(max(10 ** 9, FREE_SHARE * free - RESERVE_BYTES))


def with_default_budget(source, o, outputs, free=None):
    """(options, notes: [the budget's] or []): `o` itself when --memory was given (or nothing can be known); else
    the budget from the free memory, said, and `o` with it as its memory when the capture does
    not fit whole (the BRDF-aware default, which needs every pixel at once, then gives way to the
    per-pixel PS_DEFAULT, said)."""
    if o.memory is not None:
        return o, []
    free = free_memory() if free is None else free
    budget, size = default_budget(free), capture_size(source)
    if budget is None or size is None:
        return o, []
    m, h, w = size
    need = whole_bytes(m, h, w)
    said = (f"memory: a budget of {budget / 1e9:.1f} GB ({FREE_SHARE:.0%} of the {free / 1e9:.1f} "
            f"GB free, less {RESERVE_BYTES / 1e9:.0f} GB; --memory to set it)")
    if need <= budget:
        return o, [f"{said}: the capture ({m} photographs of {w}x{h} px, ~{need / 1e9:.1f} GB whole) is read whole"]
    if not streamed(source, outputs) or o.interreflections is True:
        return o, [f"{said} cannot hold the capture read whole (~{need / 1e9:.1f} GB) and the outputs asked for "
                   "need it whole: the run may exceed the machine's memory; give --memory to read it band by band"]
    method = PS_METHODS.canonical(o.method)
    switched = method not in BANDED_METHODS
    bands = min(budget, BANDS_MAX_BYTES)
    note = (f"{said}: the capture ({m} photographs of {w}x{h} px) needs ~{need / 1e9:.1f} GB whole: read band by "
            f"band in {bands / 1e9:.1f} GB" + ("" if bands == budget else " (larger bands buy no speed)"))
    if switched:
        why = WHOLE_IMAGE_METHODS.get(method, "it is not known to be per-pixel")
        note += f", photometric stereo with {PS_DEFAULT} ({method} needs every pixel at once: {why})"
    return replace(o, memory=str(bands), method=PS_DEFAULT if switched else o.method), [note]
