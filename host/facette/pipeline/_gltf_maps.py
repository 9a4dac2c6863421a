"""The glTF material's spatially varying maps, from the relighting model (recon._relight_model).

The model holds, per pixel and channel, a diffuse reflectance ρ and a Blinn–Phong lobe s (n·h)^k
(one exponent k per capture, or a map of them), in display-white units: a pixel's value under a
distant light of irradiance E is ρ (n·l) + s (n·h)^k, with E/π = 1. glTF's metallic-roughness BRDF
(glTF 2.0, Appendix B) gives (c/π) E (n·l) for its base colour c and, for the specular part,
F D V E (n·l) with GGX D(h) of α = roughness², D(n) = 1 / (π α²), and V = 1/4 at n = l = v. So

    base colour c = ρ                                          (the K_d map)
    α = sqrt(2 / (k + 2))                                      (Walter et al. 2007, eq. 33: the Beckmann
                                                                α of Phong exponent k; GGX of the same α,
                                                                as `pipeline._exports.gltf_roughness`)
    roughness = sqrt(α) = (2 / (k + 2))^(1/4)
    F0 = 4 α² s = 8 s / (k + 2)                                (the lobes' peaks equal at n = l = v)

F0 per pixel and colour goes into KHR_materials_specular (specularColorTexture × specularColorFactor
× glTF's F0 of IOR 1.5, 0.04); viewers without the extension keep F0 = 0.04 everywhere, so for them
the roughness texture also carries where the lobe is weaker than glass's: roughness rises from
(2/(k+2))^¼ at F0 ≥ 0.04 linearly to 1 at F0 = 0 (`roughness_of_lobe`). Metallic is 0: the model
has no metals, a coloured lobe is a coloured F0.
"""
import numpy as np

from facette._memory import decimated
from facette.pipeline._exports import block_means, srgb_encode, texture_step

__all__ = ["relight_maps", "ggx_alpha_of_exponent", "roughness_of_lobe", "f0_of_lobe", "model_step",
           "DIELECTRIC_F0", "model_textures"]

DIELECTRIC_F0 = 0.04        # glTF's F0 at its default IOR 1.5: ((1.5 - 1) / (1.5 + 1))²
F0_TOP_PERCENTILE = 99.9    # the specular colour texture's white: a few brightest lobes may clip
BASE_TOP_PERCENTILE = 99.5  # the base colour's: as the albedo's (pipeline._exports.gltf_material)


def ggx_alpha_of_exponent(k):
    """GGX α of a Blinn–Phong exponent k: sqrt(2 / (k + 2)) (Walter et al. 2007, eq. 33)."""
    return np.sqrt(2.0 / (np.asarray(k, np.float64) + 2.0))


def f0_of_lobe(spec, k):
    """F0 (..., C) whose GGX lobe has the peak of the model's s (n·h)^k: 4 α² s (k a number or (...))."""
    return 4.0 * (ggx_alpha_of_exponent(k) ** 2)[..., None] * np.asarray(spec, np.float64)


def roughness_of_lobe(f0, k):
    """glTF roughness (...) of a lobe of exponent k and F0 (..., C): sqrt(α) where the lobe is at
    least glass's (max F0 ≥ DIELECTRIC_F0), rising linearly to 1 as its F0 goes to 0 (what a viewer
    without KHR_materials_specular, whose F0 is 0.04 everywhere, can show of a weaker lobe)."""
    r_k = np.sqrt(ggx_alpha_of_exponent(k))
    weak = np.clip(1.0 - np.max(f0, axis=-1) / DIELECTRIC_F0, 0.0, 1.0)
    return np.clip(r_k + (1.0 - r_k) * weak, 0.0, 1.0)


def model_step(full_shape, model_shape):
    """The st of a model fitted at every st-th pixel of a full_shape image (1: every pixel), or None
    when no step gives model_shape."""
    h, w = full_shape
    for st in range(1, max(h, w) + 1):
        if (-(-h // st), -(-w // st)) == tuple(model_shape):
            return st
    return None


def _gain(albedo, rho, mask, st):
    """Per-channel median of ρ / albedo over the model's pixels (the albedo at the same pixels):
    the albedo in the model's unit, so that its base colour and the model's F0 share one scale."""
    a = decimated(albedo, st).astype(np.float64)[mask].reshape(int(mask.sum()), -1)
    r = np.asarray(rho, np.float64)[mask]
    gain = np.ones(r.shape[-1])
    for c in range(r.shape[-1]):
        ac = a[:, min(c, a.shape[1] - 1)]
        ok = ac > 1e-6
        if ok.sum() >= 10:
            gain[c] = float(np.median(r[ok, c] / ac[ok]))
    return gain


def relight_maps(res):
    """(maps or None, notes): the material maps of `res.relight_model` for the glTF.

    maps: {"st": the model's pixel step, "mask": (h, w) the model's pixels, "f0": (h, w, 3) and
    "roughness": (h, w) float32 at the model's pixels, "f0_top": F0 at the specular texture's white,
    "kd": the base colour's source ((H, W, 3): ρ itself when the model has every pixel, else the
    photometric-stereo albedo), "scale": (3,) its factor (the albedo's gain to ρ's unit, both divided
    by the base colour's top), "k": the exponent(s)}. None without a model (the note says why)."""
    model = res.relight_model
    if model is None:
        return None, ["glTF: no relighting model in this run (read by bands with --memory, or near lights): "
                      "base colour from the albedo, one roughness from the BRDF fit, no specular map"]
    st = model_step(res.mask.shape, model.mask.shape)
    mask = np.asarray(model.mask, bool)
    if st is None or not mask.any():
        return None, [f"glTF: the relighting model ({model.mask.shape[1]}x{model.mask.shape[0]}) does not cover "
                      "the image or no pixel: base colour from the albedo, one roughness from the BRDF fit"]
    k = model.shininess
    rho = np.nan_to_num(np.asarray(model.rho, np.float32))
    if st == 1:
        kd, gain = rho, np.ones(3)
    else:
        kd, gain = res.albedo, _gain(res.albedo, rho, mask, st)
    vals = (decimated(kd, st).astype(np.float64)[mask].reshape(int(mask.sum()), -1) * gain).ravel()
    top = max(1.0, float(np.percentile(vals, BASE_TOP_PERCENTILE))) if vals.size else 1.0
    f0 = np.where(mask[..., None], f0_of_lobe(np.nan_to_num(np.asarray(model.spec, np.float64)), k), 0.0) / top
    f0 = np.minimum(f0, 1.0)
    rough = roughness_of_lobe(f0, k)
    f0_top = float(np.percentile(np.max(f0[mask], axis=-1), F0_TOP_PERCENTILE))
    h, w = mask.shape
    k_text = f"{float(k):g}" if np.ndim(k) == 0 else f"{float(np.min(k)):g}-{float(np.max(k)):g}"
    r_k = float(np.mean(np.sqrt(ggx_alpha_of_exponent(k))))
    lobed = float(np.mean(np.max(f0[mask], axis=-1) >= DIELECTRIC_F0))
    notes = [f"glTF maps from the relighting model ({w}x{h}"
             + (", every pixel" if st == 1 else f", one pixel in {st} along each side: the report's size; --outputs "
                "relight fits every pixel") + "): base colour " + ("its K_d map" if st == 1 else
                                                     "the albedo at full size in its K_d map's unit")
             + (f" divided by {top:.3g}" if top > 1 else "")
             + f"; specular F0 = 8 s / (k + 2) per pixel and colour (KHR_materials_specular, up to {f0_top:.3g})"
             + f"; roughness (2 / (k + 2))^(1/4) = {r_k:.3g} (Blinn-Phong k = {k_text}) where the lobe is at least "
             f"glass's ({100 * lobed:.0f} % of the object), towards 1 where it is weaker"]
    if f0_top <= 0:
        notes.append("glTF: the relighting model has no lobe (too few lights for one, or a matte object): "
                     "no specular reflection, roughness 1")
    return {"st": st, "mask": mask, "f0": f0.astype(np.float32), "roughness": rough.astype(np.float32),
            "f0_top": f0_top, "kd": kd, "scale": gain / top, "k": k}, notes


def model_textures(maps, metal=False):
    """(metallic_roughness (h, w, 3) uint8, specular {"color", "color_factor", "factor"} or None for
    io.gltf.write_glb) of `relight_maps`'s maps, at the model's pixels (block means above
    GLTF_TEXTURE_MAX texels). Texels without a model pixel: glTF's plain dielectric (F0 0.04) of
    roughness 1. metal: metallic 1 on the model's pixels (the F0 is then the base colour's, and
    KHR_materials_specular, which leaves metals alone, is not written)."""
    mask, f0, rough = maps["mask"], maps["f0"], maps["roughness"]
    f = texture_step(mask.shape)
    if f > 1:
        (f0, rough), count = block_means((f0, rough), mask, f)
        rough, mask = rough[..., 0], count > 0
    top = maps["f0_top"]
    mr = np.zeros(mask.shape + (3,), np.uint8)
    mr[..., 0] = 255                                          # occlusion: unused
    mr[..., 1] = np.round(np.where(mask, rough, 1.0) * 255)
    if metal:
        mr[..., 2] = np.where(mask, 255, 0)
        return mr, None
    if top <= 0:
        return mr, {"color": None, "color_factor": 0.0, "factor": 0.0}
    colour = np.where(mask[..., None], f0 / top, DIELECTRIC_F0 / top)
    # the texture is sRGB-encoded (KHR_materials_specular); F0 = 0.04 × color_factor × texel
    return mr, {"color": srgb_encode(colour), "color_factor": top / DIELECTRIC_F0, "factor": 1.0}
