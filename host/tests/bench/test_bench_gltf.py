"""`facette bench gltf`'s pieces: the 'before' glb is the run without its relighting model (one material),
and three.js draws both."""
import numpy as np
import pygltflib

from facette.bench.gltf import _before_glb, _psnr
from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.recon.synthetic import render, sphere_on_plane


def test_before_is_the_one_material_glb(tmp_path, khronos_validate):
    rng = np.random.default_rng(2)
    d = rng.normal(size=(16, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.0
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sc = sphere_on_plane(24, 28)
    imgs = render(sc, d, "matte")
    write_diligent(tmp_path / "c", np.round(imgs / imgs.max() * 60000).astype(np.uint16), d, mask=sc.mask)
    res = process(tmp_path / "c", outputs=["gltf", "relight"], out_dir=tmp_path / "o", method="woodham1980",
                  shadows="off")
    material = _before_glb(res, tmp_path / "before.glb")
    assert "maps" not in material and res.relight_model is not None       # the run keeps its model
    assert khronos_validate(tmp_path / "before.glb")["issues"]["numErrors"] == 0
    before, after = (pygltflib.GLTF2().load(str(p)) for p in (tmp_path / "before.glb", tmp_path / "o" / "model.glb"))
    assert len(before.images) == 3 and not before.materials[0].extensions
    assert "KHR_materials_specular" in after.materials[0].extensions
    assert _psnr(np.zeros(4), np.full(4, 255.0)) == 0.0 and _psnr(np.ones(3), np.ones(3)) == float("inf")
