"""pipeline._gltf_maps: model.glb's per-pixel base colour, F0 and roughness from the relighting model,
on a rendered object whose left half is a satin orange and whose right half a matte blue."""
import io

import numpy as np
import pygltflib
import pytest
from PIL import Image

from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.pipeline._exports import srgb_encode
from facette.pipeline._gltf_maps import (DIELECTRIC_F0, f0_of_lobe, ggx_alpha_of_exponent, model_step,
                                         roughness_of_lobe)
from facette.recon.synthetic import render, sphere_on_plane

H, W = 40, 48


def _two_materials(tmp_path, m=24):
    rng = np.random.default_rng(5)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sc = sphere_on_plane(H, W, radius=14)
    left = np.arange(W) < W // 2
    imgs = np.where(left[None, None, :, None], render(sc, d, "satin", albedo=(0.7, 0.45, 0.2)),
                    render(sc, d, "matte", albedo=(0.2, 0.35, 0.7)))
    write_diligent(tmp_path / "objPNG", np.round(imgs / imgs.max() * 60000).astype(np.uint16), d, mask=sc.mask)
    return tmp_path / "objPNG", left


def _textures(glb):
    """{image name: (h, w, 3) uint8} of a .glb, and its material's extensions."""
    doc = pygltflib.GLTF2().load(str(glb))
    blob = doc.binary_blob()
    out = {}
    for img in doc.images:
        v = doc.bufferViews[img.bufferView]
        with Image.open(io.BytesIO(blob[v.byteOffset:v.byteOffset + v.byteLength])) as im:
            out[img.name] = np.asarray(im.convert("RGB"))
    return out, doc.materials[0].extensions


def _linear(u8):
    x = u8 / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def test_the_glb_carries_the_models_maps_and_they_follow_the_materials(tmp_path, khronos_validate):
    folder, left = _two_materials(tmp_path)
    res = process(folder, outputs=["gltf", "relight"], out_dir=tmp_path / "o", method="woodham1980",
                  shadows="off")
    glb = tmp_path / "o" / "model.glb"
    report = khronos_validate(glb)
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report["issues"]["messages"]
    assert report["info"]["extensionsUsed"] == ["KHR_materials_specular"]
    tex, ext = _textures(glb)
    spec = ext["KHR_materials_specular"]
    model, mask = res.relight_model, res.relight_model.mask
    assert tex["baseColor"].shape == tex["specularColor"].shape == (H, W, 3)
    # every pixel's model: the base colour is its K_d map (ρ), in sRGB
    scale = 1 / max(1.0, np.percentile(model.rho[mask], 99.5))
    np.testing.assert_array_equal(tex["baseColor"][mask], srgb_encode(model.rho * scale)[mask])
    # F0 = 0.04 x specularColorFactor x texel = 8 s / (k + 2)
    f0 = DIELECTRIC_F0 * spec["specularColorFactor"][0] * _linear(tex["specularColor"].astype(float))
    want = np.minimum(8 * model.spec * scale / (model.shininess + 2), 1.0)
    lit = mask & (want.max(-1) < DIELECTRIC_F0 * spec["specularColorFactor"][0])     # below the texture's white
    assert np.abs(f0 - want)[lit].max() < 0.01 * want.max() + 1e-4
    # the satin half has a lobe, the matte half next to none; the roughness says so too
    sphere = mask & (np.hypot(*np.mgrid[0:H, 0:W] - np.array([(H - 1) / 2, (W - 1) / 2])[:, None, None]) < 12)
    f0_l, f0_r = (np.median(f0[sphere & side].max(-1)) for side in (left, ~left))
    assert f0_l > 0.02 and f0_l > 10 * f0_r, (f0_l, f0_r)
    rough = tex["metallicRoughness"][..., 1] / 255.0
    assert np.median(rough[sphere & left]) < 0.8 < np.median(rough[sphere & ~left])
    assert (tex["metallicRoughness"][..., 2] == 0).all()                 # no metal
    # the base colours: orange on the left, blue on the right
    base = tex["baseColor"].astype(float)
    assert np.median(base[sphere & left, 0]) > np.median(base[sphere & left, 2]) + 40
    assert np.median(base[sphere & ~left, 2]) > np.median(base[sphere & ~left, 0]) + 40


def test_a_model_at_the_reports_size_gives_coarser_material_maps_over_full_size_colour(tmp_path, monkeypatch,
                                                                                     khronos_validate):
    """--outputs gltf fits the model at the report viewer's size (here forced to 20 px a side: every 3rd
    pixel): F0 and roughness at that size, the base colour the albedo at full size in ρ's unit."""
    import facette.pipeline._relight_model_stage as stage
    monkeypatch.setattr(stage, "MAX_SIDE", 20)
    folder, _ = _two_materials(tmp_path)
    res = process(folder, outputs=["gltf"], out_dir=tmp_path / "o", method="woodham1980", shadows="off")
    assert res.relight_model.mask.shape == (14, 16) and model_step((H, W), (14, 16)) == 3
    glb = tmp_path / "o" / "model.glb"
    assert khronos_validate(glb)["issues"]["numErrors"] == 0
    tex, _ = _textures(glb)
    assert tex["baseColor"].shape == (H, W, 3) and tex["specularColor"].shape == tex["metallicRoughness"].shape \
        == (14, 16, 3)
    assert any("glTF maps from the relighting model (16x14, one pixel in 3" in n for n in res.notes), res.notes


def test_without_a_model_the_glb_says_so_and_keeps_one_roughness(tmp_path):
    class Res:
        relight_model = None
        mask = np.ones((4, 4), bool)
    from facette.pipeline._gltf_maps import relight_maps
    maps, notes = relight_maps(Res())
    assert maps is None and "no relighting model" in notes[0] and "one roughness" in notes[0]


@pytest.mark.parametrize("k", [8.0, 32.0, 128.0])
def test_the_gltf_lobe_has_the_models_peak(k):
    """glTF's specular BRDF (glTF 2.0 Appendix B: GGX D, height-correlated Smith V, Schlick F) with
    F0 = 8 s / (k + 2) and α = sqrt(2 / (k + 2)), at n = l = v, times (n·l) E with E = π (the model's
    unit), is the model's lobe peak s."""
    s = 0.3
    alpha = float(ggx_alpha_of_exponent(k))
    f0 = float(f0_of_lobe(np.array([s]), k)[0])
    a2 = alpha ** 2
    ndh = ndl = ndv = 1.0
    d = a2 / (np.pi * (ndh ** 2 * (a2 - 1) + 1) ** 2)
    v = 0.5 / (ndl * np.sqrt(ndv ** 2 * (1 - a2) + a2) + ndv * np.sqrt(ndl ** 2 * (1 - a2) + a2))
    assert f0 * d * v * ndl * np.pi == pytest.approx(s)
    # the roughness: sqrt(α) for a lobe at least glass's, 1 for none, between in between
    r = roughness_of_lobe(np.array([[0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [0.02, 0.01, 0.0]]), k)
    assert r[0] == pytest.approx(np.sqrt(alpha)) and r[1] == 1.0
    assert r[2] == pytest.approx(np.sqrt(alpha) + (1 - np.sqrt(alpha)) * 0.5)
