"""A metal's lobe in the BRDF fit: Cook–Torrance with an index above the dielectrics' (its F0)."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.brdf import cook_torrance1982
from facette.fit import fit_brdf
from facette.fit._cells import METAL_N_I_MAX


def _samples(n=3000, seed=0):
    rng = np.random.default_rng(seed)

    def hemi(k):
        v = rng.normal(size=(k, 3))
        v[:, 2] = np.abs(v[:, 2])
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        return v[v[:, 2] > 0.15]
    s, o = hemi(n), hemi(n)
    m = min(len(s), len(o))
    s, o = s[:m], o[:m]
    # half the pairs near the mirror direction, where a metal shows anything at all
    near = np.arange(m) < m // 2
    mirror = np.stack([-o[:, 0], -o[:, 1], o[:, 2]], 1) + rng.normal(scale=0.15, size=(m, 3))
    mirror[:, 2] = np.abs(mirror[:, 2]) + 0.2
    s[near] = (mirror / np.linalg.norm(mirror, axis=1, keepdims=True))[near]
    return s, o


def test_a_bare_metal_is_fitted_with_its_index_and_roughness_where_a_dielectric_cannot_be():
    s, o = _samples()
    f = cook_torrance1982(s, o, np.zeros(3), 0.2, 20.0)
    f = np.repeat(np.asarray(f)[:, None], 3, axis=1) if np.ndim(f) == 1 else f
    f = f * (1 + 0.01 * np.random.default_rng(1).normal(size=f.shape))
    metal = fit_brdf(s, o, f, model="cook_torrance", n_i_max=METAL_N_I_MAX, select=False)
    dielectric = fit_brdf(s, o, f, model="cook_torrance", select=False)
    assert metal.success and abs(metal.params["sigma"] - 0.2) < 0.01, metal.params
    assert 15 < metal.params["n_i"] < 26, metal.params             # F0 0.77-0.86 against 0.82
    assert np.all(np.asarray(metal.params["kd"]) < 0.02)
    assert metal.error["relative_rms"] < 0.05
    assert dielectric.params["n_i"] <= 2.5 + 1e-9 and dielectric.error["relative_rms"] > 3 * metal.error["relative_rms"]


def test_the_metal_bound_is_for_cook_torrance_only():
    s, o = _samples(200)
    with pytest.raises(ValueError, match="Cook–Torrance"):
        fit_brdf(s, o, np.ones((len(s), 3)), model="li", n_i_max=METAL_N_I_MAX)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("mitsuba")


def _process_render(material, cache, tmp_path):
    """`process` (normals, brdf, gltf) of a Mitsuba sphere written as a DiLiGenT-style folder."""
    from facette.io.diligent import write_diligent
    from facette.pipeline import ProcessOptions, process
    d = render_scene("sphere", material, size=64, spp=16, cache_dir=cache)
    im = d["images"]
    k = 60000.0 / float(np.nanmax(im))
    folder = tmp_path / material
    write_diligent(folder, np.clip(np.round(im * k), 0, 65535).astype(np.uint16), d["light_dirs"],
                   np.full((len(im), 3), k / 65535.0), d["mask"])
    res = process(folder, outputs=["normals", "brdf", "gltf"], out_dir=tmp_path / "out",
                  options=ProcessOptions(method="li_alternating"))
    return d, res


def _metallic_texture(glb_path, tmp_path):
    """The metallic channel (B) of the .glb's metallicRoughness texture, as written."""
    import pygltflib

    from facette.io.png import read_png
    doc = pygltflib.GLTF2().load(str(glb_path))
    tex = doc.materials[0].pbrMetallicRoughness.metallicRoughnessTexture.index
    view = doc.bufferViews[doc.images[doc.textures[tex].source].bufferView]
    png = tmp_path / "mr.png"
    png.write_bytes(doc.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength])
    return read_png(png)[..., 2], doc


def test_a_bare_metal_exports_as_glTF_metal_that_the_khronos_validator_accepts(cache, tmp_path, khronos_validate):
    # Mitsuba aluminium (roughconductor, no diffuse part): the fit is a metal's lobe, and the glTF
    # material is metallic (1 on the fitted pixels) with no dielectric's IOR
    d, res = _process_render("aluminium", cache, tmp_path)
    assert res.brdf.models_tried[0]["model"] == "metal" and res.brdf.params["n_i"] > 2.5, res.brdf.models_tried
    glb = tmp_path / "out" / "model.glb"
    report = khronos_validate(glb)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    metallic, doc = _metallic_texture(glb, tmp_path)
    assert metallic.max() == 255 and metallic.min() == 0    # metal where fitted, 0 elsewhere
    assert "KHR_materials_ior" not in (doc.extensionsUsed or [])


def test_the_pipeline_fits_a_metallic_paint_as_a_metal_lobe_and_exports_it(cache, tmp_path, khronos_validate):
    # Mitsuba's blend of a copper roughconductor (α 0.2) and a diffuse base: photometric stereo finds
    # a metal's lobe, so the BRDF fit tries "metal" first; it fits where li and Cook–Torrance did not
    d, res = _process_render("metallic_paint", cache, tmp_path)
    mat = res.ps.info["materials"][0]
    assert mat["diffuse"] == "lambert" and mat["n_i"] > 2.5, mat["model_choice"]
    fit = res.brdf
    assert fit.models_tried[0]["model"] == "metal" and fit.model == "cook_torrance", fit.models_tried
    assert fit.params["n_i"] > 2.5 and abs(fit.params["sigma"] - 0.2) < 0.04, fit.params
    sel = binary_erosion(d["mask"]) & res.ps.valid
    err = np.degrees(np.arccos(np.clip(np.sum(res.ps.normal * d["normals"], -1), -1, 1)))[sel]
    assert err.mean() < 3.0
    # glTF's metal has no diffuse part: metallic where the lobe's F0 outweighs the mean K_d (here
    # F0 ~0.3 against K_d ~0.25, half the base's: the blend's weight), a dielectric otherwise; no IOR
    glb = tmp_path / "out" / "model.glb"
    assert khronos_validate(glb)["issues"]["numErrors"] == 0
    metallic, doc = _metallic_texture(glb, tmp_path)
    n = fit.params["n_i"]
    assert (metallic.max() == 255) == (((n - 1) / (n + 1)) ** 2 > np.mean(fit.params["kd"]))
    assert "KHR_materials_ior" not in (doc.extensionsUsed or [])
