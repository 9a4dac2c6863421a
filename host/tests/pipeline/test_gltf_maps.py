"""pipeline._gltf_maps: model.glb's per-pixel base colour, F0 and roughness from the relighting model,
on a rendered object whose left half is a satin orange and whose right half a matte blue."""
import io

import numpy as np
import pygltflib
import pytest
from PIL import Image

from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.pipeline._gltf_maps import (DIELECTRIC_F0, ggx_alpha_of_exponent, ggx_lobe, model_step,
                                         relight_maps, roughness_of_lobe)
from facette.recon._relight_model import physical_basis
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
    # what a glTF viewer computes from the textures (diffuse c (1 - max F0) (n·l), GGX lobe of the
    # roughness' α) is the model's physics under the captured lights, to a few per cent of white
    f0 = DIELECTRIC_F0 * spec["specularColorFactor"][0] * _linear(tex["specularColor"].astype(float))
    top = 1 / relight_maps(res)[0]["scale"][0]
    kd = _linear(tex["baseColor"].astype(float)) * (1 - f0.max(-1, keepdims=True))
    alpha2 = (tex["metallicRoughness"][..., 1] / 255.0) ** 4
    lights = res.inputs.light_dirs
    lobe_k = float(ggx_alpha_of_exponent(model.shininess) ** 2)
    glossy = alpha2 < lobe_k * 1.05          # texels of the model's lobe width (elsewhere weaker ones)
    errs, peak_errs = [], []
    for light in lights[::4]:
        b = physical_basis(model.normals, light[None], model.shininess)[0]
        want = model.rho * b[..., :1] + model.spec * b[..., 1:2] + model.amb * b[..., 2:3]
        nl = np.clip(model.normals @ light, 0, None)[..., None]
        lobe = ggx_lobe(model.normals, light[None], lobe_k)[0][..., None]
        got = top * (kd * nl + f0 * lobe)
        errs.append(np.abs(got - want)[mask & glossy].mean())
        # the lobes' peaks matched alone (F0 = 8 s / (k + 2), the rest diffuse): further off
        peak = (model.rho + model.amb) * nl + 8 * model.spec / (model.shininess + 2) * lobe
        peak_errs.append(np.abs(peak - want)[mask & glossy].mean())
    assert np.median(errs) < 0.05 and np.median(errs) < 0.8 * np.median(peak_errs), (errs, peak_errs)
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
    maps, notes = relight_maps(Res())
    assert maps is None and "no relighting model" in notes[0] and "one roughness" in notes[0]


@pytest.mark.parametrize("k", [8.0, 32.0, 128.0])
def test_the_gltf_lobe_is_glTFs_and_the_roughness_blends_to_1(k):
    """ggx_lobe is glTF 2.0 Appendix B's π D V (n·l): at n = l = v, 1 / (4 α²) (with F0 = 4 α² s it
    peaks at s, the model's lobe); it falls with the half-vector's angle as GGX does."""
    alpha = float(ggx_alpha_of_exponent(k))
    a2 = alpha ** 2
    z = np.array([[0.0, 0.0, 1.0]])
    assert ggx_lobe(z, z, a2)[0, 0] == pytest.approx(1 / (4 * a2), rel=1e-5)
    th = np.radians(30.0)
    light = np.array([[np.sin(th), 0.0, np.cos(th)]])
    c = np.cos(th / 2)
    d = a2 / (np.pi * (c * c * (a2 - 1) + 1) ** 2)
    v = 0.5 / (np.cos(th) * np.sqrt(a2 + (1 - a2)) + np.sqrt(np.cos(th) ** 2 * (1 - a2) + a2))
    assert ggx_lobe(z, light, a2)[0, 0] == pytest.approx(np.pi * d * v * np.cos(th), rel=1e-4)
    # the roughness: sqrt(α) for a lobe at least glass's, 1 for none, between in between
    r = roughness_of_lobe(np.array([[0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [0.02, 0.01, 0.0]]), k)
    assert r[0] == pytest.approx(np.sqrt(alpha)) and r[1] == 1.0
    assert r[2] == pytest.approx(np.sqrt(alpha) + (1 - np.sqrt(alpha)) * 0.5)


def test_three_js_draws_the_glb_as_the_models_physics(tmp_path):
    """three.js (GLTFLoader, MeshPhysicalMaterial, headless Chromium) draws model.glb under a light
    as the model's physics without cast shadows, in 8-bit display values: the maps' colour spaces,
    the exposure, the normal map's frame and the UVs are what a viewer reads."""
    from facette.bench._three import three_view
    from facette.recon import srgb_encode
    folder, left = _two_materials(tmp_path)
    res = process(folder, outputs=["gltf", "relight"], out_dir=tmp_path / "o", method="woodham1980",
                  shadows="off")
    model = res.relight_model
    top = 1 / relight_maps(res)[0]["scale"][0]
    inner = np.zeros((H, W), bool)
    inner[2:-2, 2:-2] = True                       # the mesh's outer half-pixel is no texel's centre
    inner &= model.mask
    with three_view(tmp_path / "o" / "model.glb", W, H, res.inputs.pixel_pitch_mm) as (draw, materials):
        assert materials == ["MeshPhysicalMaterial"]              # KHR_materials_specular read
        for light in res.inputs.light_dirs[::6]:
            pic = draw(light, np.pi * top).astype(float)
            b = physical_basis(model.normals, light[None], model.shininess)[0]
            phys = model.rho * b[..., :1] + model.spec * b[..., 1:2] + model.amb * b[..., 2:3]
            want = np.round(255 * srgb_encode(np.clip(phys, 0, 1)))
            diff = np.abs(pic - want)[inner]
            assert np.median(diff) <= 3 and diff.mean() < 8, (light, np.median(diff), diff.mean())
            dark = np.abs(pic - want)[inner & ~left[None, :].repeat(H, 0)]
            assert np.median(dark) <= 2                           # the matte half: diffuse alone
