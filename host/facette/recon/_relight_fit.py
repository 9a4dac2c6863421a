"""Fitting the relighting model (`recon._relight_model`): `fit_relight_bands` from a band reader,
`fit_relight_model` from whole images (the same fit, the images read as one band).

The photographs are read a band of rows at a time (read(r0, r1) -> (linear (m, r1 - r0, W, 3),
display values of the same shape or None)), in three passes:

0. a sample of the object's pixels, evenly spread in raster order (`SAMPLE` for the choices,
   `WHITE_SAMPLE` for the white): the white (when not given: the WHITE_PERCENTILE of the brightest
   channel), the lobe's exponent, and whether cast shadows are kept (shadows="auto"): the model
   fitted to the sample with and without them, the one whose residual predicts the fitted lights
   left out better (its leave-one-light-out error, as the whole fit judges it) kept. One fit
   then, not one with and one without (bench relight's captures: the same choice, half the time);
1. each band's physics maps, solved by blocks of pixels, and the residual's gram over the lights
   summed block after block;
2. the residual planes (the residual of each block projected on the gram's eigenvectors).

Each pixel's maps depend on that pixel's values alone and the gram is a sum over pixels: any
band height gives the whole fit's model (within float32 rounding of the sums). Held at the
image's size: the mask, the normals, the three maps, the planes (float16) and the cast shadows'
visibility (per light, uint8, on `cast_shadow`'s grid of at most 1 MP); with `spill`, the normals,
maps and planes are in temporary files (`_memory.disk_array`, 12 + 36 + 6 x planes bytes a pixel),
written a band at a time and their pages handed back after each band: the mask (1 byte a pixel)
stays in memory.
"""
import numpy as np
from threadpoolctl import threadpool_limits

from facette._memory import disk_array, release

from ._relight_model import (BLOCK_VALUES, SATURATED, SHADOW_SOFTNESS, SHININESS, RelightModel, _fit_block,
                             _kernel, _kernel_choice, _predict, cast_shadow, default_planes, physical_basis)
from ._rti import hsh_basis, srgb_encode

__all__ = ["fit_relight_bands", "fit_relight_model", "WHITE_PERCENTILE"]

SAMPLE = 20_000             # the object's pixels the exponent and the shadows are chosen on
WHITE_SAMPLE = 200_000      # the object's pixels the white is taken from
EXPONENT_ONCE = True        # shadows "auto": judged with the exponent of the fit without them (chosen again if kept)
WHITE_PERCENTILE = 99.9     # the white: this percentile of the sample's brightest channel over the lights


CLEAN_PIXELS = 1 << 22      # pixels of the normals cleaned at a time (`_cleaned`)


def fit_relight_model(images, light_dirs, mask, normals, heights=None, n_planes=None, shown=None, white=1.0,
                      shadows="auto"):
    """The model fitted to whole images: `fit_relight_bands` reading them as one band.

    images : (m, H, W, 3) linear, scaled so that 1 is the display's white (values above 1 are
    clipped in display); light_dirs : (m, 3) unit; mask (H, W); normals (H, W, 3) unit, camera
    frame; heights : (H, W) in pixels (integrated normals) for cast shadows, or None; shown :
    the display values (m, H, W, 3) if known (8-bit photographs), else sRGB of the clipped images;
    white : the images' value shown as white (None: chosen, see `fit_relight_bands`)."""
    def read(r0, r1):
        return images[:, r0:r1], None if shown is None else shown[:, r0:r1]
    return fit_relight_bands(read, light_dirs, mask, normals, heights, n_planes, white, shadows)


class _Shadows:
    """Each light's cast-shadow visibility (`cast_shadow`) as uint8 (0..255), kept on its march's
    grid (every st-th pixel, at most 1 MP) and repeated to a band's rows on demand."""

    def __init__(self, heights, dirs, max_pixels=1 << 20):
        h = np.asarray(heights, np.float32)
        self.shape = h.shape
        self.st = st = int(np.ceil(np.sqrt(h.size / max_pixels)))
        small = h[::st, ::st] / np.float32(st) if st > 1 else h
        self.vis = np.stack([np.round(cast_shadow(small, d, SHADOW_SOFTNESS / st, max_pixels=max_pixels) * 255)
                             .astype(np.uint8) for d in dirs])

    def rows(self, r0, r1):
        """(m, r1 - r0, W) uint8 of rows r0..r1."""
        st = self.st
        if st == 1:
            return self.vis[:, r0:r1]
        part = self.vis[:, r0 // st:-(-r1 // st)]
        part = np.repeat(np.repeat(part, st, axis=1), st, axis=2)
        return part[:, r0 - (r0 // st) * st:r1 - (r0 // st) * st, :self.shape[1]]

    def at(self, rows, cols):
        """(m, n) uint8 at image pixels (rows, cols)."""
        return self.vis[:, np.asarray(rows) // self.st, np.asarray(cols) // self.st]


def _cleaned(normals, mask, spill=False):
    """(mask (H, W) bool where the normal is finite too, normals (H, W, 3) float32, 0 outside it), made
    CLEAN_PIXELS at a time (normals may be a disk array: its pages handed back after each band); the
    normals in a disk array with `spill`."""
    mask = np.asarray(mask, bool)
    h, w = mask.shape
    ok = np.empty((h, w), bool)
    n = disk_array((h, w, 3), np.float32) if spill else np.empty((h, w, 3), np.float32)
    rows = max(1, CLEAN_PIXELS // max(w, 1))
    for r0 in range(0, h, rows):
        band = np.asarray(normals[r0:r0 + rows], np.float32)
        good = mask[r0:r0 + rows] & np.all(np.isfinite(band), axis=-1)
        ok[r0:r0 + rows] = good
        n[r0:r0 + rows] = np.where(good[..., None], np.nan_to_num(band), np.float32(0))
        release(normals), release(n)
    return ok, n


class _Fit:
    """What the passes share: the lights, the normals, the mask, the bands, the terms; spill: the
    image-sized arrays in temporary files (see the module's docstring)."""

    def __init__(self, read, light_dirs, mask, normals, rows, spill=False):
        dirs = np.asarray(light_dirs, float)
        self.dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        self.read, self.m, self.spill = read, len(self.dirs), spill
        self.mask, self.n = _cleaned(normals, mask, spill)
        h = self.mask.shape[0]
        rows = h if rows is None else max(1, int(rows))
        self.spans = [(r0, min(h, r0 + rows)) for r0 in range(0, h, rows)]
        self.counts = [int(np.count_nonzero(self.mask[r0:r1])) for r0, r1 in self.spans]
        self.total = sum(self.counts)
        # as many terms as the lights support: the lobe and the room's light need a dozen lights
        self.terms = (0, 1, 2) if self.m >= 12 else (0,)

    def values(self, lin, shown, r, c, white):
        """(linear, display) values (m, n, C) float32 of some pixels of a band; unknown = white."""
        y = np.nan_to_num(lin[:, r, c].astype(np.float32) / np.float32(white), nan=1.0)
        s = srgb_encode(np.clip(y, 0, 1)) if shown is None else np.asarray(shown[:, r, c], np.float32)
        return y, s.astype(np.float32)

    def basis(self, rr, cc, k, vis):
        """The physical basis (m, n, 3) at image pixels (rr, cc); vis (m, n) uint8 or None."""
        return physical_basis(self.n[rr, cc], self.dirs, k, None if vis is None else vis / np.float32(255))

    def blocks(self, n):
        step = max(4096, BLOCK_VALUES // max(self.m, 1))
        return [slice(a, min(a + step, n)) for a in range(0, n, step)]

    def zeros(self, shape, dtype):
        """An image-sized array of zeros: in a temporary file with `spill`."""
        return disk_array(shape, dtype) if self.spill else np.zeros(shape, dtype)


def _sample(fit, picks, white_picks):
    """Pass 0: (rows, cols, linear (m, n, 3), display or None) of the pixels `picks` (indices
    into the object's pixels in raster order) and the brightest channel (m, n') of `white_picks`."""
    want = np.union1d(picks, white_picks)
    out_r, out_c, lin, shown, top = [], [], [], [], []
    start = 0
    for (r0, r1), count in zip(fit.spans, fit.counts):
        here = want[(want >= start) & (want < start + count)] - start
        start += count
        if not here.size:
            continue
        imgs, disp = fit.read(r0, r1)
        r, c = np.nonzero(fit.mask[r0:r1])
        r, c = r[here], c[here]
        out_r.append(r + r0), out_c.append(c)
        lin.append(np.asarray(imgs[:, r, c], np.float32))
        shown.append(None if disp is None else np.asarray(disp[:, r, c], np.float32))
        top.append(np.max(lin[-1], axis=-1))
    rows, cols = np.concatenate(out_r), np.concatenate(out_c)
    lin, top = np.concatenate(lin, axis=1), np.concatenate(top, axis=1)
    shown = None if shown[0] is None else np.concatenate(shown, axis=1)
    at = np.searchsorted(want, picks)
    return (rows[at], cols[at], lin[:, at], None if shown is None else shown[:, at]), \
        top[:, np.searchsorted(want, white_picks)]


def _white_of(top):
    vals = top[np.isfinite(top) & (top > 0)]
    return float(np.percentile(vals, WHITE_PERCENTILE)) if vals.size else 1.0


def _sample_choice(fit, sample, white, shadow, n_planes, exponents=SHININESS, done=None):
    """(exponent, leave-one-light-out error) of the model fitted to the sample pixels alone
    (with the cast shadows `shadow`, a _Shadows, or None), the exponent the best of `exponents`.
    done: {(exponent, shadows or not): (error, prediction)} of the fits made already (filled here):
    the shadows' judgement fits the exponent chosen without them, and the choice with them again."""
    r, c, lin, shown = sample
    vis = None if shadow is None else shadow.at(r, c)
    y, s = fit.values(lin[:, None], None if shown is None else shown[:, None], 0, slice(None), white)   # (m, n, C)
    best, done = None, {} if done is None else done
    for k in exponents if 1 in fit.terms else SHININESS[:1]:
        if (k, shadow is None) not in done:
            b = fit.basis(r, c, k, vis)
            pred = _predict(b, _fit_block(y, s, b, fit.terms))
            ok = np.all(s < SATURATED, axis=-1)[..., None]
            done[k, shadow is None] = float(np.sum(ok * (srgb_encode(np.clip(pred, 0, 1)) - s) ** 2)), pred
        err, pred = done[k, shadow is None]
        if best is None or err < best[0]:
            best = (err, k, pred)
    _, k, pred = best
    if n_planes is None:
        return k, None
    rows = (s - srgb_encode(np.clip(pred, 0, 1))).transpose(1, 2, 0).reshape(-1, fit.m).astype(np.float64)
    gram = rows.T @ rows
    evals, evecs = np.linalg.eigh(gram)
    funcs, energy = evecs[:, ::-1][:, :n_planes], np.clip(evals[::-1][:n_planes], 0, None)
    loo = _kernel_choice((funcs * energy) @ funcs.T, fit.dirs, _spacing(fit.dirs)[0])[1]
    return k, loo + float(np.trace(gram) - energy.sum())


def _spacing(dirs):
    """(median nearest-neighbour distance of the lights' (x, y), their largest |(x, y)|)."""
    xy = dirs[:, :2]
    dist = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    return float(np.median(dist.min(axis=1))), float(np.max(np.linalg.norm(xy, axis=1)))


def fit_relight_bands(read, light_dirs, mask, normals, heights=None, n_planes=None, white=1.0, shadows="auto",
                      rows=None, spill=False):
    """The relighting model (`RelightModel`) fitted from a band reader (see the module's docstring).

    read(r0, r1) -> (linear (m, r1 - r0, W, 3), display values or None), linear scaled so that
    `white` is the display's white (None: chosen, WHITE_PERCENTILE); light_dirs (m, 3); mask,
    normals, heights (H, W[, 3]) whole (heights in pixels, or None: no cast shadows); rows: the
    band height (None: one band); shadows "auto" (with heights: kept where the sample says they
    predict the fitted lights left out better), True: kept, False: none. spill: the model's normals,
    maps and planes in temporary files (numpy memmaps: the model holds them; gone with it)."""
    fit = _Fit(read, light_dirs, mask, normals, rows, spill)
    m = fit.m
    planes = 0 if m < 3 else min(default_planes(m, fit.total), m if n_planes is None else int(n_planes))
    if fit.total == 0:
        zero = np.zeros(fit.mask.shape + (3,), np.float32)
        return RelightModel(fit.n, fit.mask, zero, zero, zero, SHININESS[0], white=float(white or 1.0),
                            notes=["no pixel of the object has a normal: nothing fitted"])
    with threadpool_limits(limits=1, user_api="blas"):     # tall products: threads only wait on a busy machine
        picks = np.linspace(0, fit.total - 1, min(SAMPLE, fit.total)).astype(int)
        white_picks = np.linspace(0, fit.total - 1, min(WHITE_SAMPLE, fit.total)).astype(int)
        sample, top = _sample(fit, picks, white_picks)
        white = _white_of(top) if white is None else float(white)
        shadow = None if heights is None or shadows is False else _Shadows(heights, fit.dirs)
        judge = planes if planes > 0 else None
        notes = []
        if shadow is not None and shadows == "auto" and judge is not None:
            # the shadows judged with the exponent chosen without them (EXPONENT_ONCE); kept, their own
            done = {}               # the fits of the sample made: not made again
            k_flat, loo_flat = _sample_choice(fit, sample, white, None, judge, done=done)
            k, loo = _sample_choice(fit, sample, white, shadow, judge, (k_flat,) if EXPONENT_ONCE else SHININESS,
                                    done=done)
            if loo_flat < loo:
                notes.append(f"no cast shadows: without them the fitted lights left out are predicted better "
                             f"(on {len(picks)} pixels: {loo_flat:.4g} against {loo:.4g})")
                shadow, k = None, k_flat
            elif EXPONENT_ONCE:
                k = _sample_choice(fit, sample, white, shadow, None, done=done)[0]
        else:
            k = _sample_choice(fit, sample, white, shadow, None)[0]
        return _fit_passes(fit, k, shadow, white, heights if shadow is not None else None, planes, notes)


def _fit_passes(fit, k, shadow, white, heights, n_planes, notes):
    """Passes 1 and 2: the maps and the residual's gram, then the planes."""
    m, mask = fit.m, fit.mask
    maps = fit.zeros((3,) + mask.shape + (3,), np.float32)

    def band_blocks(r0, r1):     # (rows, cols, linear, display, basis) of each block of a band
        lin, shown = fit.read(r0, r1)
        vis = None if shadow is None else shadow.rows(r0, r1)
        r, c = np.nonzero(mask[r0:r1])
        for b in fit.blocks(len(r)):
            rr, cc = r[b], c[b]
            y, s = fit.values(lin, shown, rr, cc, white)
            yield rr + r0, cc, y, s, fit.basis(rr + r0, cc, k, None if vis is None else vis[:, rr, cc])

    def residual(rr, cc, s, basis):      # (n_b * 3, m): display values minus srgb(phys), per light
        x = np.stack([maps[j, rr, cc] for j in range(3)], axis=1)             # (n_b, 3, C)
        phys = _predict(basis, x)
        return (s - srgb_encode(np.clip(phys, 0, 1))).transpose(1, 2, 0).reshape(-1, m).astype(np.float64)

    gram = np.zeros((m, m))
    for r0, r1 in fit.spans:
        for rr, cc, y, s, basis in band_blocks(r0, r1):
            maps[:, rr, cc] = _fit_block(y, s, basis, fit.terms).transpose(1, 0, 2)
            if n_planes > 0:
                rows = residual(rr, cc, s, basis)
                gram += rows.T @ rows
        release(maps), release(fit.n)          # spilled: the band's pages handed back
    model = RelightModel(fit.n, mask, maps[0], maps[1], maps[2], float(k),
                         None if heights is None else np.asarray(heights, np.float32), white=float(white),
                         notes=notes)
    if n_planes <= 0:
        return model
    evals, evecs = np.linalg.eigh(gram)
    funcs = evecs[:, ::-1][:, :n_planes]                                 # (m, K): the light functions
    energy = np.clip(evals[::-1][:n_planes], 0, None)
    model.spacing, model.reach = _spacing(fit.dirs)
    # the kernel judged on the residual the planes keep (what the model will interpolate)
    choice, loo = _kernel_choice((funcs * energy) @ funcs.T, fit.dirs, model.spacing)
    # the model's error at the fitted lights left out: the planes' (interpolated) and what they leave
    model.loo_error = loo + float(np.trace(gram) - energy.sum())
    if choice is None:
        model.notes.append("no residual: interpolating it did not predict the fitted lights left out")
        return model
    eps, mix, ridge = choice
    # float16: 5e-4 of white where 8-bit display steps are 4e-3 (half the memory at 12 MP)
    model.planes = fit.zeros(mask.shape + (3, funcs.shape[1]), np.float16)
    for r0, r1 in fit.spans:
        for rr, cc, _, s, basis in band_blocks(r0, r1):
            model.planes[rr, cc] = (residual(rr, cc, s, basis) @ funcs).reshape(-1, 3, funcs.shape[1])
        release(model.planes), release(maps), release(fit.n)
    weights = np.linalg.solve(_kernel(fit.dirs, fit.dirs, eps, mix) + ridge * np.eye(m), funcs)      # (m, K)
    model.centres, model.weights, model.epsilon = fit.dirs[:, :2], weights, eps
    model.trend = mix * (hsh_basis(fit.dirs, 2).T @ weights) if mix else None                   # (4, K)
    return model
