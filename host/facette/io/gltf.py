"""glTF 2.0 binary (.glb) of a textured mesh with a metallic-roughness material (pygltflib).

One mesh, one primitive (triangles; POSITION, NORMAL, TANGENT, TEXCOORD_0), one material
with base colour, normal and metallic-roughness textures embedded as PNG, and optionally a
per-pixel F0 colour (KHR_materials_specular's specularColorTexture). glTF's frame is
the camera frame of facette (x right, y up, z towards the viewer) and its unit is the metre.
"""
import json

import numpy as np
import pygltflib as gl

from facette._threads import run_blocks
from facette.io.atomic import write_bytes_atomic
from facette.io.png import encode_png

__all__ = ["write_glb"]

# zlib level of the embedded textures: 1 encodes a 2144 x 1424 normal map in 0.17 s against
# 1.0 s at level 6; the same pixels, a 12 MP scan's model.glb 61.6 MB instead of 60.5
PNG_LEVEL = 1


def _u8_image(name, img, channels):
    img = np.asarray(img)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != channels or 0 in img.shape:
        raise ValueError(f"{name} must be a (H, W, {channels}) uint8 image, got {img.shape} {img.dtype}")
    return encode_png(img, compression=PNG_LEVEL)


def _specular(specular, texture):
    """(KHR_materials_specular's dict or None, the PNG of its colour texture or None); `texture`: the
    index that texture gets."""
    if specular is None:
        return None, None
    factor, colour_factor = float(specular.get("factor", 1.0)), float(specular.get("color_factor", 1.0))
    if not (0.0 <= factor <= 1.0 and np.isfinite(colour_factor) and colour_factor >= 0):
        raise ValueError(f"specular factor must be in [0, 1] and color_factor finite >= 0, got {factor}, "
                         f"{colour_factor}")
    ext = {"specularFactor": factor, "specularColorFactor": [colour_factor] * 3}
    if specular.get("color") is None:
        return ext, None
    ext["specularColorTexture"] = {"index": texture}
    return ext, _u8_image("specular color", specular["color"], 3)


def write_glb(path, vertices_mm, faces, normals, tangents, uv, base_color, normal_map,
              metallic_roughness, ior=None, name="facette scan", extras=None, specular=None):
    """Write a .glb.

    vertices_mm (V, 3) float, mm (written in metres); faces (F, 3) int indices in [0, V),
    counter-clockwise seen from outside; normals (V, 3) unit; tangents (V, 4): unit xyz
    along +u and the handedness w = ±1; uv (V, 2) in [0, 1], v down (glTF's convention:
    image row 0 at v = 0). Textures (H, W, 3) uint8: base_color sRGB-encoded; normal_map
    tangent-space, (n + 1) / 2 · 255; metallic_roughness with roughness in G and metallic
    in B (glTF's channels). ior : index of refraction (KHR_materials_ior), or None for
    glTF's default 1.5. extras : a dict stored as the asset's extras (e.g. that the scan was
    incomplete), shown by viewers that list the asset's metadata. specular : None, or
    KHR_materials_specular's {"color": (h, w, 3) uint8 sRGB-encoded F0 colour or None,
    "color_factor": its multiplier (glTF's F0 = 0.04 · color_factor · texel, may exceed 1),
    "factor": the specular strength in [0, 1]}. Textures may differ in size (uv spans each).
    """
    v = np.asarray(vertices_mm, np.float64)
    f = np.asarray(faces)
    n = np.asarray(normals, np.float64)
    t = np.asarray(tangents, np.float64)
    uv = np.asarray(uv, np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
        raise ValueError(f"vertices must have shape (V, 3) with V > 0, got {v.shape}")
    nv = len(v)
    for label, arr, k in (("normals", n, 3), ("tangents", t, 4), ("uv", uv, 2)):
        if arr.shape != (nv, k):
            raise ValueError(f"{label} must have shape ({nv}, {k}), got {arr.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ValueError(f"faces must have shape (F, 3) with F > 0, got {f.shape}")
    if f.min() < 0 or f.max() >= nv:
        raise ValueError(f"face indices must be in [0, {nv}), found {f.min()}..{f.max()}")
    for label, arr in (("vertices", v), ("normals", n), ("tangents", t), ("uv", uv)):
        if not np.isfinite(arr).all():
            raise ValueError(f"{label} must be finite")
    # the textures encoded two at a time (OpenCV's encoder gives the GIL up): 4288x2848, 0.3 CPU s
    encodes = [lambda: _u8_image("base_color", base_color, 3), lambda: _u8_image("normal_map", normal_map, 3),
               lambda: _u8_image("metallic_roughness", metallic_roughness, 3), lambda: _specular(specular, 3)]
    *pngs, (spec_ext, spec_png) = run_blocks(lambda encode: encode(), encodes)
    labels = ["baseColor", "normal", "metallicRoughness"]
    if spec_png is not None:
        pngs.append(spec_png)
        labels.append("specularColor")

    pos = (v * 1e-3).astype("<f4")
    arrays = [pos, n.astype("<f4"), t.astype("<f4"), uv.astype("<f4"), f.astype("<u4").ravel()]
    blob = bytearray()
    views = []

    def add(data, target=None):
        while len(blob) % 4:
            blob.append(0)
        views.append(gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        blob.extend(data)
        return len(views) - 1

    acc = []
    for k, (arr, typ) in enumerate(zip(arrays[:4], (gl.VEC3, gl.VEC3, gl.VEC4, gl.VEC2))):
        view = add(arr.tobytes(), gl.ARRAY_BUFFER)
        a = gl.Accessor(bufferView=view, componentType=gl.FLOAT, count=nv, type=typ)
        if k == 0:                                       # glTF requires POSITION's bounds
            a.min, a.max = pos.min(axis=0).tolist(), pos.max(axis=0).tolist()
        acc.append(a)
    view = add(arrays[4].tobytes(), gl.ELEMENT_ARRAY_BUFFER)
    acc.append(gl.Accessor(bufferView=view, componentType=gl.UNSIGNED_INT, count=int(arrays[4].size),
                           type=gl.SCALAR))
    images = [gl.Image(bufferView=add(png), mimeType=gl.IMAGEPNG, name=label) for png, label in zip(pngs, labels)]

    material = gl.Material(
        name="facette LI fit",
        pbrMetallicRoughness=gl.PbrMetallicRoughness(
            baseColorTexture=gl.TextureInfo(index=0), metallicRoughnessTexture=gl.TextureInfo(index=2),
            metallicFactor=1.0, roughnessFactor=1.0),
        normalTexture=gl.NormalMaterialTexture(index=1), doubleSided=False)
    ext = {}
    if ior is not None:
        if not 1.0 <= float(ior) <= 10.0:
            raise ValueError(f"ior must be in [1, 10], got {ior}")
        ext["KHR_materials_ior"] = {"ior": float(ior)}
    if spec_ext is not None:
        ext["KHR_materials_specular"] = spec_ext
    if ext:
        material.extensions = ext
    extensions = sorted(ext)
    doc = gl.GLTF2(
        asset=gl.Asset(version="2.0", generator="facette", extras=dict(extras or {})),
        scene=0, scenes=[gl.Scene(nodes=[0])], nodes=[gl.Node(mesh=0, name=name)],
        meshes=[gl.Mesh(name=name, primitives=[gl.Primitive(
            attributes=gl.Attributes(POSITION=0, NORMAL=1, TANGENT=2, TEXCOORD_0=3),
            indices=4, material=0, mode=gl.TRIANGLES)])],
        accessors=acc, bufferViews=views, buffers=[gl.Buffer(byteLength=0)],
        images=images, samplers=[gl.Sampler(magFilter=gl.LINEAR, minFilter=gl.LINEAR_MIPMAP_LINEAR,
                                            wrapS=gl.CLAMP_TO_EDGE, wrapT=gl.CLAMP_TO_EDGE)],
        textures=[gl.Texture(sampler=0, source=i) for i in range(len(pngs))],
        materials=[material], extensionsUsed=extensions)
    while len(blob) % 4:
        blob.append(0)
    doc.buffers[0].byteLength = len(blob)
    doc.set_binary_blob(bytes(blob))
    write_bytes_atomic(path, b"".join(doc.save_to_bytes()))
    return json.loads(doc.to_json())
