"""Exports for the tools people already use: RTIViewer (PTM LRGB, HSH .rti) and glTF 2.0 viewers.

The fits live in `facette.recon` (fit_ptm_lrgb, fit_hsh), the file layouts in `facette.io`
(ptm, rti, gltf); this module prepares what the glTF material needs from a process result:
sRGB base colour, a tangent-space normal map and the roughness that stands for the LI σ.
"""
import warnings

import numpy as np
from scipy.ndimage import uniform_filter

from facette._memory import decimated, release
from facette.fit import is_metal
from facette.recon import srgb_encode as srgb_transfer

__all__ = ["hsh_order_for", "fill_unfitted", "fill_left", "unfitted_verdict", "gltf_roughness", "srgb_encode",
           "vertex_normals", "vertex_tangents", "tangent_space_normal_map", "gltf_material", "gltf_inputs",
           "GLTF_TEXTURE_MAX", "texture_step", "block_means"]

ROWS = 64                  # image rows of the normal map made at a time
TEXEL_ROWS = 512           # texel rows of block-mean textures made at a time
PTM_TERMS = 6
# The glTF's textures are at most this many texels on their long side: a 100 MP map is a
# 0.3 GB texture few viewers load (WebGL's usual limit is 16384, phones' 4096-8192), and the
# full-size maps are beside it (normal.exr, albedo.exr). A 12 MP scan's keep its full size.
GLTF_TEXTURE_MAX = 8192
SCALE_PIXELS = 16e6         # pixels the base colour's scale (a percentile of the albedo) is taken from


def hsh_order_for(n_lights, asked):
    """(the HSH order relight.rti can be fitted at with `n_lights` lights, note or None).

    An order needs at least as many lights as terms (order²): with fewer, every pixel's fit
    is undetermined and the file would be all zeros. `asked` when the lights allow it, else
    order 2 (4 terms) with at least 4 lights, else None (relight.rti is not written)."""
    if n_lights >= asked * asked:
        return asked, None
    if n_lights >= 4:
        return 2, (f"relight.rti: HSH order 2 (4 terms) instead of {asked} ({asked * asked} terms): "
                   f"{n_lights} lights cannot determine {asked * asked} terms")
    return None, (f"relight.rti not written: {n_lights} light(s) cannot determine even the 4 terms of "
                  "HSH order 2 (scan at least 4 lights)")


def fill_unfitted(fit, images, mask, name):
    """Give the masked pixels the fit left out (fewer usable lights than its terms: zero
    coefficients, black in a viewer) their mean value as a constant term, in place; they
    then look as the object does under average light, without relighting.

    fit : a recon `PTMFit` or `HSHFit`; images (m, H, W, 3) as fitted; mask (H, W) bool;
    name : the file name for the note. Returns (write, note): write False when no masked
    pixel could be fitted (the file would say nothing: it is not written)."""
    mask = np.asarray(mask, bool)
    write, note = unfitted_verdict(fit, int((mask & ~np.asarray(fit.valid, bool)).sum()), int(mask.sum()), name)
    if write:
        fill_left(fit, images, mask)
    return write, note


def unfitted_verdict(fit, n_left, n_mask, name):
    """`fill_unfitted`'s (write, note) for n_left of n_mask masked pixels left out by the fit
    (the counts of a whole image, or summed over its bands)."""
    ptm = fit.coeffs.ndim == 3
    terms = PTM_TERMS if ptm else fit.coeffs.shape[-1]
    if n_mask == 0 or n_left == n_mask:
        return False, (f"{name} not written: no pixel of the mask has the {terms} usable lights its "
                       f"{'HSH' if getattr(fit, 'order', None) else 'PTM'} fit needs")
    if n_left == 0:
        return True, None
    return True, (f"{name}: {n_left} of {n_mask} masked pixels ({n_left / n_mask:.1%}) have fewer than "
                  f"{terms} usable lights; they keep their mean value (no relighting there)")


def fill_left(fit, images, mask):
    """`fill_unfitted`'s filling of the masked pixels the fit left out, in place, whatever their
    share (a band of an image: the verdict waits for every band). Returns (left out, masked)."""
    mask = np.asarray(mask, bool)
    left = mask & ~np.asarray(fit.valid, bool)
    n_left, n_mask = int(left.sum()), int(mask.sum())
    ptm = fit.coeffs.ndim == 3
    terms = PTM_TERMS if ptm else fit.coeffs.shape[-1]
    if n_left == 0:
        return n_left, n_mask
    vals = np.asarray(images)[:, left].astype(np.float64) / fit.white      # (m, n, 3), as fitted
    if getattr(fit, "encoding", "linear") == "srgb":                         # the displayed values
        vals = srgb_transfer(np.clip(vals, 0.0, 1.0))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)                       # all-NaN: 0 below
        if ptm:       # L of each sample: its projection on the pixel's colour (as the fit takes it)
            rgb = fit.rgb[left].astype(np.float64)
            lum = (vals * rgb).sum(-1) / np.maximum((rgb * rgb).sum(-1), 1e-12)
            const = np.nan_to_num(np.nanmean(lum, axis=0))
            coeffs = np.zeros((n_left, PTM_TERMS), fit.coeffs.dtype)
            coeffs[:, 5] = const                                      # a5: the constant term
        else:
            k = fit.CONSTANT             # HSH's Y00, a per-channel PTM's a5
            y00 = float(fit.basis(np.array([0.0, 0.0, 1.0]))[k])
            mean = np.nan_to_num(np.nanmean(vals, axis=0))                     # (n, 3)
            coeffs = np.zeros((n_left, 3, terms), fit.coeffs.dtype)
            coeffs[:, :, k] = mean / y00
    fit.coeffs[left] = coeffs
    return n_left, n_mask


def gltf_roughness(sigma, distribution="beckmann"):
    """glTF metallic-roughness `roughness` in [0, 1] for a microfacet roughness σ.

    glTF evaluates GGX with α = roughness² (glTF 2.0 spec, Appendix B). The LI fit's
    Beckmann σ is an RMS slope; Beckmann and GGX of the same α have the same peak
    D(n) = 1 / (π α²) and the same mean-square slope to first order (Walter et al. 2007
    compare them at equal α), so α_GGX = σ and roughness = √σ. A Gaussian σ is an angle
    (rad): exp(-θ²/2σ²) ≈ Beckmann with slope √2 σ, so roughness = (√2 σ)^½. GGX: √σ.
    Clipped to [0, 1] (σ > 1 is rougher than glTF can say).
    """
    s = np.asarray(sigma, dtype=float)
    if np.any(~np.isfinite(s)) or np.any(s < 0):
        raise ValueError(f"sigma must be finite and >= 0, got {sigma}")
    if distribution == "gaussian":
        s = np.sqrt(2.0) * s
    elif distribution not in ("beckmann", "ggx"):
        raise ValueError(f"unknown microfacet distribution {distribution!r}: beckmann, ggx or gaussian")
    return np.clip(np.sqrt(s), 0.0, 1.0)


def srgb_encode(linear):
    """Linear values in [0, 1] (clipped) -> sRGB-encoded uint8 (IEC 61966-2-1).
    In float32: 8-bit output needs no more (12 MP albedo: 0.2 s instead of 1.2 in float64;
    1 value in 10⁵ rounds to the neighbouring byte)."""
    x = np.clip(np.nan_to_num(np.asarray(linear, np.float32)), 0.0, 1.0)
    y = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, np.float32(1 / 2.4)) - 0.055)
    return np.round(y * 255.0).astype(np.uint8)


def vertex_normals(vertices, faces):
    """Area-weighted vertex normals (V, 3) of a triangle mesh (faces counter-clockwise)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])   # |fn| = 2 · area
    n = np.zeros_like(v)
    for k in range(3):            # bincount: ~1.5x faster than np.add.at
        for c in range(3):
            n[:, c] += np.bincount(f[:, k], weights=fn[:, c], minlength=len(v))
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(norm > 0, n / np.where(norm > 0, norm, 1), [0.0, 0.0, 1.0])


def vertex_tangents(normals):
    """Tangents (V, 4) along +x (the texture's +u) made orthogonal to each normal, w = +1, so
    that glTF's bitangent cross(n, t) points along +y (image up)."""
    n = np.asarray(normals, np.float64)
    t = np.array([[1.0, 0.0, 0.0]]) - n * n[:, :1]          # e_x - (e_x · n) n
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(norm > 1e-9, t / np.where(norm > 1e-9, norm, 1), [1.0, 0.0, 0.0])
    return np.concatenate([t, np.ones((len(n), 1))], axis=1)


def tangent_space_normal_map(normals, height_mm, mask, pixel_pitch_mm, step=1):
    """Normal-map texture (H, W, 3) uint8 of the photometric-stereo normals relative to the
    mesh they will be draped on.

    normals (H, W, 3) camera frame; height_mm (H, W); mask (H, W) bool; step: the mesh's
    vertex step (px). The mesh surface at each pixel is that of the height smoothed over
    `step` px: N = (-h_x, -h_y, 1)/|.|, T = (1, 0, h_x)/|.|, B = N × T; the texel is
    (n·T, n·B, n·N) mapped to (x + 1)/2 · 255, and (0, 0, 1) outside the mask.
    """
    h = mask.shape[0]
    out = np.empty(mask.shape + (3,), np.uint8)
    up = np.array([0.0, 0.0, 1.0], np.float32)
    halo = step + 2          # rows the smoothing and the gradient reach beyond a band
    # by bands of ROWS rows with their halo (a 50 MP height map in float64 and its two gradients
    # held whole were 1.6 GB); float32 by rows, channel by channel: 8-bit texels need no more
    # (12 MP: 0.2 s, 0.6 before; 1 texel value in 10⁵ moves by one step)
    for r in range(0, h, ROWS):
        a, b = max(0, r - halo), min(h, r + ROWS + halo)
        hgt = np.where(mask[a:b], np.asarray(height_mm[a:b], np.float64), 0.0)
        if step > 1:
            hgt = uniform_filter(hgt, size=step, mode="nearest")
        if hgt.shape[0] > 1:
            gy, gx = (g[r - a:r - a + ROWS].astype(np.float32) for g in np.gradient(hgt, pixel_pitch_mm))
        else:                # a one-row image: no slope across its rows
            gx = np.gradient(hgt, pixel_pitch_mm, axis=1).astype(np.float32)
            gy = np.zeros_like(gx)
        sl = slice(r, r + ROWS)
        hx, hy = gx, -gy                             # image rows go down, y goes up
        inv_n = 1 / np.sqrt(hx * hx + hy * hy + 1)   # N = (-hx, -hy, 1)·inv_n
        inv_t = 1 / np.sqrt(hx * hx + 1)             # T = (1, 0, hx)·inv_t
        n = np.asarray(normals[sl], np.float32)
        nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
        # B = N × T = (-hy·hx, hx² + 1, hy)·inv_n·inv_t
        ts = np.stack([(nx + nz * hx) * inv_t,
                       (-nx * hy * hx + ny * (hx * hx + 1) + nz * hy) * inv_n * inv_t,
                       (-nx * hx - ny * hy + nz) * inv_n], -1)
        ok = mask[sl] & (nx * nx + ny * ny + nz * nz > 0.25)
        ts = np.where(ok[..., None], ts, up)
        ts /= np.maximum(np.sqrt((ts * ts).sum(-1, keepdims=True)), np.float32(1e-12))
        out[sl] = np.round((ts + 1) * np.float32(127.5)).clip(0, 255)
        release(normals)                             # a disk map: its pages handed back
    return out


def gltf_material(res):
    """What the glTF material takes from a `ProcessResult` and the notes that say so (cheap:
    the report lists the notes while `gltf_inputs` builds the arrays): a dict with the base
    colour's per-channel `scale`, the roughness `r` (None: 1 everywhere), the `ior`, a metal's
    `metal_f0` and, when the run has a relighting model, its per-pixel `maps`
    (pipeline._gltf_maps), and notes."""
    notes = []
    f = texture_step(res.mask.shape)
    if f > 1:
        h, w = res.mask.shape
        notes.append(f"glTF textures {-(-w // f)} x {-(-h // f)} (block means of {f} x {f} pixels; the "
                     "full-size maps are normal.exr and albedo.exr)")
    from facette.pipeline._gltf_maps import relight_maps      # it builds on this module's textures
    maps, map_notes = relight_maps(res)
    r, ior, metal_f0, brdf_notes = _brdf_material(res)
    if maps is not None:          # per-pixel K_d, F0 and roughness: the relighting model's
        if metal_f0 is not None:  # the BRDF fit's verdict: a metal (glTF's metal: F0 is its base colour)
            map_notes.append(f"glTF: metallic 1, base colour F0 = {metal_f0:.2f} on the fitted pixels (the BRDF fit "
                             "found a metal's lobe stronger than its diffuse part); roughness from the model")
        return {"scale": maps["scale"], "r": None, "ior": None, "metal_f0": metal_f0, "maps": maps}, \
            notes + map_notes
    notes += map_notes
    # the scale from every st-th row and column (the same distribution), of at most ~SCALE_PIXELS:
    # a 50 MP albedo's masked values in float64 and the percentile's copies were 4 GB
    st = max(f, int(np.ceil(np.sqrt(res.mask.size / SCALE_PIXELS))))
    albedo, mask = decimated(res.albedo, st), res.mask[::st, ::st]
    top = 1.0
    if mask.any():
        vals = np.nan_to_num(albedo[mask].astype(np.float64), copy=False)
        del albedo
        top = float(np.percentile(vals, 99.5, overwrite_input=True))
    if top > 1.0:
        notes.append(f"glTF base colour: albedo divided by {top:.3g} (its 99.5th percentile) to fit [0, 1]")
    return {"scale": np.full(3, 1.0 / max(top, 1.0)), "r": r, "ior": ior, "metal_f0": metal_f0}, notes + brdf_notes


def _brdf_material(res):
    """(roughness or None, IOR or None, a metal's F0 or None, notes) of the BRDF fit (one material)."""
    notes = []
    r, ior, metal_f0 = None, None, None
    fit = res.brdf
    params = getattr(fit, "params", None) or {}
    if fit is not None and getattr(fit, "success", False) and "sigma" in params and \
            getattr(fit, "model", "") in ("li", "cook_torrance"):
        dist = getattr(fit, "distribution", None) or "beckmann"
        r = float(gltf_roughness(float(np.mean(params["sigma"])), dist))
        ior = params.get("n_i")
        what = f"glTF roughness = sqrt(sigma) = {r:.3g} (sigma = {float(np.mean(params['sigma'])):.3g}, {dist}); "
        if ior is not None and is_metal(ior):
            # a metal's lobe: its index stands for the metal's F0 (no dielectric's IOR); glTF's metal
            # has no diffuse part, so a lobe weaker than the diffuse part (a metallic paint) stays
            # a dielectric of the same roughness
            f0 = ((ior - 1) / (ior + 1)) ** 2
            kd = float(np.mean(params.get("kd", 0.0)))
            ior = None
            if f0 > kd:
                metal_f0 = f0
                notes.append(what + f"metallic 1, base colour F0 = {f0:.2f} (a metal's lobe, n_i "
                             f"{params['n_i']:.3g}; K_d {kd:.2f} dropped)")
            else:
                notes.append(what + f"metallic 0, no IOR: a metal's lobe (F0 {f0:.2f}) beside a stronger "
                             f"diffuse part (K_d {kd:.2f}), which glTF's metal cannot hold")
        else:
            notes.append(what + "metallic 0" + (f"; IOR = n_i = {ior:.3g}" if ior else ""))
    else:
        notes.append("glTF roughness 1 (no successful microfacet BRDF fit to take sigma from)")
    return r, ior, metal_f0, notes


def gltf_inputs(res, step, material=None):
    """Keyword arguments of `facette.io.gltf.write_glb` for a `ProcessResult` with a mesh,
    and notes for the report. The roughness texture carries √σ on the material the BRDF was
    fitted to and 1 elsewhere; metallic is 0 (a dielectric: the LI n_i becomes the IOR) unless the
    fit is a metal's lobe stronger than its diffuse part (`gltf_material`).
    material : `gltf_material(res)`'s dict when already made (its notes are then not repeated)."""
    notes = []
    if material is None:
        material, notes = gltf_material(res)
    verts, faces = res.mesh
    if len(faces) == 0:
        raise ValueError("the mesh has no triangles (is the mask empty?); nothing to export as glTF")
    h, w = res.mask.shape
    f = texture_step((h, w))
    pitch = res.inputs.pixel_pitch_mm
    # texel j covers pixels [j f, (j + 1) f): pixel x's centre at u = (x + 0.5) / (f · texels)
    th, tw = -(-h // f), -(-w // f)
    uv = np.stack([(verts[:, 0] / pitch + 0.5) / (f * tw), (-verts[:, 1] / pitch + 0.5) / (f * th)], axis=1)
    normals = vertex_normals(verts, faces)
    fitted_px = res.inputs.sample_mask() & res.mask
    maps = material.get("maps")
    kd = res.albedo if maps is None else maps["kd"]       # the base colour's source, at full size
    if f == 1:              # full size: the maps as they are (on disk with --memory), read by bands
        mask, fitted = res.mask, fitted_px
        base = _base_colour(kd, fitted, material)
        normal_map = tangent_space_normal_map(res.normals, res.height, mask, pitch, step)
    else:
        mask, fitted, base, normal_map = _block_textures(res, kd, fitted_px, f, material, pitch, step)
    extras = {"scan_incomplete": res.inputs.incomplete} if res.inputs.incomplete else None
    kw = dict(vertices_mm=verts, faces=faces, normals=normals, tangents=vertex_tangents(normals), uv=uv,
              base_color=base, normal_map=normal_map, extras=extras)
    if maps is not None:
        from facette.pipeline._gltf_maps import model_textures
        mr, specular = model_textures(maps, metal=material["metal_f0"] is not None)
        return dict(kw, metallic_roughness=mr, specular=specular), notes
    ior = material["ior"]
    mr = np.zeros(mask.shape + (3,), np.uint8)
    mr[..., 0] = 255                                        # unused (occlusion lives elsewhere)
    mr[..., 1] = 255                                        # roughness 1 where no fit says otherwise
    if material["r"] is not None:
        mr[..., 1][fitted] = np.round(np.float32(material["r"]) * 255).astype(np.uint8)
    if material.get("metal_f0") is not None:                # metallic in B; a metal's colour is its F0
        mr[..., 2] = np.where(fitted, 255, 0).astype(np.uint8)
    return dict(kw, metallic_roughness=mr, ior=None if ior is None else float(ior)), notes


def _block_textures(res, kd, fitted_px, f, material, pitch, step):
    """(texel mask, fitted texels, base colour, normal map) of the maps' f x f block means, made a
    band of TEXEL_ROWS texel rows at a time (the normal map's band with the halo its smoothing and
    gradient reach; the same bytes as whole): 100 MP held 0.7 GB of float block means at once."""
    h, w = res.mask.shape
    th, tw = -(-h // f), -(-w // f)
    mask, fitted = np.zeros((th, tw), bool), np.zeros((th, tw), bool)
    base, normal_map = np.empty((th, tw, 3), np.uint8), np.empty((th, tw, 3), np.uint8)
    step_t = max(1, round(step / f))
    halo = step_t + 2
    for t0 in range(0, th, TEXEL_ROWS):
        t1 = min(th, t0 + TEXEL_ROWS)
        a, b = max(0, t0 - halo), min(th, t1 + halo)
        rows = slice(a * f, b * f)
        # the fitted pixels as one more map: its block mean > 1/2 is "most of the block" (fitted ⊂ mask)
        (albedo, n_small, height, share), count = block_means(
            (kd[rows], res.normals[rows], res.height[rows], fitted_px[rows]), res.mask[rows], f)
        inner = slice(t0 - a, t1 - a)
        m = count > 0
        mask[t0:t1] = m[inner]
        fitted[t0:t1] = share[inner, :, 0] > 0.5
        base[t0:t1] = _base_colour(albedo[inner], fitted[t0:t1], material)
        n_small /= np.maximum(np.linalg.norm(n_small, axis=-1, keepdims=True), np.float32(1e-12))
        normal_map[t0:t1] = tangent_space_normal_map(n_small, height[..., 0], m, pitch * f, step_t)[inner]
    return mask, fitted, base, normal_map


def _base_colour(albedo, fitted, material):
    """(H, W, 3) uint8 sRGB base colour of `albedo` (in memory or on disk) times the material's
    per-channel scale, F0 on the `fitted` texels of a metal; a band of rows at a time (no full-size
    float copy)."""
    base = np.empty(albedo.shape[:2] + (3,), np.uint8)
    scale = np.asarray(material["scale"], np.float32)
    for r0 in range(0, base.shape[0], ROWS):
        band = np.nan_to_num(np.asarray(albedo[r0:r0 + ROWS], np.float32))
        if np.any(scale != 1):
            band = band * scale
        if material.get("metal_f0") is not None:
            band[fitted[r0:r0 + ROWS]] = np.float32(material["metal_f0"])
        base[r0:r0 + ROWS] = srgb_encode(band)
        release(albedo)
    return base


def texture_step(shape):
    """Pixels per glTF texel along each side: 1 up to GLTF_TEXTURE_MAX on the long side."""
    return max(1, -(-max(shape) // GLTF_TEXTURE_MAX))


def block_means(maps, mask, f, rows=None):
    """The means over the `mask`ed pixels of each f x f block (the last ones may be smaller) of
    each of `maps` ((H, W) or (H, W, C); kept on disk or not, read a band at a time): (list of
    (ceil(H/f), ceil(W/f), C) float32 arrays, 0 where a block has no masked pixel; the masked
    pixels per block)."""
    h, w = mask.shape
    starts = np.arange(0, w, f)
    rows = rows or f * max(1, (16 << 20) // (w * 12 * f))   # ~16 MB of float32 RGB per band
    out = [np.zeros((-(-h // f), len(starts), 1 if m.ndim == 2 else m.shape[2]), np.float32) for m in maps]
    count = np.zeros((-(-h // f), len(starts)), np.int32)
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        mk = np.asarray(mask[r0:r1])
        b0, rstarts = r0 // f, np.arange(0, r1 - r0, f)
        count[b0:b0 + len(rstarts)] = np.add.reduceat(np.add.reduceat(mk.astype(np.int32), starts, 1), rstarts, 0)
        for a, o in zip(maps, out):
            band = np.nan_to_num(np.asarray(a[r0:r1], np.float32).reshape(r1 - r0, w, -1)) * mk[..., None]
            o[b0:b0 + len(rstarts)] = np.add.reduceat(np.add.reduceat(band, starts, 1), rstarts, 0)
            release(a)
    for o in out:
        o /= np.maximum(count, 1)[..., None]
    return out, count
