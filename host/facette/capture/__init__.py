"""Captures, whichever their kind: a facette scan directory (`scan`), a DiLiGenT-style folder
(`diligent`), an RTI capture of photographs with an `.lp` file or a mirror sphere (`rti`). Each
is read here once, whole (`load_input`) or a band of rows at a time (`open_bands`), into what
`process` takes: a `PSInput` with the lights, the masks (`masks`) and the notes. Between `scan`
(the scan directory's record) and `pipeline` (what is made of a capture)."""
from .base import NO_PITCH_NOTE, PSInput, given_mask, source_path
from .masks import auto_masks, margin_of, masks_from, object_of
from .base import ArrayBands
from .rti import LP_NAME
from .open import capture_size, load_input, open_bands, open_capture

__all__ = ["LP_NAME", "NO_PITCH_NOTE", "PSInput", "given_mask", "source_path", "auto_masks", "margin_of", "masks_from",
           "object_of", "load_input", "open_bands", "open_capture", "ArrayBands", "capture_size"]
