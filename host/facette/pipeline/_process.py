"""`process`: from HDR images to normals, heights, mesh, reflectance samples, BRDF and report.

Stages run only when a requested output needs them (docs/outputs.md):

    output    needs stages
    normals   load, ps                       (normal.exr)
    albedo    load, ps                       (albedo.exr)
    mask      load, ps                       (mask.png)
    height    load, ps, integrate            (height.exr)
    mesh      load, ps, integrate, mesh      (mesh.ply)
    samples   load, ps, samples              (samples.npz)
    brdf      load, ps, samples, fit         (brdf.json; needs facette.fit)
    ptm       load, ptm                      (relight.ptm: PTM LRGB for RTIViewer, as photographed)
    rti       load, hsh                      (relight.rti: HSH order 3 for RTIViewer, as photographed)
    relight-web load, hsh                    (relight_web/: Relight's web format, openlime's HSH)
    gltf      load, ps, integrate, mesh, relight   (model.glb: mesh + the model's per-pixel PBR maps)
    report    load, ps (+ whatever else ran) (report.html)
"""
import json
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from facette.fit import fit_cells_verdict, preferred_model
from facette._memory import handing_back
from facette.errors import BadInputError
from facette.io.atomic import atomic_path, write_text_atomic
from facette.io.exr import write_exr
from facette.io.ply import write_ply
from facette.io.gltf import write_glb
from facette.io.png import write_mask
from facette.calib.lp import write_lp
from facette.io.ptm import write_ptm_lrgb
from facette.io.rti import write_hsh_rti
from facette.recon import INTEGRATION_METHODS, flat_margin, integrate, mesh_from_height, MESH_MAX_SLOPE
from facette.pipeline._exports import gltf_inputs, gltf_material
from facette.pipeline._budget import with_default_budget
from facette.pipeline._relight_budget import relighting_budget
from facette.capture import LP_NAME
from facette.pipeline._band_uncertainty import normal_image, uncertainty_of
from facette.pipeline._stages import ALL_OUTPUTS, FILES, OUTPUTS, STAGES_FOR, stages_needed
from facette.pipeline._options import ProcessOptions
from facette.pipeline._record import claim_results, mark_running, write_record
from facette.pipeline._rti_bands import relight_stage, write_relight_web
from facette.pipeline._relight_later import relight_after_maps
from facette.pipeline._rti_exposure import record_exposure
from facette.pipeline._streamed import solved
from facette.pipeline._quality import check_fit_cells, truth_errors
from facette.pipeline._report import report_fit_section, report_pictures, write_report
from facette.pipeline._relight_model_stage import model_input, relight_model_stage, save_relight_model
from facette.pipeline._samples import _samples_stage  # bench/recon.py imports it from here too

__all__ = ["OUTPUTS", "ALL_OUTPUTS", "STAGES_FOR", "ProcessOptions", "ProcessResult", "process", "stages_needed"]


@dataclass
class ProcessResult:
    """What `process` computed. Arrays at the input image size (H, W):

    normals (H, W, 3) unit vectors, camera frame (0 where not valid); albedo (H, W, 3); mask (H, W) bool, normals inside
    the input mask, measured or `filled` ((H, W) bool or None: pipeline._filled); object_mask (H, W) bool, the object in
    it (mask.png: the mask without the dark table or cloth `auto_masks` finds around the object; the mask itself where
    there is none, or a mask was given); height (H, W) mm or None; mesh (vertices, faces) or None; filtered
    `FilteredReflectance` or None; samples raw `ReflectanceSamples` subset or None; brdf a facette.fit FitResult or
    None; ps the full `PSResult`; timings {stage: seconds}; files {output: path}; errors {name: value} against the
    scan's truth.npz when present (angular error in degrees, height RMS in mm); ptm a PTMFit, hsh an HSHFit (--memory:
    every k-th pixel, _rti_bands) or None; fit_errors {name: value}: rel. RMS of the PTM / HSH relighting against the
    (fall-off corrected) HDR images on the object (above 6.3 M values, on an even sample of rows:
    `recon.RELIGHT_ERROR_VALUES`); interreflections the figures of `without_interreflections` when it was asked for,
    else None; light_gains: pipeline._light_gains's.
    """
    normals: np.ndarray = None
    albedo: np.ndarray = None
    mask: np.ndarray = None
    object_mask: np.ndarray = None
    height: np.ndarray = None
    mesh: tuple = None
    filtered: object = None
    samples: object = None
    brdf: object = None
    ps: object = None
    inputs: object = None
    timings: dict = field(default_factory=dict)
    files: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    options: dict = field(default_factory=dict)
    ptm: object = None
    hsh: object = None
    fit_errors: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    interreflections: dict = None
    light_gains: dict = None
    rti_exposure: object = None       # the relighting files' scale (pipeline._rti_exposure.Exposure)
    filled: np.ndarray = None
    relight_model: object = None
    uncertainty: np.ndarray = None      # (H, W) deg, each normal's 90 % band, or None: pipeline._confidence


def _fit_stage(filtered, fit_options, brdf_aware=False, material=None):
    """BRDF identification on the hemisphere sensor's cells (facette.fit.fit_hemisphere_cells:
    the model averaged over each cell, which removes the lobe-widening bias of fitting cell
    centres). The LI volume part: after BRDF-aware normals (`brdf_aware`, li_alternating, which
    itself uses them), eq 3.15 from quadrature tables (volume "tables"); otherwise the
    approximate formula (eq 3.49-3.57, "approx"). Mitsuba spheres and relief at 256 spp, σ / n_i /
    K_d over the truth, approx → tables: with li_alternating's normals paint 0.10 1.148 / 1.340 /
    1.00-1.01 → 1.018 / 1.300 / 1.00, satin 1.126 / 1.599 / 1.06-1.09 → 0.979 / 1.483 / 0.99-1.00;
    with rank_trimmed's tables are better on two scenes, worse on two (satin 1.157 / 1.443 → 0.824 /
    1.277) for 0.4-1.4 s more: approx there. "coupled" where photometric stereo chose that diffuse
    part for the main `material`; fit_options={"volume": ...} chooses ("quadrature": ~15× slower).
    The model: facette.fit.preferred_model(material) first (from the material's (σ, n_i) after BRDF-aware normals),
    the others too when it is off by more than facette.fit.FITS_RELATIVE_RMS, and a verdict either way
    (facette.fit.fit_cells_verdict); fit_options={"model": ...} fits that one. Returns (FitResult or None, note)."""
    check_fit_cells(filtered)         # too few filled cells: InsufficientData (exit 3)
    options = dict(fit_options)
    model = options.pop("model", None)
    model, material = (None if model == "auto" else model), material or {}
    if model in (None, "li"):
        options.setdefault("volume", "coupled" if material.get("diffuse") == "coupled" else
                           "tables" if brdf_aware else "approx")
    start = (material["sigma"], material["n_i"]) if brdf_aware and model is None and material.get("brdf_step") else None
    res = fit_cells_verdict(filtered, prefer=model or preferred_model(material), start=start,
                            **({} if model is None else {"models": (model,)}), **options)
    note = "" if getattr(res, "success", True) else f"brdf: the fit failed ({res.message})"
    if getattr(res, "verdict", "") == "no model fits well":
        note = "brdf: no model fits well (" + ", ".join(
            f"{t['model']} off by {100 * t['relative_rms']:.0f} % RMS" for t in res.models_tried
            if t["relative_rms"] is not None) + "): the parameters are the closest, not the material's"
    return res, note


def preload():
    """Import what `process` loads on first use (matplotlib for the report, ~0.5 s; numba and
    the compiled kernels of the loading and the PTM fit, ~0.5 s): a scan that will be processed
    calls this on a thread while it acquires, so that the time does not come after the last frame."""
    from facette.capture._pixels_jit import median_over_lights, usable_green
    from facette.recon._rti_jit import ptm_colour_block, srgb_lum_block, srgb_scale_inplace, srgb_table
    # each kernel loaded (or compiled) for the array types `process` hands it
    img = np.ones((2, 2, 2, 3), np.float32)
    median_over_lights(img[..., 1], np.empty((2, 2), np.float32), slice(0, 2))
    usable_green(img[0, ..., 1], np.ones((2, 2), np.float32), 3.0, np.empty((2, 2), bool))
    flat = img.reshape(2, 4, 3)
    ptm_colour_block(flat[:, 0:2], np.empty((4, 3)), np.empty(4), np.empty((2, 4)), 0)    # a block: strided
    lut = srgb_table()               # the sRGB encodings of relight.ptm / relight.rti
    srgb_lum_block(flat[:, 0:2], np.ones((4, 3)), np.empty((2, 4)), 0, 1.0, lut)
    srgb_scale_inplace(img.copy(), 1.0, lut)
    srgb_scale_inplace(img.astype(np.float64), 1.0, lut)
    try:
        import matplotlib
        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot  # noqa: F401
        from matplotlib import colormaps  # noqa: F401
    except Exception:     # the report itself will say what is wrong
        pass


def process(source, outputs=None, out_dir=None, options=None, **overrides):
    """Run the processing chain on a scan directory, a DiLiGenT-style folder or an RTI capture.

    source : path (or Scan object) of a facette scan (scan.json + hdr/) or a DiLiGenT folder.
    outputs : list from OUTPUTS (default all); only the stages they need run.
    out_dir : where to write the files of docs/outputs.md (None: compute only, write nothing).
    options : a `ProcessOptions` (default: every default); **overrides : fields of ProcessOptions
        that replace its values (`process(src, method="woodham1980")`).
    interreflections (an option): take the light a concave surface gathers from itself out of
        the images before photometric stereo (`facette.recon.without_interreflections`, its shape
        from a first rank_trimmed pass; needs the albedo as a reflectance, as the rig's
        calibration gives it: "auto", the default, runs it on a reflectance-calibrated scan read
        whole and says why not elsewhere, pipeline._interreflections). The BRDF fit then sees the
        direct light only; PTM/HSH keep the images as photographed. Left out, with a note, when
        gathered light is under IR_SKIP_P95 (0.5 %) of the values at their 95th percentile (a
        convex object gathers none). With li_alternating, the light glossy walls mirror into
        each other is removed too, with the lobe it finds (facette.fit.ps_li_without_interreflections).
    Returns a `ProcessResult` (timings: wall seconds per stage, "after_ps" the concurrent
    stages together, "cpu" the CPU seconds of the whole call; `interreflections` the removal's
    figures when it ran). Raises InsufficientData
    (facette.errors) when the data cannot carry the result (too dark, saturated, empty mask,
    too few filled cells for a BRDF fit).
    """
    options = options if options is not None else ProcessOptions()
    if overrides:
        options = replace(options, **overrides)
    # The concurrent stages mix a Python-bound BRDF fit with numpy blocks that give the GIL
    # up and want it back after each operation; at Python's 5 ms switch interval each block
    # waits for the fit to hand it over. 0.5 ms for the call: 12 MP process 10.8 -> 10.1 s
    # (medians of 3, alternating), the same CPU.
    interval = sys.getswitchinterval()
    sys.setswitchinterval(min(interval, 0.0005))
    try:
        # the stages run on threads of their own: BLAS keeps to one thread per caller (its threads on top
        # of ours oversubscribe the cores: a 6x12 by 12x32768 product took 7 ms, not 0.2, on 2 busy cores)
        with threadpool_limits(limits=1, user_api="blas"):
            return _process(source, outputs, out_dir, options)
    finally:
        sys.setswitchinterval(interval)


def _process(source, outputs, out_dir, o):
    outputs = list(OUTPUTS if outputs is None else outputs)
    stages = stages_needed(outputs)
    # no --memory: from the free memory; relighting: over bands (pipeline._relight_budget)
    o, budget_notes = relighting_budget(source, o, stages, outputs) or with_default_budget(source, o, outputs)
    res = ProcessResult(options=dict(o.reported(), outputs=outputs), notes=budget_notes)
    record_options = o.recorded()
    t_all, cpu_all = time.perf_counter(), time.process_time()
    if out_dir is not None and "report" in outputs:
        # matplotlib takes ~0.5 s to import: let it load while the numbers are computed
        threading.Thread(target=preload, daemon=True).start()

    def claim(inp):                    # before any work: the folder must take this run's files
        return None if out_dir is None else claim_results(Path(out_dir), record_options, inp, o.overwrite,
                                                          set(FILES.values()) | {LP_NAME}, o.mask)

    # the band loop: over bands read from the capture's files when the budget's band is shorter than the
    # image, else over one band, the capture read whole (pipeline._streamed.solved)
    inp, images, direct, light_dirs, previous, relight = solved(source, o, res, outputs, stages, claim)
    try:
        return _from_ps(res, inp, stages, outputs, images, direct, light_dirs, o, out_dir, record_options, previous,
                        t_all, cpu_all, relight=relight)
    finally:
        if relight is not None:
            relight.close()


def _from_ps(res, inp, stages, outputs, images, direct, light_dirs, o, out_dir, record_options, previous,
             t_all, cpu_all, relight=None):
    """The stages after photometric stereo, the checks against truth and the files (relight:
    the fits of pipeline._rti_bands, when --memory made them over bands)."""
    drawn = {}         # report sections drawn by the concurrent stages
    if out_dir is not None:            # before the first file: whose files these will be
        mark_running(Path(out_dir), record_options, inp, [FILES[name] for name in outputs if name in FILES])
    # --memory: the stages after photometric stereo one at a time (100 MP: 4.0 GB two at once)
    res.notes.extend(_after_ps(res, inp, stages, outputs, images, direct, light_dirs, o, out_dir, drawn,
                               workers=1 if o.memory else 2, relight=relight))
    record_exposure(res)                 # the relighting files' scale: a note and process.json
    res.errors = truth_errors(inp, res) if res.normals is not None else {}
    res.timings["total_compute"] = time.perf_counter() - t_all
    if out_dir is not None:
        t0 = time.perf_counter()
        _write_last(res, Path(out_dir), outputs, drawn)
        if inp.lights_file is not None:       # the sphere's lights, beside the results (never the input)
            res.files["lp"] = str(write_lp(Path(out_dir) / LP_NAME, *inp.lights_file))
        write_record(Path(out_dir), record_options, inp, res, previous)
        res.timings["write"] = time.perf_counter() - t0
    res.timings["cpu"] = time.process_time() - cpu_all
    return res


def _timed(res, name, fn, *args):
    """fn(*args), its wall time in res.timings[name] (s)."""
    t0 = time.perf_counter()
    out = fn(*args)
    res.timings[name] = time.perf_counter() - t0
    return out


def _after_ps(res, inp, stages, outputs, images, direct, light_dirs, o, out_dir, drawn, workers=2, relight=None):
    """The stages after photometric stereo, which depend on it only and not on each other,
    concurrently on `workers` threads (numpy, scipy's FFT and the file writers release the GIL):
    heights -> mesh, samples -> BRDF fit, PTM, HSH; each writes its files as soon as it is done; `drawn`
    receives the report sections they draw; `o` the ProcessOptions. The notes, in the stages' order."""
    integration, mesh_step = o.integration, o.mesh_step
    out = None if out_dir is None else Path(out_dir)
    if out is not None: out.mkdir(parents=True, exist_ok=True)     # noqa: E701
    relight = relight_after_maps(relight, res, inp, images, light_dirs, o, outputs)   # ptm, rti: bands, after the maps
    write = _writers(res, out, outputs, o.ascii_ply, relight)

    def shape():
        mk = res.mask if integration == "least_squares" else None
        # the margin's pixels, for the flat-margin integration: its mean slope is the table's lean
        bg = inp.background_mask()
        margin = None if bg is None or INTEGRATION_METHODS.canonical(integration) != "poisson_flat_margin" \
            else flat_margin(bg & res.mask, res.mask.shape)
        hgt = _timed(res, "integrate", integrate, res.normals, inp.pixel_pitch_mm, mk, integration, margin)
        for r0 in range(0, hgt.shape[0], 1024):      # in place, a band at a time: no (H, W) temporary
            hgt[r0:r0 + 1024][~res.mask[r0:r0 + 1024]] = 0.0
        res.height = hgt
        notes = [] if margin is None else [
            f"heights: the table's lean (its mean slope over the {int(margin.sum())} background pixels) "
            "taken out of the background's slopes only, the object's integrated as measured"]
        write("height")
        if "mesh" in stages:
            # the object's surface only: no table, no curtains down its silhouette
            step = mesh_step or max(1, int(np.ceil(np.sqrt(res.object_mask.sum() / 1e6))))
            res.mesh = _timed(res, "mesh", mesh_from_height, res.height, res.object_mask,
                              inp.pixel_pitch_mm, step, MESH_MAX_SLOPE)
            res.options["mesh_step"] = step
            write("mesh")
        notes += relight_model_stage(res, model_input(images, relight), light_dirs, inp.pixel_pitch_mm, write,
                                     "relight" in outputs) if "relight" in stages else []
        return notes

    def reflectance():
        # the images as photometric stereo saw them (near lights: fall-off divided out; the
        # direct light only when inter-reflections were removed: what the BRDF models);
        # --memory: taken band by band with photometric stereo already
        if res.filtered is None:
            res.filtered, res.samples = _timed(res, "samples", _samples_stage, direct, inp.sample_mask(),
                                               res.ps, light_dirs, o.theta0_deg)
        write("samples")
        if "fit" not in stages:
            return []
        mats = res.ps.info.get("materials") or [{}]
        main = max(mats, key=lambda q: q.get("pixels", 0))
        res.brdf, note = _timed(res, "fit", _fit_stage, res.filtered, dict(o.fit_options),
                                res.ps.method == "li_alternating", main)
        write("brdf")
        if out is not None and "report" in outputs:
            # matplotlib holds the GIL: drawn here, it runs beside numpy stages that let it go
            drawn["fit"] = _timed(res, "report_fit", report_fit_section, res)
        return [note] if note else []

    photos = None       # the fits over bands (`whole_bands`): the photographs' scale applied a band at a time

    def relit(name):      # relight.ptm, relight.rti (pipeline._rti_bands: whole images, or bands with --memory)
        ok, notes = relight_stage(name, res, photos, light_dirs, o, relight)
        if ok:
            write(name)
            if name == "rti":
                write("relight-web")
        return notes

    confidence = res.normals is not None and {"normals", "report"} & set(outputs)     # what shows it

    def maps():
        # the uncertainty (normal.exr's channel) on this thread, the other stages beside it (it ran alone before)
        if confidence:
            uncertainty_of(res, direct, light_dirs, o.saturation)      # over bands: made with them already
        for name in ("normals", "albedo", "mask"):
            write(name)
        return []

    # started in this order: the maps (on disk in a second), the shape (heights, then the longest chain)
    tasks = [(maps, out is not None or confidence), (shape, "integrate" in stages), (reflectance, "samples" in stages),
             (lambda: relit("rti"), "hsh" in stages), (lambda: relit("ptm"), "ptm" in stages)]
    # what needs the maps, the shape and the reflectance, started on the pool as soon as they are done (beside the
    # relighting files, not after them): model.glb, and the report's pictures (the page is assembled last)
    last = [(lambda: _model_glb(res, out, drawn), out is not None and "gltf" in outputs),
            (lambda: _report_pictures(res, drawn), out is not None and "report" in outputs)]
    t0, budget = time.perf_counter(), o.memory_bytes     # with a budget, the heap back after each stage
    with ThreadPoolExecutor(workers) as pool:
        def submit(fn):
            return pool.submit(handing_back(fn, budget) if budget else fn)
        later, first = [], [fn for fn, wanted in tasks[:3] if wanted]
        join = _Join(len(first), lambda: later.extend(submit(fn) for fn, wanted in last if wanted))
        futures = [submit(join.after(fn)) for fn in first] + [submit(fn) for fn, wanted in tasks[3:] if wanted]
        if not first:
            join.done()
        # in the order of `tasks` whatever finished first; re-raises a stage's error here
        notes = [n for f in futures for n in f.result()]
    notes += [n for f in later for n in f.result()]
    res.timings["after_ps"] = time.perf_counter() - t0
    return notes


class _Join:
    """Calls `then()` once `count` functions wrapped by `after` have returned (not when one raised: its
    error comes out of its future)."""

    def __init__(self, count, then):
        self.count, self.then, self.lock = count, then, threading.Lock()

    def after(self, fn):
        def run():
            out = fn()
            self.done()
            return out
        return run

    def done(self):
        with self.lock:
            self.count -= 1
            fire = self.count <= 0
        if fire:
            self.then()


def _model_glb(res, out, drawn):
    """model.glb (the mesh, with the relighting model's maps and the BRDF fit's verdict as its material) made
    and written; its material's notes kept in drawn["gltf_notes"] (the report lists them, after the others)."""
    if res.mesh is None or not len(res.mesh[1]):
        drawn["gltf_notes"] = ["gltf: the mesh has no triangles (empty mask); model.glb not written"]
        return []
    material, drawn["gltf_notes"] = gltf_material(res)
    t0 = time.perf_counter()
    kwargs, _ = gltf_inputs(res, res.options.get("mesh_step", 1), material)
    write_glb(out / FILES["gltf"], **kwargs)
    res.timings["write_gltf"] = time.perf_counter() - t0
    return []


def _report_pictures(res, drawn):
    """The report's pictures (pipeline._report.report_pictures) into drawn["pictures"]."""
    drawn["pictures"] = _timed(res, "report_pictures", report_pictures, res)
    return []


def _writers(res, out, outputs, ascii_ply, relight=None):
    """write(output): write that output's file into `out` if it was asked for (None: nothing);
    relight.ptm and .rti from the spill of `relight` (pipeline._rti_bands) when there is one."""
    meta = {"software": "facette", "source": str(res.inputs.source),
            "method": res.options["method"], "frame": "camera: x right, y up, z towards the camera"}
    if res.inputs.incomplete:
        meta["scan"] = f"incomplete: {res.inputs.incomplete}"

    def brdf_text():
        text = res.brdf.to_json() if hasattr(res.brdf, "to_json") else json.dumps(res.brdf, indent=2)
        ps_info = res.ps.info if res.ps is not None else {}
        if "materials" in ps_info:   # BRDF-aware photometric stereo: its own per-region fits
            doc = json.loads(text)
            doc["photometric_stereo"] = {k: ps_info[k] for k in ("materials", "levels", "rounds",
                                                                 "regions_found_by", "dark_offset") if k in ps_info}
            text = json.dumps(doc, indent=2)
        if res.inputs.incomplete:
            text = json.dumps({**json.loads(text), "scan_incomplete": res.inputs.incomplete}, indent=2)
        return text

    def samples(path):
        fr, raw = res.filtered, res.samples
        # stored, not deflated: 12 MP samples.npz 9.4 MB against 6.2 MB, 0.01 s against 0.42 s
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:   # never a truncated npz
            np.savez(fh, filtered_mean=fr.mean.astype(np.float32), filtered_count=fr.count,
                filtered_theta_s=fr.theta_s, filtered_s=fr.s, filtered_o=fr.o, partition_edges=fr.edges,
                partition_counts=fr.counts, theta0_deg=res.options["theta0_deg"],
                raw_s=raw.s, raw_o=raw.o, raw_f=raw.f, raw_pixel=raw.pixel, raw_light=raw.light,
                image_shape=np.array(res.normals.shape[:2]), scan_incomplete=res.inputs.incomplete)

    comment = "facette" + (f" (scan incomplete: {res.inputs.incomplete})" if res.inputs.incomplete else "")
    how = {
        # uncompressed: float32 maps of a real surface are noise to ZIP (12 MP normal, albedo
        # and height: 80.4 MB zipped against 85.6 MB, 1.1 s against 0.12 s to write)
        "normals": lambda p: write_exr(p, *normal_image(res), header=meta, compression="none"),
        "albedo": lambda p: write_exr(p, res.albedo, ("R", "G", "B"), header=meta, compression="none"),
        "height": lambda p: write_exr(p, res.height, ("Z",), header={**meta, "unit": "mm"}, compression="none"),
        "mask": lambda p: write_mask(p, res.object_mask, {"Comment": comment} if res.inputs.incomplete else None,
                                     grey=res.filled),
        "mesh": lambda p: write_ply(p, *res.mesh, binary=not ascii_ply, comment=comment),
        "samples": samples,
        "brdf": lambda p: write_text_atomic(p, brdf_text()) if res.brdf is not None else None,
        "ptm": relight.write_ptm if relight else lambda p: write_ptm_lrgb(p, res.ptm.coeffs, res.ptm.rgb),
        "relight": lambda p: save_relight_model(p, res.relight_model) if res.relight_model is not None else None,
        "rti": lambda p: (relight.write_rti if relight else lambda q, c: write_hsh_rti(q, res.hsh.coeffs, c))(
            p, _rti_comments(res)),
        "relight-web": lambda p: write_relight_web(p, res, relight),
    }

    def write(output):
        if out is not None and output in outputs:
            _timed(res, f"write_{output}", how[output], out / FILES[output])

    return write


def _rti_comments(res):
    """relight.rti's header comments: who wrote it and what its values are."""
    enc = res.hsh.encoding
    how = ("sRGB (display values, as RTIBuilder's from sRGB photographs)" if enc == "srgb"
           else "linear (proportional to the radiance; viewers show it darker than the photographs)")
    lines = [f"facette relight.rti: HSH order {res.hsh.order}, first row = top of the picture",
             f"encoding: {enc} - {how}", res.rti_exposure.comment()]
    if res.inputs.incomplete:
        lines.append(f"scan incomplete: {res.inputs.incomplete}")
    return lines


def _write_last(res, out, outputs, drawn):
    """What needs every stage: the report, assembled from the pictures the stages after photometric stereo drew
    (model.glb was written beside them, its notes listed here); then the list of files written."""
    res.notes.extend(drawn.pop("gltf_notes", []))        # the report lists these notes
    if "report" in outputs:
        _timed(res, "write_report", write_report, res, out / FILES["report"], drawn.get("fit"), drawn.get("pictures"))
        res.files["report"] = str(out / FILES["report"])
    for o in outputs:
        if (out / FILES[o]).exists() and o != "report":
            res.files[o] = str(out / FILES[o])
