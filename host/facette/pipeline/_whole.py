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
from facette.pipeline._light_gains import gained, light_gains_of_bands
from facette.pipeline._quality import check_samples, light_geometry
from facette.pipeline._rti_bands import band_reader
from facette.pipeline._shadows import with_shadows
from facette.pipeline._tiled_process import (band_loop, one_band_note, read_whole_notes, solve_channel,
                                             solve_reader, solve_setup)
from facette.pipeline._tiles import BANDED_METHODS
from facette.recon import dark_level_notes, near_light_directions

__all__ = ["whole_process", "HeldBands"]


class HeldBands(ArrayBands):
    """The photographs of a capture read whole, as the band loop's reader of its one band: read()
    gives a copy (the loop's passes divide their band by the gains in place), except once `last` is
    set: then the photographs themselves (the solve's read, which divides them in place as the whole
    reading always did: no second copy of the stack)."""
    last = False

    def read(self, r0, r1, flat=None):
        images = self.images[:, r0:r1]
        usable = None if self.usable is None else self.usable[:, r0:r1]
        if self.last:
            self.last = False
            return images, usable
        return images.copy(), usable

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
                                   inp.images / np.transpose(falloff, (2, 0, 1))[..., None])
    del falloff
    res.ps = ps
    res.notes.extend(dark_level_notes(ps.info.get("dark_offset")))
    normals_of(res, inp, ps)
    # mask.png: the object, without the dark table or cloth around it (when one surrounds it)
    res.object_mask = res.mask if inp.background_mask() is None else \
        res.mask & object_of(inp.images, inp.mask, inp.material_mask)
    res.timings["ps"] = time.perf_counter() - t0
    return inp, images, direct, light_dirs, previous


def _one_band(res, o, inp, method_name, noisy=None):
    """(PSResult, images as the stages after photometric stereo read them, the images the method saw)
    of the band loop on the whole image as its one band. The inter-reflections' step (whole images
    only) between the gains and the cast shadows, as over the whole stack; when it changed the images
    or the solve's start, or the method is not per-pixel, the solve on the whole stack it read.
    noisy: the images "weighted" channels measure their noise on (None: another choice)."""
    h = inp.mask.shape[0]
    bands = HeldBands(inp.images, inp.usable)
    weights, used = solve_channel(o, res.notes, noisy, inp.mask)
    del noisy
    near, bag, model_bag = solve_setup(o, inp, weights)
    read = solve_reader(bands, inp, near, bag, weights, method_name)
    gains = light_gains_of_bands(res, o, inp, method_name, lambda r0, r1: read(r0, r1)[1:3], h, model_bag)
    banded, removal = method_name in BANDED_METHODS, interreflections_wanted(o, inp, res.notes, whole=True)
    if not banded or removal:
        _, solve, dirs, solved = read(0, h, gains)
        bag = dict(model_bag, mask=solved)
        direct, ps = solve_without_interreflections(res, o, solve, dirs, inp, method_name, bag) \
            if removal else (solve, None)
        if not banded or ps is not None or direct is not solve or "start_model" in bag:
            bands.last = True      # the images the solve saw, the photographs themselves divided in place
            images = gained(band_reader(bands, near, dirs), gains)(0, h)[0]
            ps = with_shadows(res, o, direct, dirs, inp.mask, method_name, bag, ps)    # cast shadows, alternated
            if ps is None:
                ps = photometric_stereo(direct, dirs, method=o.method, options=bag)
            ps, direct = results_in_rgb(ps, direct, solve, images, used)
            return ps, images, direct
        del _, solve, direct
    one = {"gains": gains}
    ps = band_loop(res, o, inp, bands, h, weights, used, one=one)[0]
    if "images" not in one:        # nothing solved (an empty mask): the images as the solve would have seen them
        bands.last = True
        one["images"] = gained(band_reader(bands, near, inp.light_dirs), gains)(0, h)[0]
    return ps, one["images"], one["images"]
