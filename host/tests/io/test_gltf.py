"""io.gltf: .glb files that the Khronos glTF validator accepts, and what they carry."""
import numpy as np
import pygltflib
import pytest

from facette.io.gltf import write_glb
from facette.io.png import read_png
from facette.pipeline._exports import (gltf_roughness, srgb_encode, tangent_space_normal_map,
                                       vertex_normals, vertex_tangents)
from facette.recon import mesh_from_height
from facette.recon.synthetic import sphere_on_plane

def _scene(h=30, w=40, pitch=0.1):
    sc = sphere_on_plane(h, w)
    height = sc.height * pitch
    verts, faces = mesh_from_height(height, sc.mask, pitch)
    n = vertex_normals(verts, faces)
    uv = np.stack([(verts[:, 0] / pitch + 0.5) / w, (-verts[:, 1] / pitch + 0.5) / h], 1)
    albedo = np.broadcast_to([0.6, 0.5, 0.4], (h, w, 3))
    mr = np.zeros((h, w, 3), np.uint8)
    mr[..., 1] = 128
    return sc, dict(vertices_mm=verts, faces=faces, normals=n, tangents=vertex_tangents(n), uv=uv,
                    base_color=srgb_encode(albedo),
                    normal_map=tangent_space_normal_map(sc.normals, height, sc.mask, pitch),
                    metallic_roughness=mr)


def test_the_khronos_validator_finds_no_error_and_no_warning(tmp_path, khronos_validate):
    _, kw = _scene()
    write_glb(tmp_path / "m.glb", ior=1.3, **kw)
    report = khronos_validate(tmp_path / "m.glb")
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    assert report["issues"]["numWarnings"] == 0, report["issues"]["messages"]
    assert report["info"]["extensionsUsed"] == ["KHR_materials_ior"]


def test_the_validator_does_report_a_broken_file(tmp_path, khronos_validate):
    """The check above can fail: a .glb whose index buffer is cut short is an error."""
    _, kw = _scene()
    write_glb(tmp_path / "m.glb", **kw)
    doc = pygltflib.GLTF2().load(str(tmp_path / "m.glb"))
    doc.accessors[4].count += 300
    doc.save(str(tmp_path / "bad.glb"))
    assert khronos_validate(tmp_path / "bad.glb")["issues"]["numErrors"] > 0


def test_mesh_in_metres_textures_and_material(tmp_path):
    sc, kw = _scene()
    info = write_glb(tmp_path / "m.glb", **kw)
    doc = pygltflib.GLTF2().load(str(tmp_path / "m.glb"))
    blob = doc.binary_blob()
    acc = doc.accessors[doc.meshes[0].primitives[0].attributes.POSITION]
    view = doc.bufferViews[acc.bufferView]
    pos = np.frombuffer(blob, "<f4", acc.count * 3, view.byteOffset).reshape(-1, 3)
    np.testing.assert_allclose(pos, kw["vertices_mm"] * 1e-3, rtol=1e-6)
    assert acc.count == sc.mask.sum() and info["asset"]["version"] == "2.0"
    pbr = doc.materials[0].pbrMetallicRoughness
    assert pbr.baseColorTexture.index == 0 and pbr.metallicRoughnessTexture.index == 2
    assert doc.materials[0].normalTexture.index == 1
    img = doc.images[1]
    v = doc.bufferViews[img.bufferView]
    (tmp_path / "n.png").write_bytes(blob[v.byteOffset:v.byteOffset + v.byteLength])
    np.testing.assert_array_equal(read_png(tmp_path / "n.png"), kw["normal_map"])


def test_normal_map_of_normals_that_match_the_mesh_is_flat():
    """Where the PS normals are the mesh's own surface normals the texels are (0, 0, 1)."""
    h, w, pitch = 20, 24, 0.5
    yy, xx = np.mgrid[0:h, 0:w]
    height = 0.2 * xx * pitch + 0.1 * (-yy) * pitch                # a tilted plane
    n = np.array([-0.2, -0.1, 1.0]) / np.linalg.norm([-0.2, -0.1, 1.0])
    tex = tangent_space_normal_map(np.broadcast_to(n, (h, w, 3)), height, np.ones((h, w), bool), pitch)
    inner = tex[2:-2, 2:-2].reshape(-1, 3).astype(int)
    assert np.all(np.abs(inner - [128, 128, 255]) <= 1)
    # a normal tilted to +x of the mesh shows up in the red channel
    tilted = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
    flat = tangent_space_normal_map(np.broadcast_to(tilted, (h, w, 3)), np.zeros((h, w)),
                                    np.ones((h, w), bool), pitch)
    assert flat[5, 5, 0] == round((tilted[0] + 1) / 2 * 255) and flat[5, 5, 1] == 128


def test_roughness_from_sigma():
    assert gltf_roughness(0.04) == pytest.approx(0.2)           # GGX alpha = sigma, roughness^2
    assert gltf_roughness(0.04, "ggx") == pytest.approx(0.2)
    assert gltf_roughness(0.02, "gaussian") == pytest.approx(np.sqrt(np.sqrt(2) * 0.02))
    assert gltf_roughness(0.0) == 0.0 and gltf_roughness(2.0) == 1.0
    with pytest.raises(ValueError, match="sigma"):
        gltf_roughness(-0.1)
    with pytest.raises(ValueError, match="distribution"):
        gltf_roughness(0.1, "phong")


def test_vertex_normals_of_a_flat_square_point_up_and_tangents_along_x():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, -1, 0], [1, -1, 0]], float)
    f = np.array([[0, 2, 1], [1, 2, 3]])
    n = vertex_normals(v, f)
    np.testing.assert_allclose(n, np.tile([0, 0, 1.0], (4, 1)))
    np.testing.assert_allclose(vertex_tangents(n), np.tile([1.0, 0, 0, 1], (4, 1)))


@pytest.mark.parametrize("change, match", [
    (dict(faces=np.array([[0, 1, 99999]])), "face indices"),
    (dict(uv=np.zeros((3, 2))), "uv must have shape"),
    (dict(base_color=np.zeros((4, 4, 3), np.float32)), "base_color"),
    (dict(ior=0.5), "ior"),
])
def test_bad_input_is_refused(tmp_path, change, match):
    _, kw = _scene()
    kw.update(change)
    with pytest.raises(ValueError, match=match):
        write_glb(tmp_path / "m.glb", **kw)
    assert not (tmp_path / "m.glb").exists()


def test_srgb_encoding_values_and_edges():
    out = srgb_encode([-1.0, 0.0, 0.0031308, 0.5, 1.0, 7.0, np.nan])
    assert out.tolist() == [0, 0, 10, 188, 255, 255, 0]   # 12.92 x 0.0031308 = 0.0404


def test_a_per_pixel_f0_colour_of_its_own_size_validates(tmp_path, khronos_validate):
    """KHR_materials_specular: an F0 colour texture smaller than the others (the relighting model's
    size), its factor above 1 (F0 = 0.04 x factor x texel), accepted by the Khronos validator."""
    _, kw = _scene()
    colour = np.zeros((10, 12, 3), np.uint8)
    colour[:, 6:] = 200
    write_glb(tmp_path / "m.glb", specular={"color": colour, "color_factor": 12.5, "factor": 1.0}, **kw)
    report = khronos_validate(tmp_path / "m.glb")
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report["issues"]["messages"]
    doc = pygltflib.GLTF2().load(str(tmp_path / "m.glb"))
    ext = doc.materials[0].extensions["KHR_materials_specular"]
    assert ext == {"specularFactor": 1.0, "specularColorFactor": [12.5] * 3, "specularColorTexture": {"index": 3}}
    assert doc.extensionsUsed == ["KHR_materials_specular"] and doc.images[3].name == "specularColor"
    with pytest.raises(ValueError, match="specular factor"):
        write_glb(tmp_path / "n.glb", specular={"color": colour, "color_factor": 1.0, "factor": 2.0}, **kw)
