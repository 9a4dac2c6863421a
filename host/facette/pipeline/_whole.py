"""`process`'s load and photometric stereo on the images held whole: a source that is not a capture's
folder, or one that fits the memory budget (`pipeline._budget`). The steps are those of the band loop
(`pipeline._streamed`, `_tiled_process.streamed_ps`), in the same order and with the same values:
the lights' gains, the cast shadows (`_shadows`), the solve; and one that needs the images whole,
the removal of inter-reflections (`_interreflections`). The images stay for the stages after
photometric stereo that read them (the relighting model, PTM/HSH, the report's photograph)."""
import time

import numpy as np

from facette.capture import load_input, object_of
from facette.methods import PS_METHODS, photometric_stereo
from facette.pipeline._channels import images_for_solve, results_in_rgb
from facette.pipeline._filled import normals_of
from facette.pipeline._interreflections import interreflections_wanted, solve_without_interreflections
from facette.pipeline._light_gains import with_light_gains
from facette.pipeline._quality import carried, check_samples, light_geometry
from facette.pipeline._shadows import with_shadows
from facette.pipeline._tiled_process import read_whole_notes
from facette.recon import dark_level_notes, near_light_directions

__all__ = ["whole_process"]


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
    m, h, w, c = inp.images.shape
    t0 = time.perf_counter()
    light_dirs, images = inp.light_dirs, inp.images
    if o.near_light and inp.positions_mm is not None:
        light_dirs, falloff = near_light_directions(inp.positions_mm, (h, w), inp.pixel_pitch_mm)
        images = images / np.transpose(falloff, (2, 0, 1))[..., None]
        res.notes.append("near lights: per-pixel directions and 1/r^2 fall-off from the light positions")
    if "ps" not in stages:       # the relighting files alone: the images and the object's mask
        res.mask, res.object_mask = inp.mask, inp.mask if inp.background_mask() is None else \
            inp.mask & object_of(inp.images, inp.mask, inp.material_mask)
        return inp, images, images, light_dirs, previous
    # one bag of options for whichever method: each takes its own (facette.methods)
    bag = o.ps_bag(mask=carried(inp.mask, inp.usable), saturation=o.saturation)
    method_name = PS_METHODS.canonical(o.method)
    solve_in, used = images_for_solve(images, inp.mask, o, bag, res.notes)     # the channels the normals see
    solve_in, images = with_light_gains(res, o, inp, method_name, solve_in, images, bag)
    direct, ps = solve_without_interreflections(res, o, solve_in, light_dirs, inp, method_name, bag) \
        if interreflections_wanted(o, inp, res.notes) else (solve_in, None)
    ps = with_shadows(res, o, direct, light_dirs, inp.mask, method_name, bag, ps)    # cast shadows, alternated
    if ps is None:
        ps = photometric_stereo(direct, light_dirs, method=o.method, options=bag)
    ps, direct = results_in_rgb(ps, direct, solve_in, images, used)
    res.ps = ps
    res.notes.extend(dark_level_notes(ps.info.get("dark_offset")))
    normals_of(res, inp, ps)
    # mask.png: the object, without the dark table or cloth around it (when one surrounds it)
    res.object_mask = res.mask if inp.background_mask() is None else \
        res.mask & object_of(inp.images, inp.mask, inp.material_mask)
    res.timings["ps"] = time.perf_counter() - t0
    return inp, images, direct, light_dirs, previous


