"""`process`'s load and photometric stereo over bands (`_tiled_process.streamed_ps`: the images read
band by band, never whole), and what is made over the same bands once the normals are known: the
normals' uncertainty (`_band_uncertainty`), relight.ptm / relight.rti (`_rti_bands`). The stages after
them (`_process._from_ps`) run as for the images held whole."""
from facette.capture import object_of
from facette.pipeline._band_uncertainty import banded_uncertainty
from facette.pipeline._filled import normals_of
from facette.pipeline._interreflections import interreflections_wanted
from facette.pipeline._relight_only import relight_only, relight_only_bands
from facette.pipeline._rti_bands import BANDED_OUTPUTS, relight_bands
from facette.pipeline._tiled_process import MEMORY_FLAGS_NOTE, streamed_ps

__all__ = ["banded_process"]


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
