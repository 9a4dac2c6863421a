"""li_alternating over row bands: the material model fitted once, on a sample drawn across the
bands, then each band solved per pixel with that model fixed.

    model = fit_li_model(read, shape, n_valid)          # one pass over the bands
    part = ps_li_alternating(band, dirs, mask=band_mask, model=model, row0=r0)   # each band

Above `coarse_pixels` valid pixels `ps_li_alternating` already fits its model on the images
binned f x f and keeps it fixed at full size, where every step is per pixel (the robust start,
the Lambertian level, the solve from the upsampled coarse normal, the settled shadows, K_d).
What it read of the whole image besides is drawn here while the bands go by:

- the binned images (f x f block means, bands of a multiple of f rows: the same blocks as whole);
- a sample of full-size rows spaced evenly down the image (about SAMPLE_PIXELS pixels), on which
  the robust start gives each photograph's dark level (`recon.dark_offsets`) and, when the coarse
  pass finds no lobe (binning smears a sharp highlight), the model choice is asked again of
  full-size pixels.

The dark level is taken out of the binned values (a block's mean less the level, floored at 0,
where the whole reading floored each value first: they differ where noise dips below the level).
An image held whole runs the same steps as one band (`ps_li_alternating` calls these), so the
bands and the whole image give the same normals (a test). Memory: the binned images and the
sample, each ~m x SAMPLE_PIXELS x C x 4 bytes, and one band.
"""
import inspect
import time
from dataclasses import dataclass

import numpy as np

from facette.recon import dark_offsets

from ._ps_li_coarse import bin_inputs, coarse_factor
from ._ps_li_pixels import Pixels, Settings

__all__ = ["LiModel", "MODEL_OPTIONS", "SAMPLE_PIXELS", "li_model", "fit_li_model", "sample_rows", "lowered",
           "whole_reader"]

# the options of ps_li_alternating its coarse pass takes (`li_model`), and those the model reads besides
ALTERNATION = ("rounds", "tol_deg", "fit_pixels", "t_residual", "iterations", "engine", "volume_model",
               "highlight_start", "diffuse")
MODEL_OPTIONS = ALTERNATION + ("channel", "saturation", "init", "init_options", "materials", "coarse_pixels",
                               "dark_offset", "seed", "fine_iterations", "neighbour_deg")
# full-size pixels of the sample (rows spread down the image): the dark level's and, where the
# coarse pass finds no lobe, the model choice's; as many as the coarse pass has at most
SAMPLE_PIXELS = 250_000


@dataclass
class LiModel:
    """What every band shares: the binning factor, the image's (H, W), the coarse pass's normals
    (hc, wc, 3) and info (its materials: σ, n_i, diffuse part), each photograph's dark level
    (offsets (m, C) and its info; offsets None: left in), the full-size model choice (fit,
    choice) when the coarse pass found no lobe, else None, and with per-pixel (near) lights their
    mean direction over the image, for which the Lambertian level's correction is tabulated (the
    band's own mean would make each band's normals depend on the band)."""
    factor: int
    shape: tuple
    coarse_normal: np.ndarray
    coarse_info: dict
    offsets: np.ndarray
    dark: dict
    choice: tuple = None
    mean_dirs: np.ndarray = None     # (m, 3) per-pixel lights' mean over the image (the Lambertian correction's)

    def summary(self):
        """info["coarse"] of the bands' results."""
        return {k: self.coarse_info[k] for k in ("factor", "pixels", "seconds", "cpu_seconds", "rounds", "sample_rows")}


def sample_rows(h, w, pixels=SAMPLE_PIXELS):
    """The rows of the sample: evenly spaced, about `pixels` pixels in all (every row when fewer)."""
    stride = max(1, -(-h // max(1, -(-pixels // max(w, 1)))))
    return np.arange(stride // 2, h, stride)


def lowered(images, offsets, saturation):
    """The images less each photograph's dark level, floored at 0 (one copy; NaN stays NaN;
    saturated values as they were: still saturated), or the images when `offsets` is None."""
    if offsets is None:
        return images
    out = images - offsets[:, None, None, :]
    np.maximum(out, 0, out=out)
    if saturation is not None:
        np.copyto(out, images, where=images >= saturation)
    return out


def li_model(read, shape, n_valid, rows, settings=None, **options):
    """The model every band of an image shares (`_ps_li_bands.LiModel`: the alternation on the
    image binned f × f, the dark level and, where the coarse pass finds no lobe, the model choice
    on full-size pixels), fitted in one pass of read(r0, r1) -> (images, light_dirs, mask) over
    bands of about `rows` rows; None when the image is solved whole instead (at most
    `coarse_pixels` of its `n_valid` pixels, or several materials: coarse_factor). options:
    ps_li_alternating's keywords (those the model does not read are ignored: mask, model, ...);
    settings: the Settings of its full-size steps (from the same options when None)."""
    from ._ps_li import DARK_NEGLIGIBLE, _check_options, _trusted, ps_li_alternating   # it calls these
    defaults = {k: p.default for k, p in inspect.signature(ps_li_alternating).parameters.items()
                if p.default is not inspect.Parameter.empty}
    o = {**defaults, **{k: v for k, v in options.items() if k in defaults}}
    f = coarse_factor(int(n_valid), o["coarse_pixels"], o["materials"])
    if f is None:
        return None
    if settings is None:
        diffuse_models = _check_options(o["rounds"], o["init"], o["highlight_start"], o["diffuse"],
                                        o["volume_model"], o["dark_offset"], o["neighbour_deg"])
        settings = Settings(iterations=o["iterations"], fine_iterations=o["fine_iterations"],
                            fit_pixels=o["fit_pixels"], t_residual=o["t_residual"], engine=o["engine"],
                            highlight_start=o["highlight_start"], diffuse_models=diffuse_models,
                            neighbour_deg=float(o["neighbour_deg"]))
    init, init_options, seed, saturation = o["init"], dict(o["init_options"] or {}), o["seed"], o["saturation"]

    def coarse_pass(ci, cl, cm, channel):     # the whole alternation on the binned images (never coarse-to-fine again)
        return ps_li_alternating(ci, cl, mask=cm, saturation=None, materials=1, coarse_pixels=None, channel=channel,
                                 init=init, init_options=init_options, seed=seed, dark_offset="none",
                                 **{k: o[k] for k in ALTERNATION})

    def choose(images, dirs, channel, base):   # the coarse pass found no lobe: asked again of full-size pixels
        px = Pixels.start(images, dirs, channel, saturation, base, settings, seed)
        pix = np.arange(px.idx.size)
        fit, _, choice = px.choose_model(px.draw(_trusted(px, pix)), pix)
        return fit, choice

    return fit_li_model(read, shape, f, rows, o["channel"], saturation, init, init_options,
                        None if o["dark_offset"] == "none" else DARK_NEGLIGIBLE, coarse_pass, choose)


def whole_reader(images, light_dirs, mask):
    """read(r0, r1) of `li_model` over images held whole."""
    return lambda r0, r1: (images[:, r0:r1], light_dirs if light_dirs.ndim == 2 else light_dirs[r0:r1], mask[r0:r1])


def fit_li_model(read, shape, factor, rows, channel, saturation, init, init_options, dark_negligible,
                 alternation, choose):
    """The LiModel of an image read by bands (module doc).

    read(r0, r1) -> (images (m, r1 - r0, W, C), light_dirs (m, 3) or (r1 - r0, W, m, 3), mask
    (r1 - r0, W) bool): a band as the solve sees it. factor: the binning factor; rows: about this
    many rows per read (rounded to a multiple of factor). alternation(images, dirs, mask) -> the
    coarse pass's PSResult (ps_li_alternating on binned images, channel); choose(images, dirs,
    channel, base: the robust start's PSResult) -> (fit, choice) of full-size pixels."""
    h, w = shape
    # the whole image in one read when the rows hold it (the last blocks padded as a last band's are: the
    # same bins), so that an image held whole hands its one band over once (`pipeline._whole.HeldBands`)
    step = h if int(rows) >= h else max(factor, int(rows) // factor * factor)
    picked = sample_rows(h, w)
    binned, b_dirs, b_mask, s_img, s_dirs, s_mask = [], [], [], [], [], []
    t0, c0 = time.perf_counter(), time.process_time()
    for r0 in range(0, h, step):
        r1 = min(h, r0 + step)
        images, dirs, mask = read(r0, r1)
        out, cdirs, cmask = bin_inputs(images, dirs, mask, factor, saturation)
        binned.append(out), b_dirs.append(cdirs), b_mask.append(cmask)
        sel = picked[(picked >= r0) & (picked < r1)] - r0
        s_img.append(images[:, sel].copy())
        s_mask.append(mask[sel])
        s_dirs.append(dirs if dirs.ndim == 2 else dirs[sel])
        del images, dirs, mask
    channel = (1 if binned[0].shape[3] == 3 else 0) if channel is None else channel   # as recon._ps._check_inputs
    per_pixel = b_dirs[0].ndim == 4
    binned, b_mask = np.concatenate(binned, axis=1), np.concatenate(b_mask)
    b_dirs = np.concatenate(b_dirs) if per_pixel else b_dirs[0]
    s_img, s_mask = np.concatenate(s_img, axis=1), np.concatenate(s_mask)
    s_dirs = np.concatenate(s_dirs) if per_pixel else s_dirs[0]
    read_s = time.perf_counter() - t0
    base = init(s_img, s_dirs, mask=s_mask, channel=channel, saturation=saturation, **(init_options or {}))
    offsets, dark = None, None
    if dark_negligible is not None:
        offsets, dark = dark_offsets(s_img, s_dirs, base.normal, base.valid, saturation)
        dark["applied"] = bool(dark["relative"] >= dark_negligible)
        dark["sample_rows"] = int(picked.size)
        offsets = offsets if dark["applied"] else None
    binned = lowered(binned, offsets, None)
    coarse = alternation(binned, b_dirs, b_mask, channel)
    del binned
    coarse.info.update(factor=factor, sample_rows=int(picked.size), read_seconds=read_s,
                       seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0)
    cmat = coarse.info["materials"][0] if coarse.info.get("materials") else {"brdf_step": False}
    choice = None
    if not cmat.get("brdf_step") or cmat.get("sigma") is None:
        choice = choose(lowered(s_img, offsets, saturation), s_dirs, channel, base)
    mean_dirs = None
    if per_pixel and b_mask.any():
        mean_dirs = b_dirs[b_mask].mean(axis=0)
        mean_dirs = (mean_dirs / np.linalg.norm(mean_dirs, axis=1, keepdims=True)).astype(np.float32)
    return LiModel(factor=factor, shape=(h, w), coarse_normal=coarse.normal, coarse_info=coarse.info,
                   offsets=offsets, dark=dark, choice=choice, mean_dirs=mean_dirs)
