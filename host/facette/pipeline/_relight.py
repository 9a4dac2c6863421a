"""Relighting with the fitted BRDF: the Python reference of the report's WebGL viewer.

A pixel with unit normal n (camera frame), substrate reflectance K_d (per channel) and a
distant light of unit irradiance from direction l is seen by the orthographic camera
(v = +z) with radiance

    L = f(s, o) cos θ_s = f_s(s, o) cos θ_s + g(K_d) · I(s, o) cos θ_s

where s, o are l, v in the pixel's local frame, f_s the specular lobe (LI eq 3.10),
I the K_d-free volume integral and g(K_d) = K_d / (π n_i² (1 − K_d r_i)) (eq 3.15).
The viewer evaluates f_s per pixel in its fragment shader and reads J = I cos θ_s from a
table over (θ_s, θ_o, Δφ) built here (`volume_table`); `relight` evaluates the same model
with facette.brdf directly, so comparing the two measures what the viewer approximates
(the table's interpolation, float16 textures, 8-bit output).
"""
from dataclasses import dataclass

import numpy as np

import facette.brdf as brdf
from facette.reflect import local_frame_directions

__all__ = ["ViewerModel", "viewer_model", "volume_table", "kd_map_from_albedo", "relight",
           "light_from_angles", "to_srgb8", "default_exposure", "BACKGROUND", "DEFAULT_LIGHT"]

DEFAULT_LIGHT = (135.0, 45.0)   # (azimuth, elevation) in deg: top left, as a raking light
BACKGROUND = 0.12     # display value (sRGB, 0..1) of pixels outside the mask
VIEWER_MODELS = ("li", "cook_torrance", "lambert")


@dataclass
class ViewerModel:
    """The fitted model as the viewer needs it.

    model : "li" | "cook_torrance" | "lambert"; kd : (C,) fitted K_d; sigma (isotropic
    roughness, 0 for Lambert), n_i (1 for Lambert); distribution, masking as in facette.brdf;
    volume : the volume evaluation the fit used ("approx", "quadrature", ...; "lambert" for
    the models whose diffuse part is K_d/π).
    """
    model: str
    kd: np.ndarray
    sigma: float
    n_i: float
    distribution: str = "beckmann"
    masking: str = "smith"
    volume: str = "lambert"

    def kd_factor(self, kd):
        """g(K_d): what multiplies the K_d-free diffuse integral; kd (..., C) in [0, 1]."""
        if self.model == "li":
            return brdf.li_kd_factor(np.asarray(kd, dtype=float), self.n_i, self.sigma, self.volume)
        return np.asarray(kd, dtype=float) / np.pi

    def has_lobe(self):
        return self.model != "lambert" and self.sigma > 0 and self.n_i > 1


def viewer_model(fit):
    """A `ViewerModel` from a facette.fit FitResult or the dict of brdf.json.

    Raises ValueError (with the reason) for what the viewer cannot show: a failed fit, a
    model other than LI / Cook–Torrance / Lambert, an anisotropic σ pair.
    """
    d = fit if isinstance(fit, dict) else (fit.to_dict() if hasattr(fit, "to_dict") else None)
    if d is None:
        raise ValueError(f"cannot read a BRDF from {type(fit).__name__}")
    params = d.get("parameters") or d.get("params") or {}
    if d.get("success") is False or not params:
        raise ValueError(f"the BRDF fit failed ({d.get('message', 'no parameters')}): nothing to relight")
    model = d.get("model")
    if model not in VIEWER_MODELS:
        raise ValueError(f"the viewer draws the {', '.join(VIEWER_MODELS)} models, not {model!r}")
    kd = np.atleast_1d(np.asarray(params.get("kd", []), dtype=float))
    if kd.size == 0 or not np.all(np.isfinite(kd)):
        raise ValueError("the BRDF has no finite K_d: nothing to relight")
    sigma = params.get("sigma", 0.0)
    if np.ndim(sigma) != 0:
        raise ValueError("the viewer draws isotropic lobes only; this fit has a (σx, σy) pair")
    lam = model == "lambert"
    return ViewerModel(model=model, kd=np.clip(kd, 0, 1), sigma=0.0 if lam else float(sigma),
                       n_i=1.0 if lam else float(params.get("n_i", 1.0)),
                       distribution=d.get("distribution") or "beckmann",
                       masking=d.get("masking") or "smith",
                       volume=(d.get("volume") or "quadrature") if model == "li" else "lambert")


# Quadrature nodes for the viewer's table: 24 × 24 instead of 48 × 48 is 6x faster (2 s for the
# table instead of 13 s) for a table error of 1e-4 of its maximum, below float16's 5e-4.
TABLE_QUADRATURE = {"n_theta": 24, "n_phi": 24}


def _volume_integral(m, s, o, for_table=False):
    """I(s, o) of the model, (...): the LI volume integral, or 1 for a K_d/π diffuse part.
    for_table: quadrature with TABLE_QUADRATURE nodes (also in place of Monte Carlo, whose
    noise a table would keep)."""
    if m.model != "li":
        return np.where((s[..., 2] > 0) & (o[..., 2] > 0), 1.0, 0.0)
    if for_table and m.volume in ("quadrature", "monte_carlo"):
        return brdf.volume_integral(s, o, m.sigma, m.n_i, m.distribution, m.masking, "quadrature",
                                    **TABLE_QUADRATURE)
    return brdf.volume_integral(s, o, m.sigma, m.n_i, m.distribution, m.masking, m.volume)


def volume_table(m, n_theta=31, n_phi=13):
    """J = I(s, o) cos θ_s on a regular grid, float32 (n_phi, n_theta, n_theta).

    Axes: Δφ ∈ [0°, 180°] (n_phi nodes), θ_o ∈ [0°, 90°], θ_s ∈ [0°, 90°] (n_theta nodes),
    i.e. the layout of a WebGL 3D texture (depth, height, width). J goes to 0 linearly at
    θ_s = 90°, which linear interpolation follows (I itself grows at grazing angles).
    """
    th = np.radians(np.linspace(0.0, 90.0, int(n_theta)))
    ph = np.radians(np.linspace(0.0, 180.0, int(n_phi)))
    P, TO, TS = np.meshgrid(ph, th, th, indexing="ij")
    # keep the last node just inside the horizon: the integral is defined there
    TO = np.minimum(TO, np.radians(89.95))
    TSc = np.minimum(TS, np.radians(89.95))
    s = np.stack([np.sin(TSc), np.zeros_like(TSc), np.cos(TSc)], axis=-1)
    o = np.stack([np.sin(TO) * np.cos(P), np.sin(TO) * np.sin(P), np.cos(TO)], axis=-1)
    j = _volume_integral(m, s, o, for_table=True) * np.cos(TS)
    return np.where(np.isfinite(j), j, 0.0).astype(np.float32)


def kd_map_from_albedo(albedo, mask, kd, material_mask=None):
    """A per-pixel K_d map (H, W, C) in [0, 1]: the photometric-stereo albedo scaled, per
    channel, so that its median over the material (material_mask & mask; default the mask)
    is the fitted K_d. The fit gives one K_d per material; the albedo carries its variation
    across the object. 0 outside the mask."""
    albedo = np.asarray(albedo, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    ref = mask if material_mask is None else mask & np.asarray(material_mask, dtype=bool)
    if not ref.any():
        ref = mask
    if albedo.ndim == 2:
        albedo = albedo[..., None]
    kd = np.broadcast_to(np.asarray(kd, dtype=float), albedo.shape[-1:])
    med = np.array([np.median(albedo[..., c][ref]) if ref.any() else 0.0
                    for c in range(albedo.shape[-1])])
    scale = np.where(med > 0, kd / np.where(med > 0, med, 1.0), 0.0)
    return np.clip(np.where(mask[..., None], albedo * scale, 0.0), 0.0, 1.0)


def light_from_angles(azimuth_deg, elevation_deg):
    """Unit light direction (3,) in the camera frame (x right, y up, z towards the camera)
    from its azimuth (deg, from +x towards +y) and elevation above the image plane (deg)."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def relight(normals, kd_map, mask, m, light, view=(0.0, 0.0, 1.0)):
    """Linear radiance (H, W, C) of every pixel under a distant light of unit irradiance.

    normals : (H, W, 3) unit normals (camera frame); kd_map : (H, W, C) in [0, 1];
    mask : (H, W) bool; m : `ViewerModel`; light : (3,) direction towards the light.
    0 outside the mask and where the light or the camera is below a pixel's horizon.
    Uses facette.brdf (li_specular, volume_integral, li_kd_factor): the reference of the viewer.
    """
    normals = np.asarray(normals, dtype=float)
    light = np.asarray(light, dtype=float)
    light = light / np.linalg.norm(light)
    h, w = normals.shape[:2]
    out = np.zeros((h, w, np.shape(kd_map)[-1]))
    sel = np.asarray(mask, bool) & (np.linalg.norm(normals, axis=-1) > 0.5)
    if not sel.any():
        return out
    n = normals[sel] / np.linalg.norm(normals[sel], axis=-1, keepdims=True)
    s, o = local_frame_directions(n, light, np.asarray(view, dtype=float))
    s, o = s.astype(float), o.astype(float)
    up = (s[:, 2] > 0) & (o[:, 2] > 0)
    s_up, o_up = s[up], o[up]
    vol = _volume_integral(m, s_up, o_up)[:, None] * m.kd_factor(np.asarray(kd_map, float)[sel][up])
    spec = brdf.li_specular(s_up, o_up, m.sigma, m.n_i, m.distribution, m.masking) if m.has_lobe() \
        else np.zeros(len(s_up))
    val = np.zeros((len(n), out.shape[-1]))
    val[up] = (spec[:, None] + vol) * s_up[:, 2:3]
    out[sel] = val
    return out


def to_srgb8(radiance, mask, exposure):
    """8-bit sRGB display values (H, W, C) of exposure × radiance, clipped to [0, 1];
    BACKGROUND outside the mask (the viewer's shader applies the same mapping)."""
    x = np.clip(np.asarray(radiance, dtype=float) * exposure, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    srgb = np.where(np.asarray(mask, bool)[..., None], srgb, BACKGROUND)
    return np.round(srgb * 255).astype(np.uint8)


def default_exposure(normals, kd_map, mask, m, light=None):
    """An exposure that puts the 95th percentile of the radiance under `light` (default the
    viewer's first light, `DEFAULT_LIGHT`) at 0.5 (display 0.74): highlights may clip, the slider brings them back."""
    light = light_from_angles(*DEFAULT_LIGHT) if light is None else light
    # a percentile needs no more than ~250 000 pixels (a full 2144 x 1424 render takes seconds)
    k = max(1, int(np.ceil(np.sqrt(np.asarray(mask).size / 250_000))))
    mask = np.asarray(mask, bool)[::k, ::k]
    vals = relight(np.asarray(normals)[::k, ::k], np.asarray(kd_map)[::k, ::k], mask, m, light)[mask]
    top = float(np.percentile(vals, 95)) if vals.size else 0.0
    return 0.5 / top if top > 0 else 1.0
