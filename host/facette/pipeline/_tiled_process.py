"""`process(..., memory="2GB")` (`facette process --memory 2GB`): photometric stereo over row bands.

A per-pixel method (`_tiles.TILED_METHODS`) gives each pixel's normal from that pixel's values
alone, so the bands solved one after the other give the untiled normals. li_alternating (the
default) too: its material model is fitted first, on a sample drawn across the bands (`band_model`,
`fit.li_model`: one pass over them, the coarse pass on the image binned, the dark level, the model
choice), and each band solved with it fixed (shipped to the workers once with a scheduler); the
image read whole runs the same steps as one band. Before the model, the cast-shadow step's pass
(`_shadows.hidden_over_bands`: each band binned on the whole image's bins, the alternation on
them) finds the lights the surface hides; each band's solve leaves its rows of them out, as the
run on the images held whole does.

- streamed (every output in STREAMED_OUTPUTS, which is all of them; any capture,
  `capture.open_capture`): the photographs are never held whole. A scan's
  HDR images are read a window of scanlines at a time (OpenEXR's scanline reader), twice: once
  for the masks' two maps (the brightest value and the median over the lights, what
  `auto_masks` splits), once for photometric stereo; a DiLiGenT folder's PNGs are staged once
  to raw files (`_tiles._Staged`: PNG decodes whole images only) and read band by band. The
  quality counts (`check_samples`) add up over the bands and are judged after the bands (the
  same verdict, later). The normals are solved on the channel the untiled run uses by default,
  the mean of R, G, B appended to each band (`_channels.with_solve_channel`; "weighted" needs
  the whole images' noise: green, said): the same normals and heights as untiled (rank_trimmed:
  the same bytes on a DiLiGenT crop, a scan and an RTI capture). The reflectance samples (samples, brdf, gltf) are taken in each band
  right after its photometric stereo (with its shadows), the bands' hemisphere sensors merged
  (the same cells as untiled; the raw subset kept beside them is drawn band by band).
  relight.ptm and relight.rti are fitted over the bands once photometric stereo is done, with
  the same reader (`_rti_bands`: one pass for their white, one for the fits, the files written
  from a scratch spill; the bytes of the untiled files).
  What is kept at the image's size: in memory the masks, the valid and skipped flags (2 bytes
  per pixel) and, for a scan, the brightest value (4 bytes/pixel); in temporary files
  (`_memory.disk_array`, ON_DISK) the normal, albedo, residual and triplet maps (30 bytes/pixel),
  written as the bands come and read a band at a time by the EXR writers, the heights (whose
  divergence is built band by band, `recon._integrate`), the glTF's textures (block means at
  most 8192 texels wide) and the report.
- a source that is not a capture's folder (a Scan object, arrays) is read whole by `process`, as
  without --memory (a note says the budget bounds nothing there; the former third way, photometric
  stereo over bands of images held whole, bounded nothing but the solve and is retired).

The band height is `_tiles.rows_per_tile` of the budget (tests force a few rows). The streamed
bands run here one after the other, or, with `scheduler` (`--scheduler tcp://host:8786`), as
tasks on a dask.distributed cluster (`_maps_task`, `_ps_task`: each opens the files itself, so
its workers must see the scan's path; a DiLiGenT folder's staged files are in a local temporary
folder: workers on this machine only); at most twice the cluster's threads in flight, so that
finished bands do not pile up; a band whose worker dies is run again by the scheduler.
12 MP (`facette bench size --scan --dask`): see README ("Large captures").
"""
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from facette._memory import disk_array, hand_back, release
from facette.fit import li_model
from facette.methods import PS_METHODS, options_for, photometric_stereo
from facette.capture import open_bands, open_capture, source_path
from facette.pipeline._band_threads import InFlight, in_order_on_threads
from facette.pipeline._channels import SOLVE_CHANNEL, channel_weights, with_solve_channel
from facette.pipeline._light_gains import divided, gained, light_gains_of_bands
from facette.pipeline._quality import add_counts, carried, check_counts, light_geometry, sample_counts
from facette.pipeline._rti_bands import band_reader
from facette.pipeline._samples import samples_sensor
from facette.pipeline._scheduler import connect_scheduler
from facette.pipeline._shadows import flag_hidden, hidden_over_bands, without_hidden
from facette.pipeline._tiles import (BANDED_METHODS, FIELD_BYTES, PROCESS_BYTES, SOLVE_CHANNEL_BYTES, WHOLE_IMAGE_METHODS,
                                    rows_per_tile)
from facette.recon import PSResult, near_light_directions

__all__ = ["STREAMED_OUTPUTS", "check_memory_options", "streamed", "streamed_ps", "read_whole_notes", "band_loop",
           "band_rows", "solve_channel", "solve_inputs", "solve_reader", "solve_setup", "one_band_note"]

STREAMED_OUTPUTS = ("normals", "albedo", "mask", "height", "mesh", "samples", "brdf", "ptm", "rti", "gltf", "report")
MEMORY_FLAGS_NOTE = ("--memory: the report shows no mask over the photograph (the photographs are not held) "
                     "and, the per-light shadow and specular flags not being kept (m bytes per pixel each), "
                     "leaves their share out and draws their maps empty")


# the PS outputs a streamed run keeps on disk (`_memory.disk_array`): 30 of their 32 bytes per
# pixel, 3 GB at 100 MP; written band by band, read band by band by the writers and the heights
ON_DISK = ("normal", "albedo", "n_triplets", "residual")


def check_memory_options(method, interreflections):
    """ValueError unless `method` can run over bands and nothing asks for the whole images first."""
    name = PS_METHODS.canonical(method)
    if name not in BANDED_METHODS:
        why = WHOLE_IMAGE_METHODS.get(name, "it is not known to be per-pixel")
        raise ValueError(f"--memory runs photometric stereo over bands of rows, which {name} cannot: {why}; "
                         f"choose one of {', '.join(BANDED_METHODS)}, or leave --memory out")
    if interreflections:
        raise ValueError("--interreflections needs the whole images at once (the light a surface gathers "
                         "from itself comes from everywhere): leave --memory out to remove them")


def streamed(source, outputs):
    """True when `process` can run without the whole images: every output in STREAMED_OUTPUTS
    and a capture's folder (whichever its kind: `capture.open_capture` reads it band by band)."""
    # _rti_bands' spills: the web planes (the HSH fit's), the relighting model's photographs
    if not set(outputs) <= set(STREAMED_OUTPUTS) | {"relight-web", "relight"}:
        return False
    try:
        path = source_path(source)
    except TypeError:
        return False
    return path.is_dir()


def band_rows(w, h, m, memory, method, rows, maps_bytes, extra=0):
    """A band's rows: `rows` when given, else what the budget `memory` leaves them (`rows_per_tile`)."""
    if rows is not None:
        if int(rows) < 1:
            raise ValueError(f"rows must be >= 1, got {rows}")
        return int(rows)
    # the budget is the whole process's: the bands get what the libraries and the maps this run
    # holds at the image's size (maps_bytes per pixel) leave; the ON_DISK maps are not held
    return rows_per_tile(w, h, m, memory, method, tuple(k for k in FIELD_BYTES if k not in ON_DISK),
                         held=PROCESS_BYTES + maps_bytes * w * h, extra_per_pixel_light=extra)


def solve_inputs(images, usable, r0, r1, mask, near, bag, weights):
    """A band as photometric stereo sees it: (images with the near lights' fall-off divided out,
    those with the solve's channel appended, light directions, the mask it solves, the options)."""
    dirs = bag.get("light_dirs")          # far lights: (m, 3)
    if near is not None:
        positions, shape, pitch = near
        dirs, falloff = near_light_directions(positions, shape, pitch, rows=(r0, r1))
        images = images / np.transpose(falloff, (2, 0, 1))[..., None]
    solve = images if weights is None else with_solve_channel(images, weights, bag.get("saturation"))
    return images, solve, dirs, carried(mask, usable), solve_options(bag, weights)


def solve_options(bag, weights):
    """The solve's options of a band: `bag` without the far lights' directions, its channel the one appended."""
    bag = {k: v for k, v in bag.items() if k != "light_dirs"}
    return bag if weights is None else dict(bag, channel=SOLVE_CHANNEL)


def band_model(method, read, shape, n_valid, rows, bag):
    """The model the bands of li_alternating share (`fit.li_model`: fitted on a sample drawn across
    the bands, read(r0, r1) -> (images, light_dirs, mask) as the solve sees them), or None: a
    per-pixel method, or an image li_alternating solves whole (`rows_for_model`)."""
    if PS_METHODS.canonical(method) != "li_alternating":
        return None
    return li_model(read, shape, n_valid, rows, **options_for("li_alternating", bag))


def rows_for_model(method, model, h, rows):
    """The band height: `rows`, or every row when li_alternating has no model for the bands (at
    most COARSE_PIXELS valid pixels: its alternation needs them all at once)."""
    return h if model is None and PS_METHODS.canonical(method) == "li_alternating" else rows


def _ps_task(spec, r0, r1, flat, near, method, bag, mask, count_in, samples=None, weights=None, model=None,
             gains=None, hidden_bins=None, hidden_bin=1, one=None):
    """A band's photometric stereo: (r0, r1, PSResult without per-light flags or None when the
    mask leaves the band out, its quality counts or None, read seconds, PS seconds, its
    reflectance samples or None). samples: {sample_mask: the band's, theta0_deg, total} to take
    the band's samples (`_samples.samples_sensor`: (HemisphereSensor, raw samples)) with the
    shadows it found. weights: (3,) the solve's channel as a sum of R, G, B appended to the band
    (`_channels.with_solve_channel`, as the whole reading's `images_for_solve`), None: green.
    model: li_alternating's, fitted over the bands (`band_model`). gains: (m,) the lights' gains the
    images are divided by (`_light_gains.light_gains_of_bands`) or None. hidden_bins, hidden_bin: the
    cast-shadow step's hidden lights of its bins and their bin (`_shadows.hidden_over_bands`) or None:
    left out of the band's solve, added to its shadow flags (the band's samples leave them out). one:
    `band_loop`'s (a capture held whole, one band: its flags kept, its images in one["images"])."""
    t0 = time.perf_counter()
    held = getattr(spec, "prepared", None) is not None
    if held:      # the one band held whole (`_whole.HeldBands`): counted
        counts = None
        if not mask.any():
            return r0, r1, None, counts, 0.0, 0.0, None
        images, solve, dirs, solved = spec.solve_inputs(r0, r1, gains)
        bag = solve_options(bag, weights)
    else:
        reader = open_bands(spec) if isinstance(spec, tuple) else spec     # a reader of this process's
        try:
            images, usable = reader.read(r0, r1, flat)
        finally:
            reader.close()
        counts = None if count_in is None else sample_counts(images, usable, count_in)
        if not mask.any():
            return r0, r1, None, counts, time.perf_counter() - t0, 0.0, None
        images, solve, dirs, solved, bag = solve_inputs(images, usable, r0, r1, mask, near, bag, weights)
        images, solve = divided(images, solve, gains)
    read_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    if model is not None:
        bag.update(model=model, row0=r0)
    found = None if hidden_bins is None else (hidden_bins, hidden_bin)
    # held whole, the copy without the hidden values that li_alternating's model read is taken again
    if held:
        solve, hidden = spec.without_hidden(solve, found, mask, r0, PS_METHODS.canonical(method))
    else:              # the solve's stack is its own when a channel was appended: its values taken out in place
        solve, hidden = without_hidden(solve, found, mask, r0, PS_METHODS.canonical(method), solve is not images)
    part = flag_hidden(photometric_stereo(solve, dirs, method=method, options=dict(bag, mask=solved)), hidden)
    del solve, hidden
    if weights is not None:                    # the albedo's R, G, B only (`_channels.results_in_rgb`)
        part = replace(part, albedo=np.ascontiguousarray(part.albedo[..., :3]))
    taken = None
    if samples is not None:
        taken = samples_sensor(images, samples["sample_mask"], part, dirs, samples["theta0_deg"], seed=r0,
                               total=samples["total"], first_pixel=r0 * images.shape[2])
    if one is not None:                        # held whole: what the stages after the solve read
        one["images"] = images
        return r0, r1, part, counts, read_s, time.perf_counter() - t0, taken
    part.shadow = part.specular = None         # m bytes per pixel each: not sent back
    return r0, r1, part, counts, read_s, time.perf_counter() - t0, taken


def _map(fn, calls, client=None, in_flight=None, threads=1):
    """fn(*args) for each args of `calls`: here one after the other (none in flight beside the
    one running; `threads` > 1: that many at once, in order, `_band_threads`), or as tasks on a dask.distributed
    `client`, at most `in_flight` at a time (default twice its threads) so that finished bands do not pile up;
    results as they finish. A task whose worker dies is run again by the scheduler elsewhere."""
    if client is None and threads > 1:
        yield from in_order_on_threads(fn, calls, threads)
        return
    if client is None:
        for args in calls:
            yield fn(*args)
        return
    from dask.distributed import as_completed
    calls = iter(calls)
    if in_flight is None:
        in_flight = 2 * max(1, sum(client.nthreads().values()))
    running = as_completed()
    for args in calls:
        running.add(client.submit(fn, *args, pure=False))
        if running.count() >= in_flight:
            break
    for fut in running:
        yield fut.result()
        del fut
        for args in calls:
            running.add(client.submit(fn, *args, pure=False))
            break


def _assemble(shape, method, results, on_disk=False):
    """The bands' results (`_ps_task`'s tuples) into one PSResult at the image's size, and the
    quality counts summed. info: the first band's, its fractions (keys ending in _fraction)
    weighted by the bands' pixels, and pixels, tiles, read_s, ps_s. on_disk: the ON_DISK maps
    in temporary files, their pages handed back after each band."""
    h, w = shape

    def field(name, tail, dtype):
        return disk_array((h, w) + tail, dtype) if on_disk and name in ON_DISK else np.zeros((h, w) + tail, dtype)
    res = PSResult(normal=field("normal", (3,), np.float32), albedo=field("albedo", (3,), np.float32),
                   valid=np.zeros((h, w), bool), n_triplets=field("n_triplets", (), np.int16),
                   shadow=np.zeros((h, w, 0), bool), specular=np.zeros((h, w, 0), bool),
                   residual=field("residual", (), np.float32), skipped=np.zeros((h, w), bool),
                   method=PS_METHODS.canonical(method))
    info, pixels, counts, read_s, ps_s, weighted = {}, 0, None, 0.0, 0.0, {}
    sensor, raws = None, []
    for r0, r1, part, band_counts, band_read, band_ps, taken in results:
        read_s, ps_s = read_s + band_read, ps_s + band_ps
        if taken is not None:
            if sensor is None:
                sensor = taken[0]
            else:
                sensor.merge(taken[0])
            raws.append(taken[1])
        if band_counts is not None:
            counts = add_counts(counts, band_counts)
        if part is None:
            continue
        for name in ("normal", "albedo", "valid", "n_triplets", "residual", "skipped"):
            getattr(res, name)[r0:r1] = getattr(part, name)
            release(getattr(res, name))
        if part.shadow is not None and (r0, r1) == (0, h):      # one band: its per-light flags kept
            res.shadow, res.specular = part.shadow, part.specular
        n = int(part.info.get("pixels", part.valid.sum()))
        pixels += n
        info = info or dict(part.info)
        for key, value in part.info.items():
            if key.endswith("_fraction") and isinstance(value, (int, float)):
                weighted[key] = weighted.get(key, 0.0) + float(value) * n
    info.update({key: total / max(pixels, 1) for key, total in weighted.items()})
    res.info = dict(info, method=res.method, pixels=pixels, read_s=read_s, ps_s=ps_s)
    if sensor is not None:
        res.info["samples"] = (sensor, raws)
    return res, counts


def _bands(h, rows):
    return [(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]


def streamed_ps(source, o, res, on_input=None, rows=None, samples=False, relight=None):
    """The load and photometric-stereo stages of `process` without the whole images: (PSInput
    with images=None, PSResult, light_dirs as `process` uses them (m, 3) or None with near
    lights, the brightest value over the lights or None). on_input(inp) is called once the
    input is known, before photometric stereo. The bands run here one after the other, or as
    tasks on the dask.distributed scheduler `o.scheduler` (its workers read the scan from its
    path: they must see it). samples: take the reflectance samples band by band too (into
    res.filtered and res.samples; the raw subset's share drawn against m x the sample mask's
    pixels, which the untiled run counts after photometric stereo, on its valid pixels only).
    Fills res.inputs, res.timings load / ps, res.quality and the notes (InsufficientData as
    untiled). relight(inp, ps, top, read, rows): called once photometric stereo is done, before
    the band reader closes, with read(r0, r1) -> (images, light directions) of a band
    (`_rti_bands.band_reader`) and the bands' rows (the PTM / HSH fits, `_rti_bands.relight_bands`);
    its time is not photometric stereo's."""
    t0 = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix="facette-tiles-"))
    client = None
    weights, used = solve_channel(o, res.notes)
    try:
        if o.scheduler is not None:
            client = connect_scheduler(o.scheduler)      # bad input within seconds, not a 30 s traceback
        flight = InFlight(lambda w, h, m, maps_bytes: band_rows(w, h, m, o.memory, o.method, rows, maps_bytes, 0 if
                                                                weights is None else SOLVE_CHANNEL_BYTES), rows is not None)
        inp, bands, top, n = open_capture(
            source, work, flight.rows_for,
            lambda fn, calls: _map(fn, calls, client), o.allow_incomplete, o.pixel_pitch_mm, o.mask, o.capture,
            lambda: hand_back(o.memory_bytes))
        try:
            res.inputs = inp
            res.notes.extend(inp.notes)
            if on_input is not None:
                on_input(inp)
            res.timings["load"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            ps, counts, near, n, gains = band_loop(res, o, inp, bands, n, weights, used, client, samples,
                                                   threads=flight.threads)
            if relight is not None:          # ptm, rti: fitted over the same bands (pipeline._rti_bands)
                t1 = time.perf_counter()
                relight(inp, ps, top, gained(band_reader(bands, near, None if near else inp.light_dirs), gains), n)
                hand_back(o.memory_bytes)
                t0 += time.perf_counter() - t1
        finally:
            bands.close()
    finally:
        if client is not None:
            client.close()
        shutil.rmtree(work, ignore_errors=True)
    # the check's verdict (InsufficientData) as untiled, after the bands that counted
    notes, quality = check_counts(counts if counts is not None else {"m": len(inp.light_dirs), "object": 0},
                                   inp.mask_source)
    res.quality = {**quality, **res.quality}           # the cast-shadow step's figures kept
    res.notes.extend(notes + light_geometry(inp.light_dirs, res.quality))
    if near:
        res.notes.append("near lights: per-pixel directions and 1/r^2 fall-off from the light positions")
    where = f" as tasks on the scheduler {o.scheduler}" if o.scheduler is not None else ""
    res.notes.append(f"--memory {o.memory}: photometric stereo over {ps.info['tiles']} bands of {n} rows{where}, "
                     f"{flight.said(ps.info['tiles'])}the images read band by band (never held whole)")
    res.timings["ps"] = time.perf_counter() - t0
    return inp, ps, (None if near else inp.light_dirs), top


def solve_channel(o, notes, images=None, mask=None):
    """(weights (3,) of the solve's channel appended to each band or None: green, process.json's
    "channels"). The mean of R, G, B needs no figure of the images: the same channel in every band as
    whole; "weighted" needs the whole images' noise (`images`, held whole), else green."""
    if o.channels == "green" or (o.channels == "weighted" and images is None):
        return None, {"channels": "green", "weights": [0.0, 1.0, 0.0]}
    weights, note = channel_weights(np.zeros((1, 1, 1, 3), np.float32) if images is None else images, mask,
                                    o.channels)
    if note:
        notes.append(note)
    return weights, {"channels": o.channels, "weights": [round(float(x), 4) for x in weights]}


def band_loop(res, o, inp, bands, n, weights, used, client=None, samples=False, one=None, threads=1):
    """Photometric stereo over bands of `n` rows of the reader `bands` (its steps: the lights' gains,
    the cast shadows, li_alternating's model, each a pass over the bands, then the solve band by
    band): (PSResult, the quality counts summed or None, near (positions, shape, pitch) or None, the
    band height solved, the gains or None). one: a dict for a capture held whole solved as one band
    (`pipeline._whole`): the quality was counted already, the per-light flags are kept, the maps
    stay in memory, and one["images"] receives the band's images as the solve saw them (its band prepared
    once and served to every pass and the solve without a copy: `HeldBands`). threads: bands solved at once."""
    h, w = inp.mask.shape
    m = len(inp.light_dirs)
    near, bag, _ = solve_setup(o, inp, weights)
    flat = getattr(bands, "flat", None)
    spec, obj = bands.spec(), None if one is not None else inp.object_mask
    smask = inp.sample_mask()
    total = m * int(np.count_nonzero(smask))

    def take(r0, r1):
        return None if not samples else {"sample_mask": smask[r0:r1], "theta0_deg": o.theta0_deg,
                                         "total": total}

    gains, hidden, model = _gains_shadows_and_model(res, o, inp, bands, near, bag, weights, n,
                                                    NOT_READ if one is None else one.get("gains", NOT_READ))
    n = rows_for_model(o.method, model, h, n)
    threads = threads if client is None and one is None and n < h else 1     # one band: no second
    hand_back(o.memory_bytes)
    hidden_bins, hidden_bin = hidden or (None, 1)
    if client is not None:     # once to every worker, not with each band
        model = model if model is None else client.scatter(model, broadcast=True)
        hidden_bins = hidden_bins if hidden is None else client.scatter(hidden_bins, broadcast=True)
    calls = ((spec, r0, r1, None if flat is None else flat[r0:r1], near, o.method, dict(bag),
              inp.mask[r0:r1], None if obj is None else obj[r0:r1], take(r0, r1), weights, model, gains,
              hidden_bins, hidden_bin, one)
             for r0, r1 in _bands(h, n))
    ps, counts = _assemble((h, w), o.method, _map(_ps_task, calls, client, threads=threads), on_disk=one is None)
    hand_back(o.memory_bytes)   # the bands' heap: not under the stages after them
    ps.info.update(tiles=len(_bands(h, n)), rows_per_tile=n, channels=used)   # pipeline._channels
    if o.channels not in ("green", "mean") and one is None:
        res.notes.append(f"channels: {o.channels} asked; with --memory the normals are solved on green")
    taken = ps.info.pop("samples", None)
    if samples:
        res.filtered, res.samples = _samples_result(taken, o.theta0_deg)
    return ps, counts, near, n, gains


def solve_setup(o, inp, weights):
    """(near (positions, shape, pitch) or None, the bands' options, the passes' options): what every
    band's solve and the passes over the bands take."""
    h, w = inp.mask.shape
    near = (o.near_light and inp.positions_mm is not None) or None
    if near:
        near = (np.asarray(inp.positions_mm), (h, w), inp.pixel_pitch_mm)
    bag = o.ps_bag(saturation=o.saturation)
    if near is None:
        bag["light_dirs"] = inp.light_dirs
    model_bag = {k: v for k, v in bag.items() if k != "light_dirs"}
    model_bag.update({} if weights is None else {"channel": SOLVE_CHANNEL})
    return near, bag, model_bag


def solve_reader(bands, inp, near, bag, weights, method_name):
    """read(r0, r1, gains=None, hidden=None) -> (the band's images, the solve's (the solve's channel
    appended, divided by the gains, the hidden values out), light directions, the mask it solves); the
    one band held whole serves its prepared band (`_whole.HeldBands.solve_read`: no copy)."""
    if getattr(bands, "prepared", None) is not None:
        return bands.solve_read
    flat = getattr(bands, "flat", None)

    def read(r0, r1, gains=None, hidden=None):
        images, usable = bands.read(r0, r1, None if flat is None else flat[r0:r1])
        images, solve, dirs, solved, _ = solve_inputs(images, usable, r0, r1, inp.mask[r0:r1], near, bag, weights)
        images, solve = divided(images, solve, gains)
        return images, without_hidden(solve, hidden, inp.mask[r0:r1], r0, method_name, solve is not images)[0], \
            dirs, solved
    return read


# `band_loop`'s gains not read yet (None: read, none to apply)
NOT_READ = object()


def _gains_shadows_and_model(res, o, inp, bands, near, bag, weights, rows, gains=NOT_READ):
    """(the lights' gains or None, the hidden lights of the cast-shadow step's bins and their bin or
    None, li_alternating's model or None), each from a pass over the bands here
    (`_light_gains.light_gains_of_bands` unless `gains` are given, `_shadows.hidden_over_bands`,
    `band_model`), each on the bands as the ones before it left them (divided by the gains, without the
    hidden values)."""
    method_name = PS_METHODS.canonical(o.method)
    read = solve_reader(bands, inp, near, bag, weights, method_name)
    model_bag = solve_setup(o, inp, weights)[2]
    if gains is NOT_READ:
        gains = light_gains_of_bands(res, o, inp, method_name, lambda r0, r1: read(r0, r1)[1:3], rows, model_bag)
    hidden = hidden_over_bands(res, o, lambda r0, r1: read(r0, r1, gains)[1:4], inp.mask, rows, method_name,
                               model_bag)
    model = band_model(o.method, lambda r0, r1: read(r0, r1, gains, hidden)[1:4], inp.mask.shape,
                       int(np.count_nonzero(inp.mask)), rows, model_bag)
    return gains, hidden, model


def one_band_note(o, h):
    """The note of a run with --memory whose capture's one band fits the budget (`_streamed.read_in_bands`)."""
    return [f"--memory {o.memory}: photometric stereo over 1 band of {h} rows: the capture fits one band, read whole "
            "(the files of a run without --memory)"] if o.memory is not None else []


def read_whole_notes(o, source):
    """The notes of a run with --memory whose source `process` reads whole (not a capture's folder:
    `streamed`): the budget bounds nothing there."""
    if o.memory is None:
        return []
    try:
        folder = source_path(source).is_dir()
    except TypeError:
        folder = False
    if folder:      # its one band fits the budget (`_streamed.read_in_bands`): said once its size is known
        return []
    notes = [f"--memory {o.memory}: {source!r} is not a capture's folder: its images were read whole, the "
             "budget bounds nothing (give the capture's folder to read it band by band)"]
    if o.scheduler is not None:
        notes.append(f"--scheduler {o.scheduler}: not used, the images being held whole here")
    return notes


def _samples_result(taken, theta0_deg):
    """(FilteredReflectance, raw samples) of the bands' (sensor, raw parts); empty when no band
    had a pixel."""
    from facette.reflect import HemisphereSensor, ReflectanceSamples
    if taken is None:
        sensor, raws = HemisphereSensor(theta0_deg, channels=3), []
    else:
        sensor, raws = taken
    if not raws:
        raws = [ReflectanceSamples(*(np.zeros((0, 3), np.float32),) * 3, np.zeros(0, np.int64),
                                   np.zeros(0, np.int16))]
    raw = raws[0] if len(raws) == 1 else ReflectanceSamples(
        *(np.concatenate([getattr(q, k) for q in raws]) for k in ("s", "o", "f", "pixel", "light")))
    return sensor.result(), raw
