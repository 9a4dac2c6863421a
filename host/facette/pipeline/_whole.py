"""`process`'s load and photometric stereo on a capture read whole (a source that is not a capture's
folder, or one that fits the memory budget, `pipeline._budget`): the band loop of `--memory`
(`_tiled_process.band_loop`: the lights' gains, the cast shadows, li_alternating's model, the solve),
its one band the whole image, read from the photographs held in memory (`HeldBands`). What needs the
whole image runs because the band is the whole image: the removal of inter-reflections
(`_interreflections`); when it takes light out (or a method needs every pixel at once) the solve runs
on the whole stack it read (`_one_band`). The images stay for the stages after photometric stereo that
read them (the relighting model, PTM/HSH, the report's photograph)."""
import time

import numpy as np

from facette.capture import ArrayBands, load_input, object_of
from facette.methods import PS_METHODS, photometric_stereo
from facette.pipeline._channels import results_in_rgb
from facette.pipeline._filled import normals_of
from facette.pipeline._interreflections import interreflections_wanted, solve_without_interreflections
from facette.pipeline._light_gains import divided, light_gains_of_bands
from facette.pipeline._quality import carried, check_samples, light_geometry
from facette.pipeline._shadows import with_shadows, without_hidden
from facette.pipeline._tiled_process import (band_loop, one_band_note, read_whole_notes, solve_channel, solve_inputs,
                                             solve_options, solve_reader, solve_setup)
from facette.pipeline._tiles import BANDED_METHODS
from facette.recon import dark_level_notes, near_light_directions

__all__ = ["whole_process", "HeldBands"]


class HeldBands(ArrayBands):
    """The photographs of a capture read whole, as the band loop's reader of its one band, prepared
    once as the solve sees it (`prepare`: the near lights' fall-off divided out, the solve's channel
    appended) and served to every pass without a copy (`solve_read`): the gains' pass before the
    division, the passes after it (the inter-reflection decision, the cast shadows, li_alternating's
    model) and the solve (`_tiled_process._ps_task`) once the band is divided by the gains, in place,
    once. The photographs themselves are that band's images when no fall-off is divided out (divided
    in place, as the whole reading always did): no copy of the stack, one solve's stack."""
    prepared = None

    def prepare(self, inp, near, bag, weights, method_name, arrived=None):
        """Make the one band as the solve sees it (`_tiled_process.solve_inputs`) from the photographs; the
        solve's stack the one-button scan made as its lights arrived (`arrived`: pipeline._arriving) when it
        is that of these photographs, weights and saturation (far lights: nothing else to divide)."""
        h = self.images.shape[1]
        solve = None if arrived is None or near is not None else \
            arrived.solve_stack(self.images, weights, bag.get("saturation"))
        self.prepared = solve_inputs(self.images, self.usable, 0, h, inp.mask, near, bag, weights) if solve is None \
            else (self.images, solve, bag.get("light_dirs"), carried(inp.mask, self.usable), solve_options(bag, weights))
        self.mask, self.method_name, self.gains = inp.mask, method_name, None

    def _divided(self, gains):
        """The prepared band, divided by `gains` in place on the first read that gives them (None: as prepared)."""
        if gains is not None and self.gains is None:
            images, solve = divided(*self.prepared[:2], gains)
            self.prepared, self.gains = (images, solve, *self.prepared[2:]), gains
        if (gains is None) != (self.gains is None):
            raise RuntimeError("the one band was read without the gains after it was divided by them")
        return self.prepared

    def solve_read(self, r0, r1, gains=None, hidden=None):
        """`_tiled_process.solve_reader`'s read of rows r0..r1 of the prepared band: views, no copy (the
        passes only read them; the hidden values are taken out of a copy, kept for the solve when the read
        is the whole band: `without_hidden`)."""
        images, solve, dirs, solved, _ = self._divided(gains)
        dirs = dirs if np.ndim(dirs) == 2 else dirs[r0:r1]
        if hidden is not None and (r0, r1) == (0, self.images.shape[1]):
            solve = self.without_hidden(solve, hidden, self.mask, 0, self.method_name, keep=True)[0]
        else:
            solve = without_hidden(solve[:, r0:r1], hidden, self.mask[r0:r1], r0, self.method_name)[0]
        return images[:, r0:r1], solve, dirs, solved[r0:r1]

    def without_hidden(self, solve, found, mask, r0, method_name, keep=False):
        """`_shadows.without_hidden` of the whole prepared band: li_alternating's model reads it (keep: kept)
        and the solve then takes that copy (the same values: 12 lights of 3 MP x 4 channels are one
        590 MB copy and a pass on every core less after the last frame)."""
        kept = self.__dict__.pop("_without", None)
        if found is None:
            return solve, None
        if kept is not None and kept[0] is solve and kept[1][0] is found[0] and kept[1][1] == found[1]:
            out = kept[2]
        else:
            out = without_hidden(solve, found, mask, r0, method_name)
        if keep:
            self._without = (solve, found, out)
        return out

    def solve_inputs(self, r0, r1, gains):
        """The solve's band (`_tiled_process._ps_task`): (images, the solve's stack, light directions, the
        mask it solves) of the prepared band, divided by `gains`."""
        if (r0, r1) != (0, self.images.shape[1]):
            raise ValueError(f"the one band is rows 0..{self.images.shape[1]}, not {r0}..{r1}")
        return self._divided(gains)[:4]

    def spec(self):
        return self         # read here only (no scheduler: the photographs are in this process's memory)


def whole_process(source, o, res, stages, claim):
    """(inp, images as the stages after photometric stereo read them, the images the method saw,
    light directions, the claim's previous record): fills res (inputs, ps, normals, albedo, masks,
    quality, notes, timings). claim(inp): the results folder's, before any work. Without "ps" in
    `stages` (the relighting files alone) only the images and the object's mask."""
    t0 = time.perf_counter()
    res.notes.extend(read_whole_notes(o, source))     # --memory, a source that is not a capture's folder
    inp = load_input(source, mask=o.mask, pixel_pitch_mm=o.pixel_pitch_mm, allow_incomplete=o.allow_incomplete,
                     capture=o.capture)
    previous = claim(inp)
    res.inputs = inp
    res.notes.extend(inp.notes)
    if inp.usable is not None:       # the data must be able to carry normals (else exit 3)
        notes, res.quality = check_samples(inp.images, inp.usable, inp.object_mask, inp.mask_source)
        res.notes.extend(notes + light_geometry(inp.light_dirs, res.quality))
    res.timings["load"] = time.perf_counter() - t0
    m, h, w, _ = inp.images.shape
    res.notes.extend(one_band_note(o, h))          # --memory whose one band holds the capture
    t0 = time.perf_counter()
    light_dirs, falloff = inp.light_dirs, None
    if o.near_light and inp.positions_mm is not None:
        light_dirs, falloff = near_light_directions(inp.positions_mm, (h, w), inp.pixel_pitch_mm)
        res.notes.append("near lights: per-pixel directions and 1/r^2 fall-off from the light positions")
    if "ps" not in stages:       # the relighting files alone: the images and the object's mask
        images = inp.images if falloff is None else inp.images / np.transpose(falloff, (2, 0, 1))[..., None]
        res.mask, res.object_mask = inp.mask, inp.mask if inp.background_mask() is None else \
            inp.mask & object_of(inp.images, inp.mask, inp.material_mask)
        return inp, images, images, light_dirs, previous
    # "weighted" channels: their noise measured on the images the solve sees (the fall-off divided out)
    ps, images, direct = _one_band(res, o, inp, PS_METHODS.canonical(o.method), None if o.channels != "weighted" else
                                   inp.images if falloff is None else
                                   inp.images / np.transpose(falloff, (2, 0, 1))[..., None],
                                   getattr(source, "prepared", None))
    del falloff
    res.ps = ps
    res.notes.extend(dark_level_notes(ps.info.get("dark_offset")))
    normals_of(res, inp, ps)
    # mask.png: the object, without the dark table or cloth around it (when one surrounds it)
    res.object_mask = res.mask if inp.background_mask() is None else \
        res.mask & object_of(inp.images, inp.mask, inp.material_mask)
    res.timings["ps"] = time.perf_counter() - t0
    return inp, images, direct, light_dirs, previous


def _one_band(res, o, inp, method_name, noisy=None, arrived=None):
    """(PSResult, images as the stages after photometric stereo read them, the images the method saw)
    of the band loop on the whole image as its one band. The inter-reflections' step (whole images
    only) between the gains and the cast shadows, as over the whole stack; when it changed the images
    or the solve's start, or the method is not per-pixel, the solve on the whole stack it read.
    noisy: the images "weighted" channels measure their noise on (None: another choice). arrived: what the
    one-button scan made as its lights arrived (pipeline._arriving) or None."""
    h = inp.mask.shape[0]
    bands = HeldBands(inp.images, inp.usable)
    weights, used = solve_channel(o, res.notes, noisy, inp.mask)
    del noisy
    near, bag, model_bag = solve_setup(o, inp, weights)
    bands.prepare(inp, near, bag, weights, method_name, arrived)
    read = solve_reader(bands, inp, near, bag, weights, method_name)      # bands.solve_read: no copy
    gains = light_gains_of_bands(res, o, inp, method_name, lambda r0, r1: read(r0, r1)[1:3], h, model_bag)
    banded, removal = method_name in BANDED_METHODS, interreflections_wanted(o, inp, res.notes, whole=True)
    if not banded or removal:
        images, solve, dirs, solved = read(0, h, gains)
        bag = dict(model_bag, mask=solved)
        direct, ps = solve_without_interreflections(res, o, solve, dirs, inp, method_name, bag) \
            if removal else (solve, None)
        if not banded or ps is not None or direct is not solve or "start_model" in bag:
            ps = with_shadows(res, o, direct, dirs, inp.mask, method_name, bag, ps)    # cast shadows, alternated
            if ps is None:
                ps = photometric_stereo(direct, dirs, method=o.method, options=bag)
            ps, direct = results_in_rgb(ps, direct, solve, images, used)
            return ps, images, direct
        del images, solve, direct
    one = {"gains": gains}
    ps = band_loop(res, o, inp, bands, h, weights, used, one=one)[0]
    if "images" not in one:        # nothing solved (an empty mask): the images as the solve would have seen them
        one["images"] = read(0, h, gains)[0]
    return ps, one["images"], one["images"]
