"""`process`'s load and photometric stereo over bands (`_tiled_process.streamed_ps`: the images read
band by band, never whole), and what is made over the same bands once the normals are known: the
normals' uncertainty (`_band_uncertainty`), relight.ptm / relight.rti (`_rti_bands`). The stages after
them (`_process._from_ps`) run as for the images held whole."""
from facette.capture import capture_size, object_of
from facette.pipeline._band_uncertainty import banded_uncertainty
from facette.pipeline._budget import whole_bytes
from facette.pipeline._filled import normals_of
from facette.pipeline._interreflections import interreflections_wanted
from facette.pipeline._relight_only import relight_only, relight_only_bands
from facette.pipeline._rti_bands import BANDED_OUTPUTS, relight_bands
from facette.pipeline._whole import whole_process
from facette.pipeline._tiled_process import MEMORY_FLAGS_NOTE, SOLVE_CHANNEL_BYTES, band_rows, streamed, streamed_ps

__all__ = ["banded_process", "read_in_bands", "solved"]


def solved(source, o, res, outputs, stages, claim):
    """`process`'s load and photometric stereo, the band loop either way: (inp, images as the stages after
    photometric stereo read them and those the method saw (None over bands), light directions, the
    claim's previous record, the relighting fits made over bands or None)."""
    if read_in_bands(source, o, outputs, stages):
        inp, light_dirs, previous, relight = banded_process(source, o, res, outputs, stages, claim)
        return inp, None, None, light_dirs, previous, relight
    return (*whole_process(source, o, res, stages, claim), None)


def read_in_bands(source, o, outputs, stages=()):
    """Whether `process` reads the capture band by band (`banded_process`), else whole, as the band
    loop's one band (`_whole`): a budget (--memory, or the default's when the capture does not fit
    whole, `_budget`) that cannot hold the whole reading (`_budget.whole_bytes`, the figure the budget's
    note says), or a scheduler, on a capture's folder whose outputs need no image after photometric
    stereo (`streamed`). A capture whose whole reading fits the budget is read whole whether or not
    --memory was given: the same files either way. The bands' own model (`_tiles.rows_per_tile`, 124
    bytes per pixel-light for li_alternating against the whole reading's 66) is not asked: it made
    `--memory 12GB` read a 12 MP x 12 capture in two bands while the note said it needs ~10.1 GB whole.
    The relighting files alone always over bands (`_relight_only`: nothing needs the photographs whole)."""
    if o.memory is None or not streamed(source, outputs):
        return False
    size = capture_size(source)
    if o.scheduler is not None or size is None or relight_only(stages):
        return True
    m, h, w = size
    if whole_bytes(m, h, w) > o.memory_bytes:
        return True         # the bands refuse a budget under their floor themselves (`rows_per_tile`)
    # a budget under the process's floor (its libraries, one band) is refused read whole too: band_rows
    # raises with the size to give (--memory 500MB: "give at least 0.7 GB")
    band_rows(w, h, m, o.memory, o.method, None, 0, 0 if o.channels == "green" else SOLVE_CHANNEL_BYTES)
    return False


def banded_process(source, o, res, outputs, stages, claim):
    """(inp, light directions as the stages after photometric stereo take them, the claim's previous
    record, the relighting fits made over bands or None): fills res (ps, normals, albedo, masks,
    uncertainty, notes, timings). claim(inp): the results folder's, before any work."""
    if relight_only(stages):      # no output needs the normals: no photometric stereo (pipeline._relight_only)
        return relight_only_bands(source, o, res, outputs, claim)
    claimed, banded = {}, []

    def after_bands(inp, ps, top, read, rows):     # the reader still open: what needs the images again
        _streamed_result(res, inp, ps, top)
        if {"normals", "report"} & set(outputs):
            banded_uncertainty(res, read, len(inp.light_dirs), rows, o.saturation)
        if BANDED_OUTPUTS & set(outputs):
            banded.append(relight_bands(read, res.object_mask, outputs, o, rows, len(inp.light_dirs), inp))
    inp, ps, light_dirs, top = streamed_ps(source, o, res, lambda i: claimed.update(previous=claim(i)),
                                           samples="samples" in stages, relight=after_bands)
    interreflections_wanted(o, inp, res.notes)        # its note: why not
    if res.ps is None:
        _streamed_result(res, inp, ps, top)
    if "report" in outputs:
        res.notes.append(MEMORY_FLAGS_NOTE)
    return inp, light_dirs, claimed["previous"], (banded[0] if banded else None)


def _streamed_result(res, inp, ps, top):
    """res.ps, normals, albedo, mask and object mask of photometric stereo over bands (`streamed_ps`)."""
    res.ps = ps
    normals_of(res, inp, ps)
    res.object_mask = res.mask if inp.background_mask() is None else \
        res.mask & object_of(None, inp.mask, inp.material_mask, top=top)
