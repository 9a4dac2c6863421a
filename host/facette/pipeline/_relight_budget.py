"""The memory budget of a run that asks for relighting: `relighting_budget`, before the default budget
(`_budget.with_default_budget`).

- The relighting files alone (relight.ptm, relight.rti, relight_web/): over bands without photometric
  stereo (`_relight_only.relight_only_budget`).
- The relighting model (output "relight", relight_model.npz; alone or with other outputs): a capture's
  folder whose whole reading would hold more than MODEL_WHOLE_BYTES is read band by band in at most
  MODEL_BANDS_BYTES, whatever the free memory. Read whole, the model's run holds photometric stereo's
  temporaries over every photograph (WHOLE_BYTES_PER_PIXEL_LIGHT a pixel and light) and then the
  photographs and the model's maps beside each other: 12 MP x 12 lights, woodham1980, 6.5 GB peak
  (10-12 GB with li_alternating), where over bands the same run holds ~2 GB and spends less CPU
  (`facette bench relight --large` measures it; docs/howto/large-captures.md). Over bands the model
  is fitted from the photographs' spill with its maps on disk (`_relight_model_stage`): its normals,
  heights and planes are the band path's.
"""
from dataclasses import replace

from facette.capture import capture_size
from facette.methods import PS_METHODS
from facette.pipeline._budget import default_budget, whole_bytes
from facette.pipeline._relight_only import relight_only_budget
from facette.pipeline._tiled_process import streamed
from facette.pipeline._tiles import BANDED_METHODS

__all__ = ["relighting_budget", "model_budget", "MODEL_WHOLE_BYTES", "MODEL_BANDS_BYTES"]

# the bound for a 12 MP capture's relighting model: a whole reading estimated above it goes over
# bands, and the bands take at most this (12 MP x 12 lights over bands in 3 GB: 2.1 GB peak)
MODEL_WHOLE_BYTES = 3 * 10 ** 9
MODEL_BANDS_BYTES = 3 * 10 ** 9


def relighting_budget(source, o, stages, outputs, free=None):
    """(options, notes) for a run that asks for relighting outputs (`relight_only_budget`, else
    `model_budget`); None when neither applies (the default budget decides)."""
    return relight_only_budget(source, o, stages, free) or model_budget(source, o, outputs, free)


def model_budget(source, o, outputs, free=None):
    """(options with the bands' --memory, [the note]) when "relight" is asked for on a capture's folder
    whose whole reading (`_budget.whole_bytes`: 66 B a pixel and light, and the process's own) exceeds
    MODEL_WHOLE_BYTES: the bands take min(MODEL_BANDS_BYTES, the default budget). None otherwise:
    --memory given, outputs the bands do not serve, a method that needs every pixel at once, the
    inter-reflections' removal asked for, a capture that fits, a size the headers do not say.
    free: the free memory (bytes; None: the machine's)."""
    if "relight" not in outputs or o.memory is not None or o.interreflections is True \
            or not streamed(source, outputs) or PS_METHODS.canonical(o.method) not in BANDED_METHODS:
        return None
    size = capture_size(source)
    if size is None:
        return None
    m, h, w = size
    need = whole_bytes(m, h, w)
    if need <= MODEL_WHOLE_BYTES:
        return None
    budget = default_budget(free)
    bands = min(MODEL_BANDS_BYTES, budget or MODEL_BANDS_BYTES)
    note = (f"memory: the relighting model of {m} photographs of {w}x{h} px would hold ~{need / 1e9:.1f} GB read "
            f"whole: read band by band in {bands / 1e9:.1f} GB (its maps on disk)"
            + ("" if budget is None else f" (a budget of {budget / 1e9:.1f} GB from the free memory; --memory to "
                                         "set it)"))
    return replace(o, memory=str(bands)), [note]
