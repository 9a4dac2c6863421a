"""The relighting files' set-up after the maps: their exposure found when the ptm or rti stage
first asks, not before the task that writes the maps starts; then each of the two stages fits its
own file on its own thread (relight.ptm on the ptm stage's, relight.rti and relight_web/ on the rti
stage's), not both on the first stage's thread while the other stage waits for it (4288x2848, 12
lights: PTM and HSH ~3 CPU s each, one after the other before)."""
from facette.pipeline._rti_bands import WholeBands, fits_from_whole, whole_bands
from facette.pipeline._rti_exposure import exposure_of

__all__ = ["relight_after_maps", "StageBands", "STAGE_OUTPUTS"]

STAGE_OUTPUTS = {"ptm": ("ptm",), "rti": ("rti", "relight-web")}     # the files each stage fits


class StageBands(WholeBands):
    """A `WholeBands` per stage: fitted(name) runs `part(name)` once, when that stage first asks."""

    def __init__(self, part):         # noqa: super().__init__ not wanted: one fit per stage, not one for both
        self._parts = {name: WholeBands(lambda name=name: part(name)) for name in STAGE_OUTPUTS}

    def fitted(self, name="rti"):
        return self._parts[name].fitted()

    def write_ptm(self, path):
        return self.fitted("ptm").write_ptm(path)

    def write_rti(self, path, comments):
        return self.fitted("rti").write_rti(path, comments)

    def close(self):
        for part in self._parts.values():
            part.close()


def relight_after_maps(relight, res, inp, images, light_dirs, o, outputs):
    """`_rti_bands.whole_bands` per stage (`StageBands`), made when the ptm / rti stage first asks:
    the exposure (`exposure_of` over the whole images, 1.6 CPU s at 4288x2848) once, on the thread of
    the first stage that asks, after the maps' task has started; then that stage's files' fits with
    it. `relight` (--memory's fits) or None as `whole_bands` would give them."""
    if not fits_from_whole(relight, images, outputs):
        return relight
    exposure = WholeBands(lambda: exposure_of(inp, o.rti_encoding, res.light_gains, images, res.object_mask))

    def part(name):
        wanted = [x for x in outputs if x in STAGE_OUTPUTS[name]]
        return whole_bands(None, res, inp, images, light_dirs, o, wanted, exposure.fitted()).fitted()
    return StageBands(part)
