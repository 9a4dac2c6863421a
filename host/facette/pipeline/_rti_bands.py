"""`process`'s ptm and hsh stages (`relight_stage`), and with --memory their fits over row bands.

The PTM and HSH fits are per pixel once their scale is known (`_rti_exposure`: the photographs'
own, or for an HDR scan the exposure that clips at most 0.1 % of the object); the files'
quantisation needs each coefficient's range over the whole image before the first byte. So, after
photometric stereo (the object mask it gives), with the band reader it used (`relight_bands`):

1. an HDR scan only: a first pass over the bands keeps the count of the object's samples and their
   top 0.1 % (`_rti_exposure.HDRWhite`), which gives the untiled exposure exactly;
2. a pass fits each band (as photographed) (`fit_ptm_lrgb`, `fit_hsh` with that white), fills what the fit
   left out (`fill_left`, the verdict of `fill_unfitted` on the counts of every band), adds the
   band's part of the relighting error (`relight_error_parts`, the rows the untiled error samples)
   and spills the float32 coefficients (and the PTM's colour bytes) to temporary files
   (`_memory.disk_array`, pages handed back after each band), keeping their range;
3. the files are written from the spill, band by band (`write_ptm_lrgb_rows`,
   `write_hsh_rti_rows`): the bytes of the untiled writer.

Kept in memory at the image's size: nothing; `ProcessResult.ptm` / `.hsh` are every `stride`-th
pixel of the fits (at most PREVIEW_PIXELS; nothing in the report reads them). On disk while it
runs: 27 bytes per pixel for the PTM, 12 x order² for the HSH (order 3: 135 bytes per pixel
together, 13.5 GB at 100 MP), in the temporary folder (TMPDIR), taken before the first band (a
full disk is said at once), gone with `close`.
"""
import threading
import time
from math import gcd

import numpy as np

from facette._memory import disk_array, release
from facette.io.ptm import column_range, ptm_rgb_bytes, write_ptm_lrgb_rows, write_ptm_rgb_rows
from facette.io.relight_web import write_relight_web as write_web_rows
from facette.io.rti import write_hsh_rti_rows
from facette.methods import PS_METHODS
from facette.pipeline._exports import fill_left, fill_unfitted, hsh_order_for, unfitted_verdict
from facette.pipeline._relight_model_stage import ImagesSpill
from facette.pipeline._rti_exposure import HDRWhite, exposure_of
from facette.pipeline._tiles import BYTES_PER_PIXEL_LIGHT as PS_BYTES_PER_PIXEL_LIGHT
from facette.recon import _rti as fit_blocks        # its _BLOCK: the pixels solved together
from facette.recon import (HSHFit, PTMFit, fit_hsh, fit_ptm_lrgb, fit_relight_error,
                           near_light_directions, relight_error_parts, relight_error_step)
from facette.recon._rti_ptm_rgb import PTMRGBFit, fit_ptm_rgb, ptm_loo_parts

__all__ = ["BANDED_OUTPUTS", "RelightBands", "WholeBands", "whole_bands", "relight_bands", "relight_stage", "relight_exposure", "band_reader", "relight_rows",
           "write_relight_web", "PREVIEW_PIXELS"]

# the outputs `relight_bands` serves over the band reader (the model: its photographs kept, `ImagesSpill`)
BANDED_OUTPUTS = frozenset({"ptm", "rti", "relight-web", "relight"})
PREVIEW_PIXELS = 1 << 20        # pixels of the fits kept in ProcessResult.ptm / .hsh at most
# A fit band's working set per pixel (near lights, both fits): per light the float32 images, their
# float64 copy divided by the fall-off, the fall-off, the directions (float64 x 3) and the PTM's
# luminance (76 bytes), per pixel the PTM's colour and coefficients and the HSH's (~170 bytes)
BYTES_PER_PIXEL_LIGHT, BYTES_PER_PIXEL = 80, 200
# a stage's fits from whole images held in memory up to this (4288x2848, 12 lights: PTM 0.08 GB, HSH 0.33; the
# file's page faults were 1.3 of 6 CPU s), above it on disk (12 MP: the HSH's 1.3 GB, not beside the images)
IN_MEMORY_BYTES = 2 ** 30
FILE_NAMES = {"ptm": "relight.ptm", "rti": "relight.rti"}      # pipeline._process.FILES's


def relight_rows(ps_rows, width, lights, method):
    """Rows of a fit band with the working set of a photometric-stereo band of `ps_rows` rows
    (`_tiles.BYTES_PER_PIXEL_LIGHT` of `method`), even (the relighting error samples pairs of
    rows), >= 2."""
    per_light = PS_BYTES_PER_PIXEL_LIGHT.get(PS_METHODS.canonical(method), max(PS_BYTES_PER_PIXEL_LIGHT.values()))
    budget = int(ps_rows) * int(width) * int(lights) * per_light
    rows = budget // (int(width) * (BYTES_PER_PIXEL_LIGHT * int(lights) + BYTES_PER_PIXEL))
    return max(2, int(rows) // 2 * 2)


def _aligned(rows, width, height):
    """(rows of the fit bands, True when they start on the fits' blocks of pixels): the band
    height made a multiple of the rows after which a band starts on a block (`recon._rti._BLOCK`
    pixels, counted from the image's first), so that each band's blocks are the untiled fit's
    and their float32 products the same sums: the untiled file's bytes. When that unit is
    taller than `rows` (an image width with few factors of 2: 8192 rows for an odd width),
    `rows` as they are (False), unless one band holds the image."""
    unit = fit_blocks._BLOCK // gcd(fit_blocks._BLOCK, int(width))
    unit *= 2 if unit % 2 else 1                  # and even: the relighting error's pairs of rows
    if rows >= height:
        return rows, True
    if unit > rows:
        return rows, False
    return rows // unit * unit, True


def band_reader(bands, near, light_dirs):
    """read(r0, r1) -> (images (m, r1 - r0, W, 3) as the fits take them, light directions): a
    band reader's (`_bands`) images, divided by the near lights' fall-off with their per-pixel
    directions (near: (positions (m, 3), (H, W), pixel pitch) or None: `light_dirs` (m, 3))."""
    def read(r0, r1):
        images, _ = bands.read(r0, r1)
        if near is None:
            return images, light_dirs
        positions, shape, pitch = near
        dirs, falloff = near_light_directions(positions, shape, pitch, rows=(r0, r1))
        return images / np.transpose(falloff, (2, 0, 1))[..., None], dirs
    return read


def _full_size(shape, dtype, in_memory):
    """An image-sized array for the fits: in memory (`in_memory`), else in a temp file (`disk_array`)."""
    return np.empty(shape, dtype) if in_memory else disk_array(shape, dtype)


def _band_of(array, r0, r1):
    """Rows r0..r1 of a spill: a view of one in memory, a copy of a disk array's (its pages handed back)."""
    if not isinstance(array, np.memmap):
        return array[r0:r1]
    band = np.array(array[r0:r1])
    release(array)
    return band


class _Spill:
    """A fit's float32 coefficients (H, W, *tail) written band after band into a temporary file
    (`_memory.disk_array`, its pages handed back after each band) or, `in_memory`, an array (whole
    images: at 4288x2848 the file's page faults and write-backs cost 1.3 CPU s of the 6), their range
    over every pixel (`column_range` of (·, T)), the counts of `fill_left`, the relighting error's parts
    and every `stride`-th pixel of the fit (the preview)."""

    def __init__(self, shape, tail, stride, in_memory=False):
        self.data = _full_size(tuple(shape) + tuple(tail), np.float32, in_memory)
        self.tail, self.stride = tuple(tail), stride
        self.lo = self.hi = None
        self.left = self.masked = 0
        self.parts, self.preview = [], []

    def target(self, r0, r1):
        """Where rows r0..r1's fit writes (`recon._rti`'s `out`): a spill in memory's rows, else None (`add`)."""
        return self.data[r0:r1] if self.in_memory() else None

    def add(self, r0, fit, counts, parts):
        coeffs = fit.coeffs
        if not np.may_share_memory(coeffs, self.data):       # not fitted in place (`target`)
            self.data[r0:r0 + len(coeffs)] = coeffs
            release(self.data)
        lo, hi = column_range(np.ascontiguousarray(coeffs, np.float32).reshape(-1, self.tail[-1]))
        self.lo = lo if self.lo is None else np.minimum(self.lo, lo)
        self.hi = hi if self.hi is None else np.maximum(self.hi, hi)
        self.left, self.masked = self.left + counts[0], self.masked + counts[1]
        self.parts.extend(parts)
        rows = [r - r0 for r in range(-(-r0 // self.stride) * self.stride, r0 + len(coeffs), self.stride)]
        kept = ("rgb", "valid") if self.in_memory() else ("coeffs", "rgb", "valid")    # in memory: `joined`'s
        self.preview.append({k: getattr(fit, k)[rows, ::self.stride] for k in kept if hasattr(fit, k)})

    def in_memory(self):
        return not isinstance(self.data, np.memmap)

    def rows(self, r0, r1):
        """Rows r0..r1 of the coefficients (`_band_of`)."""
        return _band_of(self.data, r0, r1)

    def joined(self, name):
        """Every `stride`-th pixel of the fit's `name` (coeffs, rgb, valid); the coefficients of a spill in
        memory taken from it at once (0.15 of the two stages' CPU s went to the band copies joined)."""
        if name == "coeffs" and self.in_memory():
            return np.ascontiguousarray(self.data[::self.stride, ::self.stride])
        return np.concatenate([p[name] for p in self.preview])

    def error(self):
        if not self.parts:
            return float("nan")
        num, den = (sum(x) for x in zip(*self.parts))
        return float(np.sqrt(num / den)) if den > 0 else float("nan")


class RelightBands:
    """The banded fits of `relight_bands`: ptm, hsh (`PTMFit`, `HSHFit` of every `stride`-th
    pixel, or None), ok {"ptm", "rti": the file can be written}, notes {"ptm", "rti": [...]},
    fit_errors, timings; `write_ptm(path)`, `write_rti(path, comments)` write the files from the
    spill (temporary files without a name, gone with this object or at `close()`); model_images:
    the photographs for the relighting model (`ImagesSpill`, output "relight") or None."""

    def __init__(self, shape, stride, whole=False):
        self.shape, self.stride, self.whole, self.in_memory = shape, stride, whole, False
        self.ptm = self.hsh = self.model_images = None
        self.ok, self.notes, self.fit_errors, self.timings = {}, {"ptm": [], "rti": []}, {}, {}
        self.spills, self.rgb, self.exposure = {}, None, None
        self.ptm_format, self.loo = None, []        # "lrgb" or "rgb"; `ptm_loo_parts` of every band

    def write_ptm(self, path):
        h, w = self.shape
        s = self.spills["ptm"]
        if self.ptm_format == "rgb":
            return write_ptm_rgb_rows(path, w, h, (s.lo, s.hi), s.rows)

        return write_ptm_lrgb_rows(path, w, h, (s.lo, s.hi), s.rows, lambda r0, r1: _band_of(self.rgb, r0, r1))

    def write_rti(self, path, comments):
        h, w = self.shape
        s = self.spills["rti"]
        return write_hsh_rti_rows(path, w, h, (s.lo, s.hi), s.rows, comments)

    def close(self):
        """The temporary files go (their space is given back once nothing maps them)."""
        self.spills, self.rgb, self.model_images = {}, None, None


def relight_bands(read, mask, outputs, o, ps_rows, lights, inp, exposure=None, rows=None, whole=False):
    """relight.ptm and relight.rti fitted over bands (`relight_rows` of photometric stereo's
    `ps_rows` rows), as `process`'s ptm and hsh stages fit them on the whole images.

    read(r0, r1) -> (images (m, r1 - r0, W, 3), light directions (m, 3) or (r1 - r0, W, m, 3))
    (`band_reader`); mask (H, W) bool, the object mask (an HDR scan's exposure, fill_unfitted's
    pixels, the relighting error's); outputs: what `process` was asked for (ptm, rti); o:
    ProcessOptions (method, rti_encoding, hsh_order); lights: m; inp: the input (`exposure_of`).
    Output "relight": the photographs are kept for the relighting model (`RelightBands.model_images`)
    in the same pass. exposure: the files' `Exposure` when known (the whole images': `whole_bands`),
    rows: the fit bands' rows (None: from `ps_rows`); whole: `read` gives rows of whole images in memory:
    relight.ptm's format chosen before the fits (`_ptm_format_first`), the fits held in memory up to
    IN_MEMORY_BYTES. Returns a `RelightBands` (close it), or None when none of these is asked for."""
    want_ptm, want_hsh = "ptm" in outputs, bool({"rti", "relight-web"} & set(outputs))   # the web folder: HSH's
    order, order_note = hsh_order_for(lights, o.hsh_order) if want_hsh else (None, None)
    if not want_ptm and not want_hsh and "relight" not in outputs:
        return None
    h, w = mask.shape
    rows, aligned = _aligned(relight_rows(ps_rows, w, lights, o.method) if rows is None else rows, w, h)
    spans = [(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]
    stride = max(1, int(np.ceil(np.sqrt(h * w / PREVIEW_PIXELS))))
    out = RelightBands((h, w), stride, whole)
    if "relight" in outputs:
        out.model_images = ImagesSpill(lights, h, w)
    if not want_ptm and not want_hsh:
        for r0, r1 in spans:
            out.model_images.add(r0, *read(r0, r1))
        return out
    if order_note:
        out.notes["rti"].append(order_note)
    if not aligned and exposure is None:          # (whole images, exposure given: no other file to differ from)
        out.notes["ptm" if want_ptm else "rti"].append(
            f"relight.ptm / relight.rti: fitted over bands of {rows} rows that do not start on the fit's blocks of "
            f"{fit_blocks._BLOCK} pixels (the image is {w} pixels wide): a coefficient may differ from the "
            "untiled file's by one quantisation step (float32 products summed in another order)")
    try:
        t0 = time.perf_counter()
        given, exposure = exposure is not None, exposure or exposure_of(inp, o.rti_encoding, white=(1.0, 0.0))
        if exposure.source == "hdr" and not given:          # a pass over the bands for the exposure
            top = HDRWhite(lights * int(np.count_nonzero(mask)))
            for r0, r1 in spans:
                top.add(read(r0, r1)[0], mask[r0:r1])
            exposure = exposure_of(inp, o.rti_encoding, white=top.value())
        out.exposure = exposure
        out.timings["relight_white"] = time.perf_counter() - t0
        _fit_pass(out, read, mask, spans, (want_ptm and o.ptm_format, order), exposure, lights)
        _verdicts(out, order, exposure)
    except BaseException:
        out.close()
        raise
    return out


def _fit_pass(out, read, mask, spans, wanted, exposure, lights):
    """Each band fitted, filled, its error's parts summed and spilled (`_Spill`)."""
    h, w = out.shape
    want_ptm, order = wanted                       # want_ptm: False or the format asked (`ptm_format`)
    step = relight_error_step(h, w, lights)        # fit_relight_error's sample of rows
    kw = dict(white=exposure.white, encoding=exposure.encoding, photographed=True)
    t0 = time.perf_counter()
    if want_ptm == "auto" and out.whole:          # whole images: the format first, then only its fit
        want_ptm = _ptm_format_first(out, read, mask, spans, step, exposure, kw)
    seconds = {"read": 0.0, "ptm": time.perf_counter() - t0, "hsh": 0.0}
    spilled = {"auto": 99, "lrgb": 27, "rgb": 72}.get(want_ptm, 0) + (0 if order is None else 12 * order * order)
    out.in_memory = out.whole and spilled * h * w <= IN_MEMORY_BYTES       # bytes a pixel, as `_Spill`s hold them
    if want_ptm in ("auto", "lrgb"):
        out.spills["ptm"] = _Spill((h, w), (6,), out.stride, out.in_memory)
        out.rgb = _full_size((h, w, 3), np.uint8, out.in_memory)
    if want_ptm in ("auto", "rgb"):
        out.spills["ptm_rgb"] = _Spill((h, w), (3, 6), out.stride, out.in_memory)
    if order is not None:
        out.spills["rti"] = _Spill((h, w), (3, order * order), out.stride, out.in_memory)
    for r0, r1 in spans:
        t0 = time.perf_counter()
        images, dirs = read(r0, r1)
        if out.model_images is not None:
            out.model_images.add(r0, images, dirs)
        images = exposure.photographs(images)
        band = mask[r0:r1]
        starts = [a - r0 for a in range(-(-r0 // step) * step, r1, step)]
        t1 = time.perf_counter()
        seconds["read"] += t1 - t0
        if want_ptm:
            _fit_ptms(out, images, dirs, band, starts, r0, kw)
            t2 = time.perf_counter()
            seconds["ptm"] += t2 - t1
            t1 = t2
        if order is not None:
            fit = fit_hsh(images, dirs, order=order, mask=band, out=out.spills["rti"].target(r0, r1), **kw)
            counts = fill_left(fit, images, band)
            out.spills["rti"].add(r0, fit, counts, relight_error_parts(fit, images, dirs, band, starts))
            del fit
            seconds["hsh"] += time.perf_counter() - t1
    out.timings.update(relight_read=seconds["read"], **{k: seconds[k] for k, on in (("ptm", want_ptm), ("hsh", order))
                                                        if on})


def _fit_ptms(out, images, dirs, band, starts, r0, kw):
    """A band's PTM fits (the spills `_fit_pass` made: LRGB, per channel or both) and, with both, their
    leave-one-light-out errors on the relighting error's rows (`ptm_loo_parts`; None under per-pixel
    directions: the per-channel fit is then dropped, LRGB kept as before, said)."""
    fits = {}
    if "ptm" in out.spills:
        fit = fits["ptm"] = fit_ptm_lrgb(images, dirs, mask=band, out=out.spills["ptm"].target(r0, r0 + len(band)), **kw)
        out.spills["ptm"].add(r0, fit, fill_left(fit, images, band), relight_error_parts(fit, images, dirs, band, starts))
        out.rgb[r0:r0 + len(band)] = ptm_rgb_bytes(fit.rgb)
        release(out.rgb)
    if "ptm_rgb" in out.spills:
        fit = fits["ptm_rgb"] = fit_ptm_rgb(images, dirs, kw["white"], kw["encoding"],
                                            out=out.spills["ptm_rgb"].target(r0, r0 + len(band)))
        out.spills["ptm_rgb"].add(r0, fit, fill_left(fit, images, band),
                                  relight_error_parts(fit, images, dirs, band, starts))
    if len(fits) == 2:
        parts = ptm_loo_parts(fits["ptm"], fits["ptm_rgb"], images, dirs, band, starts)
        if parts is None:
            del out.spills["ptm_rgb"]
            out.notes["ptm"].append("relight.ptm: PTM_FORMAT_LRGB (per-pixel light directions: the choice of the "
                                    "format by leave-one-light-out error needs far lights)")
        else:
            out.loo.extend(parts)


def _loo_choice(out):
    """relight.ptm's format by the leave-one-light-out errors summed in out.loo: the one with the smaller
    (ties: LRGB, half the bytes), said in out.notes."""
    num_l, num_r, n = (sum(x) for x in zip(*out.loo)) if out.loo else (0.0, 0.0, 0)
    rms_l, rms_r = (255 * np.sqrt(v / max(n, 1)) for v in (num_l, num_r))
    choice = "rgb" if n and num_r < num_l else "lrgb"
    out.notes["ptm"].append(f"relight.ptm: PTM_FORMAT_{choice.upper()} (leave-one-light-out RMS on the object "
                            f"{rms_r:.2f} grey levels per channel, {rms_l:.2f} luminance x colour)")
    return choice


def _ptm_format_first(out, read, mask, spans, step, exposure, kw):
    """relight.ptm's format ("lrgb" or "rgb") before the fits, from whole images: both PTMs fitted on the
    relighting error's rows only (each pixel's fit is its own: the values of the fits over every row
    there) and `_loo_choice` on their leave-one-light-out errors, the choice `_fit_ptms` and
    `_ptm_choice` make after fitting both everywhere; the other format is then not fitted (at 4288x2848,
    12 lights, 1.2 of the PTM stage's CPU s were the dropped fit). Per-pixel light directions: "lrgb",
    said, as `_fit_ptms` says it."""
    for r0, r1 in spans:
        # the error's blocks of two rows (`_fit_pass`'s starts), side by side: block k at rows 2k, 2k + 1
        blocks = [np.arange(a, min(a + 2, r1)) - r0 for a in range(-(-r0 // step) * step, r1, step)]
        if not blocks:
            continue
        rows, starts = np.concatenate(blocks), np.cumsum([0] + [len(b) for b in blocks[:-1]])
        images, dirs = read(r0, r1)
        if np.ndim(dirs) != 2:
            out.notes["ptm"].append("relight.ptm: PTM_FORMAT_LRGB (per-pixel light directions: the choice of the "
                                    "format by leave-one-light-out error needs far lights)")
            return "lrgb"
        images, band = exposure.photographs(images[:, rows]), mask[r0:r1][rows]
        lrgb = fit_ptm_lrgb(images, dirs, mask=band, **kw)
        rgb = fit_ptm_rgb(images, dirs, kw["white"], kw["encoding"])
        out.loo.extend(ptm_loo_parts(lrgb, rgb, images, dirs, band, starts))
    return _loo_choice(out)


def _ptm_choice(out):
    """relight.ptm's format ("lrgb" or "rgb"): the one spill left, or of both the one with the smaller
    leave-one-light-out error (`_loo_choice`); the other spill dropped."""
    if "ptm_rgb" not in out.spills:
        return "lrgb"
    if "ptm" in out.spills:
        choice = _loo_choice(out)
        del out.spills["ptm" if choice == "rgb" else "ptm_rgb"]
        if choice == "lrgb":
            return choice
        out.rgb = None
    out.spills["ptm"] = out.spills.pop("ptm_rgb")
    return "rgb"


def _verdicts(out, order, exposure):
    """The previews, `fill_unfitted`'s verdicts and notes, and the relighting errors."""
    if "ptm" in out.spills or "ptm_rgb" in out.spills:
        out.ptm_format = _ptm_choice(out)
        s = out.spills["ptm"]
        out.ptm = (PTMRGBFit(s.joined("coeffs"), None, exposure.white, s.joined("valid"), exposure.encoding)
                   if out.ptm_format == "rgb" else
                   PTMFit(s.joined("coeffs"), s.joined("rgb"), exposure.white, s.joined("valid"), exposure.encoding))
        out.ok["ptm"], note = unfitted_verdict(out.ptm, s.left, s.masked, FILE_NAMES["ptm"])
        out.notes["ptm"] += [note] if note else []
        if out.ok["ptm"]:
            out.fit_errors["ptm_relative_rms"] = s.error()
    if "rti" in out.spills:
        s = out.spills["rti"]
        out.hsh = HSHFit(s.joined("coeffs"), order, exposure.white, s.joined("valid"), exposure.encoding)
        out.ok["rti"], note = unfitted_verdict(out.hsh, s.left, s.masked, FILE_NAMES["rti"])
        out.notes["rti"] += [note] if note else []
        if out.ok["rti"]:
            out.fit_errors["hsh_relative_rms"] = s.error()


WHOLE_BAND_BYTES = 256 * 2 ** 20     # a fit band's working set from whole images (`whole_bands`)


class WholeBands:
    """`relight_bands` over the whole images, run once when a stage first asks (`fitted`, under a
    lock: the ptm and rti stages run on two threads); the writers delegate to its result."""

    def __init__(self, fit):
        self._fit, self._done, self._lock = fit, None, threading.Lock()

    def fitted(self, name=None):
        """The fits (`name`: the stage that asks, "ptm" or "rti"; one fit serves both here)."""
        with self._lock:
            if self._done is None:
                self._done = self._fit()
            return self._done

    def write_ptm(self, path):
        return self.fitted().write_ptm(path)

    def write_rti(self, path, comments):
        return self.fitted().write_rti(path, comments)

    def close(self):
        if self._done is not None:
            self._done.close()


def fits_from_whole(relight, images, outputs):
    """Whether `whole_bands` fits the relighting files from the whole images: no fits given
    (--memory's), the images held, and ptm, rti or relight-web asked."""
    return relight is None and images is not None and bool({"ptm", "rti", "relight-web"} & set(outputs))


def whole_bands(relight, res, inp, images, light_dirs, o, outputs, exposure=None):
    """`relight` when given (--memory's fits), else with the whole images (m, H, W, C) and ptm,
    rti or relight-web asked: their fits over bands of rows of them (a `WholeBands`), the
    photographs' exposure applied a band at a time: `Exposure.photographs` copies the images
    when it multiplies gains back (16 photographs of 12 MP: 2.3 GB more). res.rti_exposure set
    (to `exposure` when given: found already)."""
    if not fits_from_whole(relight, images, outputs):
        return relight
    res.rti_exposure = exposure if exposure is not None else \
        exposure_of(inp, o.rti_encoding, res.light_gains, images, res.object_mask)
    m, h, w = images.shape[:3]
    rows = max(2, WHOLE_BAND_BYTES // (w * (BYTES_PER_PIXEL_LIGHT * m + BYTES_PER_PIXEL)) // 2 * 2)

    def read(r0, r1):
        return images[:, r0:r1], light_dirs if np.ndim(light_dirs) == 2 else light_dirs[r0:r1]
    return WholeBands(lambda: relight_bands(read, res.object_mask, [x for x in outputs if x != "relight"], o, None, m,
                                            inp, exposure=res.rti_exposure, rows=rows, whole=True))


def relight_exposure(res, inp, images, o):
    """(the `Exposure` of the relighting files, the images as photographed) of `process`'s whole
    images (m, H, W, 3), over res.object_mask; res.rti_exposure set."""
    res.rti_exposure = exposure_of(inp, o.rti_encoding, res.light_gains, images, res.object_mask)
    return res.rti_exposure, res.rti_exposure.photographs(images)


def relight_stage(name, res, images, light_dirs, o, banded=None):
    """`process`'s ptm (name "ptm") or hsh ("rti") stage: res.ptm or res.hsh, res.fit_errors,
    res.timings, on the images (m, H, W, 3) as photographed (`relight_exposure`, res.rti_exposure)
    with their light directions, or taken from `banded` (a `RelightBands`, --memory).
    Returns (the file can be written, notes)."""
    if banded is not None:
        banded = banded.fitted(name) if isinstance(banded, WholeBands) else banded
        setattr(res, "ptm" if name == "ptm" else "hsh", banded.ptm if name == "ptm" else banded.hsh)
        res.rti_exposure = banded.exposure
        res.timings.update(banded.timings)
        res.fit_errors.update(banded.fit_errors)
        return banded.ok.get(name, False), banded.notes[name]
    t0 = time.perf_counter()
    e = res.rti_exposure
    kw = dict(mask=res.object_mask, white=e.white, encoding=e.encoding, photographed=True)
    if name == "ptm":
        res.ptm = fit_ptm_lrgb(images, light_dirs, **kw)
        ok, note = fill_unfitted(res.ptm, images, res.object_mask, FILE_NAMES["ptm"])   # never a blank file
        if ok:
            res.fit_errors["ptm_relative_rms"] = fit_relight_error(res.ptm, images, light_dirs, res.object_mask)
        res.timings["ptm"] = time.perf_counter() - t0
        return ok, [note] if note else []
    order, note = hsh_order_for(len(images), o.hsh_order)
    notes, ok = [note] if note else [], False
    if order is not None:
        res.hsh = fit_hsh(images, light_dirs, order=order, **kw)
        ok, note = fill_unfitted(res.hsh, images, res.object_mask, FILE_NAMES["rti"])
        notes += [note] if note else []
        if ok:
            res.fit_errors["hsh_relative_rms"] = fit_relight_error(res.hsh, images, light_dirs, res.object_mask)
    res.timings["hsh"] = time.perf_counter() - t0
    return ok, notes


def write_relight_web(path, res, banded=None):
    """OUT/relight_web/ (Relight's web format, `io.relight_web`) of res.hsh: the whole fit, or the
    spill of `banded` (--memory) read band by band."""
    h, w = res.mask.shape
    if banded is not None:
        s = (banded.fitted("rti") if isinstance(banded, WholeBands) else banded).spills["rti"]
        rows, lo_hi = s.rows, (s.lo, s.hi)
    else:
        coeffs = res.hsh.coeffs
        rows, lo_hi = (lambda r0, r1: coeffs[r0:r1]), column_range(coeffs.reshape(-1, coeffs.shape[-1]))
    dirs = res.inputs.light_dirs
    lights = dirs if dirs.ndim == 2 else dirs[h // 2, w // 2]
    pitch = res.inputs.pixel_pitch_mm if res.inputs.kind == "scan" else None
    return write_web_rows(path, w, h, "hsh", rows, lo_hi, lights, pixel_size_mm=pitch)
