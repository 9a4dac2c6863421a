"""The relighting viewer of report.html: data packed for WebGL, and the page section.

Everything is embedded (no server, no network): normals as float16 (n_x, n_y; n_z ≥ 0 is
rebuilt), the K_d map and the mask as RGBA8, the volume table J(θ_s, θ_o, Δφ) as float16
(facette.pipeline._relight.volume_table), the mesh heights as float32, and viewer.js
(plain WebGL 2, written for facette; no library). Images wider than MAX_SIDE are decimated
(a 2144 × 1424 scan: 1072 × 712, ~8 MB of page).
"""
import base64
import html
import json
import numpy as np

import facette.brdf as brdf
from facette._data import package_text
from facette._memory import decimated
from facette.pipeline._relight import (BACKGROUND, DEFAULT_LIGHT, default_exposure, kd_map_from_albedo,
                                       viewer_model, volume_table)
from facette.pipeline._viewer_model import model_data
from facette.recon import MESH_MAX_SLOPE

__all__ = ["viewer_data", "viewer_section", "MAX_SIDE", "MESH_MAX_SIDE"]

MAX_SIDE = 1100          # larger images are decimated for the viewer (the files keep full
                         # size): the canvas is drawn at most 900 px wide; 2144 x 1424 made a
                         # 32 MB page, 8 MB at 1072 x 712
MESH_MAX_SIDE = 400      # vertices per side of the 3D view's grid
_DISTRIBUTIONS = {"beckmann": 0, "ggx": 1, "gaussian": 2}
_MASKINGS = {"smith": 0, "vcavity": 1}


def _b64(a):
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def viewer_data(normals, mask, fit, albedo=None, kd_map=None, height=None, pitch_mm=1.0,
                material_mask=None, max_side=MAX_SIDE, light=DEFAULT_LIGHT, relight_model=None):
    """The viewer's data (a JSON-ready dict) and the arrays it was made from.

    normals : (H, W, 3) unit normals, camera frame; mask : (H, W) bool; fit : a FitResult
    or the dict of brdf.json; albedo : (H, W, C) photometric-stereo albedo, scaled into a
    K_d map (`kd_map_from_albedo`, median over material_mask) unless kd_map (H, W, C) in
    [0, 1] is given; height :
    (H, W) mm or None (no 3D view); pitch_mm : pixel size (mm); light : (azimuth, elevation) deg.
    Returns (data, arrays) with arrays = dict(normals, mask, kd_map, model): what was packed,
    at the viewer's size, for the Python reference render. Raises ValueError when the fit
    cannot be drawn (see `viewer_model`). relight_model : a `facette.recon.RelightModel` (process's
    "relight" output): the page draws it (`pipeline._viewer_model`) instead of the fitted BRDF (fit
    may then be None), arrays["sv_model"] the model as shipped.
    """
    if relight_model is not None and fit is None:
        fit = {"model": "lambert", "success": True, "parameters": {"kd": [0.8, 0.8, 0.8]}}
    m = viewer_model(fit)
    mask = np.asarray(mask, dtype=bool)
    if np.ndim(normals) != 3 or np.shape(normals)[2] != 3 or mask.shape != np.shape(normals)[:2]:
        raise ValueError(f"normals must be (H, W, 3) and mask (H, W); got {np.shape(normals)} and {mask.shape}")
    st = max(1, int(np.ceil(max(mask.shape) / max_side)))
    # decimated before any copy (a 100 MP map in float64 would be 2.4 GB), by bands
    n, mk = decimated(np.asarray(normals), st).astype(np.float64), mask[::st, ::st]
    if kd_map is None:
        if albedo is None:
            kd = np.broadcast_to(m.kd, mk.shape + m.kd.shape) * mk[..., None]
        else:
            mat = None if material_mask is None else np.asarray(material_mask, bool)[::st, ::st]
            kd = kd_map_from_albedo(decimated(np.asarray(albedo), st), mk, m.kd, mat)
    else:
        kd = np.clip(np.asarray(kd_map[::st, ::st], dtype=float), 0, 1)
    kd = np.atleast_3d(kd)
    if kd.shape[2] == 1:
        kd = np.repeat(kd, 3, axis=2)
    kd = kd[..., :3]
    # pixels facing away from the camera (n_z < 0) cannot be packed as (n_x, n_y): masked out
    mk = mk & (n[..., 2] >= 0) & np.all(np.isfinite(n), axis=-1)
    rgba = np.zeros(mk.shape + (4,), np.uint8)
    rgba[..., :3] = np.round(np.where(mk[..., None], kd, 0) * 255)
    rgba[..., 3] = np.where(mk, 255, 0)
    nxy = np.where(mk[..., None], n[..., :2], 0).astype(np.float16)
    table = volume_table(m)
    r_i = brdf.diffuse_r_i(m.n_i, m.sigma, m.volume) if m.model == "li" else 0.0
    kd_a = 1.0 / (np.pi * m.n_i ** 2) if m.model == "li" else 1.0 / np.pi
    exposure = default_exposure(n, kd, mk, m)
    data = {
        "width": int(mk.shape[1]), "height": int(mk.shape[0]), "decimation": st,
        "normals": _b64(nxy), "kd": _b64(rgba),
        "table": {"n_theta": int(table.shape[1]), "n_phi": int(table.shape[0]),
                  "data": _b64(table.astype(np.float16))},
        "model": {"name": m.model, "specular": bool(m.has_lobe()), "sigma": m.sigma, "n_i": m.n_i,
                  "distribution": _DISTRIBUTIONS[m.distribution], "masking": _MASKINGS[m.masking],
                  "gauss_norm": (1.0 / brdf.gaussian_norm_exact(m.sigma))
                  if m.distribution == "gaussian" and m.sigma > 0 else 0.0,
                  "kd_a": kd_a, "kd_b": r_i},
        "exposure": exposure, "light": [float(light[0]), float(light[1])], "background": BACKGROUND,
        "mesh": None, "sv": None,
    }
    arrays = {"normals": n, "mask": mk, "kd_map": kd, "model": m, "exposure": exposure}
    if relight_model is not None:
        small_albedo = None if albedo is None else decimated(np.asarray(albedo), st)   # a coarser model's texture
        data["sv"], arrays["sv_model"] = model_data(relight_model, st, mk, n, small_albedo)
        data["exposure"] = 1.0           # the model's display values: 1 = the photographs' white
    if height is not None:
        hgt = np.asarray(height[::st, ::st], dtype=np.float64)
        ms = max(1, int(np.ceil(max(hgt.shape) / MESH_MAX_SIDE)))
        # NaN outside the mask: the 3D view draws no triangle there (no curtains down the silhouette)
        grid = np.where(mk, hgt, np.nan)[::ms, ::ms]
        data["mesh"] = {"cols": int(grid.shape[1]), "rows": int(grid.shape[0]), "step_px": ms,
                        "step_mm": float(pitch_mm) * st * ms, "max_slope": MESH_MAX_SLOPE,
                        "heights": _b64(grid.astype(np.float32))}
    return data, arrays


def viewer_section(data):
    """HTML of the viewer (canvases, controls, the data and the script) for `viewer_data`."""
    script = package_text("facette.pipeline", "viewer.js").replace(
        "  // @relight-model", package_text("facette.pipeline", "viewer_model.js") + "\n  // relight-model")
    payload = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    mdl = data["model"]
    what = (f"{mdl['name'].upper()} model, σ = {mdl['sigma']:.3g}, n_i = {mdl['n_i']:.3g}"
            if mdl["specular"] else f"{mdl['name']} model (no specular lobe)")
    if data.get("sv"):
        what = ("facette's relighting model: per-pixel diffuse, lobe and gathered-light maps, cast shadows "
                f"from the heights, {data['sv']['n_planes']} residual planes interpolated over the captured lights")
    mesh = ('<figure><canvas id="facette-mesh" width="640" height="480"></canvas><figcaption>Mesh '
            '(from the integrated heights), shaded with the same model: drag to turn, wheel to zoom'
            '</figcaption></figure>') if data["mesh"] else "<p>No heights were computed: no 3D view.</p>"
    small = data["decimation"] > 1
    return f"""<section id="viewer"><h2>Relighting</h2>
<p>The object re-rendered from its normals and its reflectance ({html.escape(what)}),
under a distant light: drag on the picture to move the light (the centre is the camera's direction).
{'The picture is decimated by ' + str(data['decimation']) + ' for the page.' if small else ''}</p>
<div class="controls"><label>Light elevation <input id="facette-elevation" type="range" min="2" max="90" step="1"
value="{data['light'][1]}"></label> <label>Exposure <input id="facette-exposure" type="range" min="-5" max="5"
step="0.1" value="0"></label> <span id="facette-light-readout"></span><span id="facette-viewer-status"></span></div>
<figure><canvas id="facette-relight" style="width:min(100%, 900px);touch-action:none;cursor:crosshair"></canvas>
<figcaption>Relit image (pixels of the scan, one fragment each)</figcaption></figure>
{mesh}
<script type="application/json" id="facette-viewer-data">{payload}</script>
<script>{script}</script></section>"""
