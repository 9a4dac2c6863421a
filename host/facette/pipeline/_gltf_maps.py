"""The glTF material's spatially varying maps, from the relighting model (recon._relight_model).

The model holds, per pixel and channel, a diffuse reflectance ρ, a Blinn–Phong lobe s (n·h)^k (one
exponent k per capture, or a map of them) and gathered light a l_z, in display-white units: a
pixel's value under a distant light of irradiance E = π is ρ (n·l) + s (n·h)^k + a l_z. glTF's
metallic-roughness BRDF (glTF 2.0, Appendix B) gives c (n·l) for its base colour c and, for the
specular part, F D V π (n·l) with GGX D of α = roughness², height-correlated Smith V, F ≈ F0. So

    α = sqrt(2 / (k + 2))              (Walter et al. 2007, eq. 33: the Beckmann α of Phong exponent
                                        k; GGX of the same α, as `pipeline._exports.gltf_roughness`)
    roughness = sqrt(α) = (2 / (k + 2))^(1/4)
    (c_d, F0) per pixel and colour: the least-squares fit, ≥ 0, of c_d (n·l) + F0 π D V (n·l) to the
              model's physics (without its cast shadows) under the captured lights (`_project`);
              at n = l = v the lobes' peaks alone would give F0 = 4 α² s = 8 s / (k + 2), which
              misses where a broad lobe (k = 8) stands in for diffuse or gathered light
    base colour c = c_d / (1 - max F0) (glTF's diffuse is c (1 - max F), KHR_materials_specular)

F0 per pixel and colour goes into KHR_materials_specular (specularColorTexture × specularColorFactor
× glTF's F0 of IOR 1.5, 0.04); viewers without the extension keep F0 = 0.04 everywhere, so for them
the roughness texture also carries where the lobe is weaker than glass's: roughness rises from
(2/(k+2))^¼ at F0 ≥ 0.04 linearly to 1 at F0 = 0 (`roughness_of_lobe`). Metallic is 0 unless a BRDF
fit beside it finds a metal (pipeline._exports.gltf_material).
"""
import numpy as np

from facette._memory import decimated
from facette.pipeline._exports import block_means, srgb_encode, texture_step
from facette.recon._relight_model import physical_basis

__all__ = ["relight_maps", "ggx_alpha_of_exponent", "ggx_lobe", "roughness_of_lobe", "model_step",
           "DIELECTRIC_F0", "model_textures"]

DIELECTRIC_F0 = 0.04        # glTF's F0 at its default IOR 1.5: ((1.5 - 1) / (1.5 + 1))²
F0_TOP_PERCENTILE = 99.9    # the specular colour texture's white: a few brightest lobes may clip
BASE_TOP_PERCENTILE = 99.5  # the base colour's: as the albedo's (pipeline._exports.gltf_material)


def ggx_alpha_of_exponent(k):
    """GGX α of a Blinn–Phong exponent k: sqrt(2 / (k + 2)) (Walter et al. 2007, eq. 33)."""
    return np.sqrt(2.0 / (np.asarray(k, np.float64) + 2.0))


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

PROJECT_VALUES = 1 << 22    # pixel-light pairs per block of the projection (~50 MB per float32 array)
VIEW_LIGHTS_MAX_DEG = 75.0  # lights of the projection without captured ones: a dome up to 75° from the axis


def _view_lights(light_dirs):
    """The lights the glTF material is fitted under: the captured ones (m, 3), or a dome."""
    d = None if light_dirs is None else np.asarray(light_dirs, np.float64)
    if d is not None and d.ndim == 2 and d.shape[1] == 3 and len(d) >= 3:
        return d / np.linalg.norm(d, axis=1, keepdims=True)
    th, ph = np.meshgrid(np.radians(np.linspace(5, VIEW_LIGHTS_MAX_DEG, 8)), np.radians(np.arange(0, 360, 30)))
    return np.c_[(np.sin(th) * np.cos(ph)).ravel(), (np.sin(th) * np.sin(ph)).ravel(), np.cos(th).ravel()]


def ggx_lobe(normals, lights, alpha2):
    """glTF's specular radiance per unit F0 (m, ...) under lights (m, 3) of irradiance π, seen along
    +z: π D V (n·l), GGX D and height-correlated Smith V (glTF 2.0 Appendix B; F ≈ F0, as within
    75° of the axis (1 - v·h)^5 < 5e-4)."""
    n = np.asarray(normals, np.float32)
    lights = np.asarray(lights, np.float32)
    half = lights + np.array([0, 0, 1], np.float32)
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    nl = np.einsum("...c,mc->m...", n, lights)
    nh = np.clip(np.einsum("...c,mc->m...", n, half), 0, 1)
    nv = np.clip(n[..., 2], 1e-3, 1)
    a2 = np.float32(alpha2)
    d = a2 / (np.float32(np.pi) * (nh * nh * (a2 - 1) + 1) ** 2)
    nlp = np.clip(nl, 0, 1)
    v = 0.5 / np.maximum(nlp * np.sqrt(nv * nv * (1 - a2) + a2) + nv * np.sqrt(nlp * nlp * (1 - a2) + a2), 1e-6)
    return np.where(nl > 0, np.float32(np.pi) * d * v * nlp, 0).astype(np.float32)


def _project(model, lights, alpha2):
    """(c_d, F0) (h, w, 3) per pixel: glTF's diffuse c_d (n·l) and GGX lobe F0 · `ggx_lobe` (α² alpha2)
    closest, in least squares over `lights` and ≥ 0, to the model's physics without its cast shadows
    (ρ (n·l) + s (n·h)^k + a l_z: what a glTF viewer can show); the model's pixels only."""
    mask = np.asarray(model.mask, bool)
    cd, f0 = np.zeros(mask.shape + (3,), np.float32), np.zeros(mask.shape + (3,), np.float32)
    rows, cols = np.nonzero(mask)
    step = max(1024, PROJECT_VALUES // len(lights))
    for a in range(0, len(rows), step):
        r, c = rows[a:a + step], cols[a:a + step]
        terms = np.stack([np.asarray(model.rho[r, c], np.float64), np.asarray(model.spec[r, c], np.float64),
                          np.asarray(model.amb[r, c], np.float64)], axis=1)             # (N, 3 terms, C)
        n = np.asarray(model.normals[r, c], np.float32)
        basis = physical_basis(n, lights, model.shininess if np.ndim(model.shininess) == 0
                               else np.asarray(model.shininess)[r, c])                # (m, N, 3)
        y = np.einsum("mnj,njc->mnc", basis, terms)                                     # (m, N, C)
        g = np.stack([np.clip(np.einsum("nc,mc->mn", n, lights.astype(np.float32)), 0, None),
                      ggx_lobe(n, lights, alpha2)], axis=-1).astype(np.float64)         # (m, N, 2)
        gram = np.einsum("mnj,mnk->njk", g, g) + 1e-9 * np.eye(2)
        rhs = np.einsum("mnj,mnc->njc", g, y)
        both = np.linalg.solve(gram, rhs)                                               # (N, 2, C)
        # non-negative: where one coefficient is < 0, the other alone
        alone = rhs / np.maximum(np.diagonal(gram, axis1=1, axis2=2)[..., None], 1e-12)
        x = np.where((both < 0).any(axis=1, keepdims=True),
                     np.where(alone[:, :1] * rhs[:, :1] >= alone[:, 1:] * rhs[:, 1:],
                              np.concatenate([alone[:, :1], 0 * alone[:, 1:]], 1),
                              np.concatenate([0 * alone[:, :1], alone[:, 1:]], 1)), both)
        x = np.maximum(x, 0)
        cd[r, c], f0[r, c] = x[:, 0], x[:, 1]
    return cd, f0

def _base_top(cd, lobe, sample=200_000):
    """The exposure `top` ≥ 1 that the maps are divided by (a viewer lights them `top` times brighter):
    the smallest with the base colours c_d / (top (1 - max F0)), F0 = min(lobe / top, 1), at most 1 on
    BASE_TOP_PERCENTILE % of the pixels (cd, lobe (N, 3)); by bisection (the base colours fall as top grows)."""
    pick = np.linspace(0, len(cd) - 1, min(sample, len(cd))).astype(int)
    cd, lobe = cd[pick], lobe[pick]

    def over(top):
        fm = np.minimum(lobe / top, 1.0).max(axis=-1, keepdims=True)
        return float(np.percentile(cd / (top * np.maximum(1.0 - fm, 0.1)), BASE_TOP_PERCENTILE)) > 1.0

    if not len(cd) or not over(1.0):
        return 1.0
    lo, hi = 1.0, 2.0
    while over(hi) and hi < 1e6:
        lo, hi = hi, 2 * hi
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if over(mid) else (lo, mid)
    return hi


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
    # the glTF material closest to the model's physics under the captured lights: its diffuse and a
    # GGX lobe of the model's width (α of k), per pixel and colour (the peak-matched F0 = 8 s / (k + 2)
    # differs where the broad lobes stand in for light the surface gathers, k = 8)
    rho, lobe = _project(model, _view_lights(getattr(res.inputs, "light_dirs", None)),
                         float(np.mean(ggx_alpha_of_exponent(k) ** 2)))
    top = _base_top(rho[mask], lobe[mask])
    f0 = np.minimum(lobe / top, 1.0)
    # glTF (KHR_materials_specular): diffuse × (1 - max F), F ≈ F0 for the lights a viewer looks under
    # (|v·h| > 0.7: F0 + 0.002): the base colour c_d / (1 - max F0) shows c_d (at most 10x)
    kd_model = rho / np.maximum(1.0 - f0.max(axis=-1, keepdims=True), 0.1)
    if st == 1:
        kd, gain = kd_model.astype(np.float32), np.ones(3)
    else:
        kd, gain = res.albedo, _gain(res.albedo, kd_model, mask, st)
    rough = roughness_of_lobe(f0, k)
    f0_top = float(np.percentile(np.max(f0[mask], axis=-1), F0_TOP_PERCENTILE))
    h, w = mask.shape
    k_text = f"{float(k):g}" if np.ndim(k) == 0 else f"{float(np.min(k)):g}-{float(np.max(k)):g}"
    r_k = float(np.mean(np.sqrt(ggx_alpha_of_exponent(k))))
    lobed = float(np.mean(np.max(f0[mask], axis=-1) >= DIELECTRIC_F0))
    notes = [f"glTF maps from the relighting model ({w}x{h}"
             + (", every pixel" if st == 1 else f", one pixel in {st} along each side: the report's size; --outputs "
                "relight fits every pixel") + "): a diffuse and an F0 per pixel and colour fitted to its physics "
             f"under the captured lights (F0 up to {f0_top:.3g}, KHR_materials_specular); base colour "
             + ("that diffuse" if st == 1 else "the albedo at full size in that diffuse's unit")
             + (f", the maps divided by {top:.3g}" if top > 1 else "")
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
