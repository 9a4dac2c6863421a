"""Photometric-stereo scenes rendered by an independent renderer, Mitsuba 3.

The images are not made with facette's BRDF code: `roughplastic` (Beckmann, `nonlinear: true`)
is a rough dielectric interface over a Lambertian substrate, close to the LI model with
K_d = `diffuse_reflectance`, σ = α, n_i = `int_ior`; plaster is Mitsuba's `diffuse`.
Camera: orthographic, looking down −z (camera frame x right, y up, z towards the camera).
Lights: directional emitters of irradiance 1 (so a Lambertian reflectance ρ gives
E = (ρ/π) s·n, facette's convention), one image per light, optionally point emitters (near
light, with their positions). True normals: the `aov` integrator's `nn:sh_normal`, averaged
over each pixel like the images (`_render`).

Shapes (our own): "sphere"; "relief", a bas-relief height field (bumps, ridges and a crater:
concavities that cast shadows and inter-reflect); "vase", a surface of revolution with a concave
neck; "shell", a ribbed dome with a pit (a check scene, with the "lacquer" material, for changes
tuned on the others); "table", two domes on a dark table that fills the frame (heights against
Mitsuba's positions, and the flat margin the integration assumes). Materials: "plaster" (matte), the thesis's three paints (σ, n_i = 0.10, 1.30; 0.08, 1.28;
0.05, 1.26), "satin" (σ 0.2, n_i 1.5). Textures: a K_d pattern (stripes and spots, two colours)
so that albedo varies over the object.

`render_scene(...)` caches its result as an .npz under a cache folder (renders are never
committed) and returns a dict: images (m, H, W, 3) float32, light_dirs (m, 3), normals
(H, W, 3), mask (H, W), kd (H, W, 3) the true K_d, and the material's parameters.
"""
import hashlib
import json
from pathlib import Path

import numpy as np

__all__ = ["CONCAVE_SHAPES", "MATERIALS", "NON_LI_SCENES", "SHAPES", "render_scene", "rig_light_directions"]

# concave height fields (`facette bench concave`): deep enough that the lights 30-45 deg off the axis
# are hidden on their walls (cast shadows) and the walls light each other
CONCAVE_SHAPES = ("bowl", "grooves", "craters", "cup")

MATERIALS = {
    "plaster": {"type": "diffuse"},
    "paint_0.10": {"sigma": 0.10, "n_i": 1.30},
    "paint_0.08": {"sigma": 0.08, "n_i": 1.28},
    "paint_0.05": {"sigma": 0.05, "n_i": 1.26},
    "satin": {"sigma": 0.20, "n_i": 1.50},
    "lacquer": {"sigma": 0.07, "n_i": 1.45},    # a check scene: n_i unlike the thesis's paints
    # materials the LI model does not cover (no dielectric interface over a diffuse substrate):
    # metals (Mitsuba's measured complex IOR; no diffuse part, K_d unused), a metallic paint (a
    # blend of a copper lobe and a diffuse base) and a rough plastic with a broad lobe
    "gold": {"type": "roughconductor", "conductor": "Au", "alpha": 0.15},
    "aluminium": {"type": "roughconductor", "conductor": "Al", "alpha": 0.3},
    "metallic_paint": {"type": "metallic_paint", "conductor": "Cu", "alpha": 0.2, "weight": 0.5},
    "rough_plastic": {"sigma": 0.40, "n_i": 1.50},
    # weak gloss (a worn glaze, a waxed or partly varnished surface: the highlight a fraction of a
    # dielectric's, roughplastic's specular_reflectance < 1), for the lobe-or-not choice between
    # matte and glossy: no LI (σ, n_i) renders them exactly
    "glaze_0.10": {"sigma": 0.10, "n_i": 1.50, "specular": 0.25},
    "glaze_0.20": {"sigma": 0.20, "n_i": 1.50, "specular": 0.35},
    "glaze_0.05": {"sigma": 0.05, "n_i": 1.50, "specular": 0.1},
}
# scenes of those materials (shape, material, textured): `facette bench peers --mitsuba`
NON_LI_SCENES = [("sphere", "gold", False), ("sphere", "aluminium", False),
                 ("sphere", "metallic_paint", True), ("sphere", "rough_plastic", False),
                 ("relief", "rough_plastic", True), ("relief", "gold", False)]
SHAPES = ("sphere", "relief", "vase", "shell", "table") + CONCAVE_SHAPES
# "table": two domes in the scene's material on a dark, slightly glossy table filling the frame (a
# fossil on black cloth): a hemisphere (radius 0.38, a vertical wall at its foot) and a spherical
# cap 0.25 high (radius 0.5, meeting the table at 60°). Heights are checked against `positions`.
TABLE_KD = (0.04, 0.04, 0.045)
TABLE_MATERIAL = "paint_0.05"
TABLE_DOMES = (((0.42, 0.05, 0.0), 0.38), ((-0.45, -0.1, -0.25), 0.5))


def rig_light_directions():
    """The thesis rig's 12 directions (§4.3.2): θ 15° at φ 30°, 90°, …; θ 30° at φ 0°, 60°, …"""
    dirs = []
    for k in range(6):
        for th, ph in ((30.0, 60.0 * k), (15.0, 30.0 + 60.0 * k)):
            t, p = np.radians(th), np.radians(ph)
            dirs.append([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    return np.array(dirs)


def _heightfield(name, n=160):
    """Vertices (n*n, 3), faces, uv of a height field over [-1, 1]^2 (z up towards the camera)."""
    x = np.linspace(-1, 1, n)
    xx, yy = np.meshgrid(x, x)
    if name == "relief":
        z = (0.35 * np.exp(-((xx + 0.4) ** 2 + (yy - 0.35) ** 2) / 0.08)
             + 0.25 * np.exp(-((xx - 0.45) ** 2 + (yy + 0.3) ** 2) / 0.05)
             + 0.08 * np.sin(5 * xx + 2 * yy) * np.exp(-(xx ** 2 + yy ** 2) / 0.6)
             - 0.30 * np.exp(-((xx - 0.35) ** 2 + (yy - 0.45) ** 2) / 0.04)     # a crater
             - 0.15 * np.exp(-((xx + 0.3) ** 2 + (yy + 0.5) ** 2) / 0.02))
    elif name == "shell":  # a ribbed dome (fossil shell): 14 radial ribs fading towards the apex
        r = np.sqrt(xx ** 2 + yy ** 2)
        th = np.arctan2(yy + 0.15, xx)
        z = 0.45 * np.maximum(1 - r ** 2, 0) + 0.035 * np.cos(14 * th) * np.minimum(r, 0.9) \
            - 0.1 * np.exp(-((xx - 0.3) ** 2 + (yy + 0.35) ** 2) / 0.01)
    elif name in CONCAVE_SHAPES:
        z = _concave(name, xx, yy)
    else:  # vase: a surface of revolution seen from above, concave neck around a bulge
        r = np.sqrt(xx ** 2 + yy ** 2)
        z = 0.5 * np.exp(-r ** 2 / 0.12) - 0.25 * np.exp(-(r - 0.55) ** 2 / 0.02) + 0.1 * np.cos(3 * r)
    v = np.stack([xx.ravel(), yy.ravel(), z.ravel()], axis=1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    uv = np.stack([(xx.ravel() + 1) / 2, (yy.ravel() + 1) / 2], axis=1)
    return v, faces, uv


def _concave(name, xx, yy):
    """Heights of the concave scenes over [-1, 1]^2 (walls up to 60-75 deg steep)."""
    r = np.sqrt(xx ** 2 + yy ** 2)
    if name == "bowl":     # a spherical bowl (radius 0.8) cut 0.41 deep into a plane, rim 0.7
        return -np.maximum(np.sqrt(np.maximum(0.64 - r ** 2, 0)) - np.sqrt(0.64 - 0.49), 0)
    if name == "cup":      # a flat-bottomed cup 0.55 deep, its walls 75 deg steep at their middle
        return -0.55 / (1 + np.exp((r - 0.5) / 0.04))
    if name == "grooves":  # three parabolic grooves, two along y and one diagonal
        z = np.zeros_like(xx)
        for u, depth, half in ((xx + 0.55, 0.22, 0.18), (xx - 0.05, 0.3, 0.14), ((xx + yy) / np.sqrt(2) - 0.75, 0.18, 0.15)):
            z = np.minimum(z, -depth * np.maximum(0, 1 - (u / half) ** 2))
        return z
    # craters: a field of pits with raised rims
    z = np.zeros_like(xx)
    for cx, cy, a in ((-0.45, 0.4, 0.35), (0.4, 0.45, 0.25), (0.05, -0.3, 0.4), (-0.55, -0.55, 0.2), (0.6, -0.5, 0.22)):
        rr = np.sqrt((xx - cx) ** 2 + (yy - cy) ** 2)
        z += -0.45 * a / 0.35 * np.exp(-(rr / (0.55 * a)) ** 2) + 0.08 * a / 0.35 * np.exp(-((rr - a) / (0.25 * a)) ** 2)
    return z


def _write_ply(path, v, faces, uv):
    """Binary PLY with positions and texture coordinates (Mitsuba computes smooth normals)."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            "property float x\nproperty float y\nproperty float z\nproperty float u\nproperty float v\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    vert = np.concatenate([v, uv], axis=1).astype("<f4")
    fc = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    fc["n"], fc["i"] = 3, faces
    with open(path, "wb") as f:
        f.write(head.encode())
        f.write(vert.tobytes())
        f.write(fc.tobytes())


def _kd_texture(textured, kd, res=256):
    """(res, res, 3) K_d image: constant, or stripes and spots in two colours."""
    base = np.ones((res, res, 3)) * np.asarray(kd, float)
    if not textured:
        return base
    u = np.linspace(0, 1, res)
    uu, vv = np.meshgrid(u, u)
    other = np.array([0.75, 0.45, 0.25])
    pat = (np.sin(2 * np.pi * 5 * (uu + 0.3 * vv)) > 0.3) | (((uu - 0.6) ** 2 + (vv - 0.4) ** 2) < 0.02)
    return np.where(pat[..., None], other, base)


def _bsdf(mi, material, kd_img):
    tex = {"type": "bitmap", "bitmap": mi.Bitmap(kd_img[::-1].astype(np.float32)), "raw": True,
           "filter_type": "bilinear"}
    spec = MATERIALS[material]
    if spec.get("type") == "diffuse":
        return {"type": "diffuse", "reflectance": tex}
    if spec.get("type") in ("roughconductor", "metallic_paint"):
        metal = {"type": "roughconductor", "material": spec["conductor"], "distribution": "beckmann",
                 "alpha": spec["alpha"]}
        if spec["type"] == "roughconductor":
            return metal
        return {"type": "blendbsdf", "weight": spec["weight"],
                "bsdf_0": {"type": "diffuse", "reflectance": tex}, "bsdf_1": metal}
    return {"type": "roughplastic", "distribution": "beckmann", "alpha": spec["sigma"],
            "int_ior": spec["n_i"], "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": tex,
            **({"specular_reflectance": spec["specular"]} if "specular" in spec else {})}


def render_scene(shape="sphere", material="paint_0.10", size=128, spp=64, kd=(0.6, 0.5, 0.4),
                 textured=False, lights=None, near_distance=None, max_depth=4, cache_dir=None,
                 variant=None, seed=0):
    """Render (or load from the cache) one scene; see the module doc for what is returned.

    shape : one of SHAPES; material : one of MATERIALS; size : image side (pixels), spp :
    samples per pixel; kd : the base K_d per channel; textured : vary K_d over the object;
    lights : (m, 3) directions (default the rig's 12); near_distance : None (directional) or
    the distance of point lights from the scene centre, in scene units (the object spans
    [-1, 1]); max_depth : path length (≥ 3 gives inter-reflections in concavities).
    """
    if shape not in SHAPES:
        raise ValueError(f"shape {shape!r}: choose one of {', '.join(SHAPES)}")
    if material not in MATERIALS:
        raise ValueError(f"material {material!r}: choose one of {', '.join(MATERIALS)}")
    lights = rig_light_directions() if lights is None else np.asarray(lights, float)
    key = json.dumps(["v2", shape, material, size, spp, list(kd), textured, np.round(lights, 6).tolist(),
                      near_distance, max_depth, seed], sort_keys=True)
    tag = hashlib.sha1(key.encode()).hexdigest()[:12]
    # the truth has a cache entry of its own: the images of an older cache stay valid
    truth_tag = hashlib.sha1(json.dumps(["truth-pixel-mean-v1", shape, material, size, spp, list(kd),
                                         textured], sort_keys=True).encode()).hexdigest()[:12]
    cache = Path(cache_dir) if cache_dir else None
    out_file = cache / f"mitsuba_{shape}_{material}_{size}_{tag}.npz" if cache else None
    truth_file = cache / f"mitsuba_{shape}_{material}_{size}_truth_{truth_tag}.npz" if cache else None
    params = {"shape": shape, "material": material, **MATERIALS[material], "kd": list(kd),
              "textured": textured, "size": size, "spp": spp, "near_distance": near_distance}
    d = truth = None
    if out_file is not None and out_file.is_file():
        with np.load(out_file, allow_pickle=False) as z:
            d = {"images": z["images"], "light_dirs": z["light_dirs"], "params": json.loads(str(z["params"]))}
    if truth_file is not None and truth_file.is_file():
        with np.load(truth_file, allow_pickle=False) as z:
            truth = {k: z[k] for k in z.files}
    if d is None or truth is None:
        rendered = _render(shape, material, size, spp, kd, textured, lights, near_distance, max_depth,
                           variant, seed, images=d is None)
        if d is None:
            d = {"images": rendered.pop("images"), "light_dirs": lights.astype(np.float64), "params": params}
            if out_file is not None:
                out_file.parent.mkdir(parents=True, exist_ok=True)
                np.savez_compressed(out_file, images=d["images"], light_dirs=d["light_dirs"],
                                    params=json.dumps(params))
        truth = rendered
        if truth_file is not None:
            truth_file.parent.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(truth_file, **truth)
    d.update(truth)
    return d


def _render(shape, material, size, spp, kd, textured, lights, near_distance, max_depth, variant, seed,
            images=True):
    """Mitsuba renders of one scene: the images (one per light, when `images`) and the truth.

    The truth is the pixel mean, like the images: the `aov` integrator at `spp` samples
    through the same box filter, the normal renormalised. One sample per pixel (a random
    point inside it) scattered 0.53° (sphere) to 0.58° (relief) around that mean, a floor
    under every error measured against it. Pixels the surface covers for less than about
    half are outside the mask (|mean normal| ≤ 0.5)."""
    import mitsuba as mi
    # scalar_rgb: the llvm variants need an LLVM that matches Dr.Jit (the Debian one aborts in the
    # code generator here); scalar is slower but renders the same images
    mi.set_variant(variant or "scalar_rgb")
    T = mi.ScalarTransform4f
    kd_img = _kd_texture(textured, kd)
    bsdf = _bsdf(mi, material, kd_img)
    tmp = None
    shapes = {}
    if shape == "sphere":
        shapes["obj"] = {"type": "sphere", "radius": 0.9, "bsdf": bsdf}
    elif shape == "table":
        for k, (centre, radius) in enumerate(TABLE_DOMES):
            shapes[f"dome{k}"] = {"type": "sphere", "center": list(centre), "radius": radius, "bsdf": bsdf}
        shapes["table"] = {"type": "rectangle", "to_world": T.scale([1.5, 1.5, 1.0]),
                           "bsdf": _bsdf(mi, TABLE_MATERIAL, _kd_texture(False, TABLE_KD))}
    else:
        import tempfile
        tmp = tempfile.TemporaryDirectory()
        ply = Path(tmp.name) / f"{shape}.ply"
        _write_ply(ply, *_heightfield(shape))
        shapes["obj"] = {"type": "ply", "filename": str(ply), "bsdf": bsdf, "face_normals": False}
    sensor = {"type": "orthographic",
              "to_world": T.look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
              "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                       "pixel_format": "rgb"},
              "sampler": {"type": "independent", "sample_count": spp}}
    out = {}
    if images:
        imgs = []
        for i, s in enumerate(lights):
            if near_distance is None:
                emitter = {"type": "directional", "direction": (-s).tolist(),
                           "irradiance": {"type": "rgb", "value": 1.0}}
            else:
                # point light of intensity d^2: irradiance 1 at the scene centre, like the directional case
                emitter = {"type": "point", "position": (s * near_distance).tolist(),
                           "intensity": {"type": "rgb", "value": float(near_distance) ** 2}}
            scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": max_depth},
                                  "sensor": sensor, **shapes, "light": emitter})
            imgs.append(np.array(mi.render(scene, seed=seed + 7919 * i), dtype=np.float32)[..., :3])
        out["images"] = np.stack(imgs)
    aov = mi.load_dict({"type": "scene", "integrator": {"type": "aov", "aovs": "nn:sh_normal,pp:position,kd:albedo"},
                        "sensor": sensor, **shapes})
    a = np.array(mi.render(aov, seed=seed + 104729), dtype=np.float32)
    nrm, pos = a[..., 0:3], a[..., 3:6]
    if tmp is not None:
        tmp.cleanup()
    ln = np.linalg.norm(nrm, axis=-1)
    mask = ln > 0.5
    nrm = np.where(mask[..., None], nrm / np.maximum(ln, 1e-9)[..., None], 0).astype(np.float32)
    # true K_d per pixel: the renderer's own diffuse reflectance, its mean over the pixel (the
    # silhouette's pixels mix in the background's 0: the benches erode the mask by 1 px)
    kd_map = np.where(mask[..., None], a[..., 6:9], 0)
    out.update(normals=nrm, mask=mask, kd=kd_map.astype(np.float32), positions=pos.astype(np.float32))
    return out
