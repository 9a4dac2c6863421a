"""The relighting files' set-up after the maps: their exposure found when the ptm or rti stage
first asks, not before the task that writes the maps starts."""
from facette.pipeline._rti_bands import WholeBands, fits_from_whole, whole_bands

__all__ = ["relight_after_maps"]


def relight_after_maps(relight, res, inp, images, light_dirs, o, outputs):
    """`_rti_bands.whole_bands`, made when the ptm / rti stage first asks (`WholeBands.fitted`):
    its `exposure_of` over the whole images (1.6 CPU s at 4288x2848) then runs on that stage's
    thread, after the maps' task has started, not before it. `relight` (--memory's fits) or None
    as `whole_bands` would give them."""
    if not fits_from_whole(relight, images, outputs):
        return relight
    return WholeBands(lambda: whole_bands(None, res, inp, images, light_dirs, o, outputs).fitted())
