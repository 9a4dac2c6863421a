"""RTI and glTF exports as outputs of `facette process`: on by default, left out on request."""
import numpy as np
import pytest

from facette.cli.main import main
from facette.pipeline import OUTPUTS, process, stages_needed
from facette.pipeline._exports import hsh_order_for
from facette.recon.synthetic import render, sphere_on_plane
from test_process import L, _write_scan


def test_exports_are_default_outputs_and_validate(tmp_path, capsys, khronos_validate):
    sc = sphere_on_plane(32, 40)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    assert {"ptm", "rti", "gltf"} <= set(OUTPUTS)
    status = main(["process", str(tmp_path / "scan"), "-o", str(tmp_path / "o"), "--brdf-model",
                   "lambert"])
    assert status == 0
    text = capsys.readouterr().out
    assert "ptm_relative_rms" in text and "hsh_relative_rms" in text
    for name in ("relight.ptm", "relight.rti", "model.glb"):
        assert (tmp_path / "o" / name).stat().st_size > 0
    assert (tmp_path / "o" / "relight.ptm").read_bytes().startswith(b"PTM_1.2\nPTM_FORMAT_LRGB\n40\n32\n")
    assert khronos_validate(tmp_path / "o" / "model.glb")["issues"]["numErrors"] == 0
    assert "glTF maps from the relighting model (40x32, every pixel)" in text


def test_outputs_can_leave_the_exports_out(tmp_path):
    sc = sphere_on_plane(24, 24)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    assert stages_needed(["ptm"]) == ["load", "ptm"]          # the images and the mask, not the normals
    assert stages_needed(["rti"]) == ["load", "hsh"]
    assert stages_needed(["relight-web"]) == ["load", "hsh"]
    assert stages_needed(["gltf"]) == ["load", "ps", "integrate", "mesh", "relight"]
    res = process(tmp_path / "scan", outputs=["normals", "ptm"], out_dir=tmp_path / "o")
    assert res.ptm is not None and res.hsh is None and "hsh" not in res.timings
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["normal.exr", "process.json", "relight.ptm"]
    assert 0 < res.fit_errors["ptm_relative_rms"] < 0.1
    res = process(tmp_path / "scan", outputs=["normals"], out_dir=tmp_path / "p")
    assert res.ptm is None and not res.fit_errors
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == ["normal.exr", "process.json"]


def test_gltf_with_an_empty_mask_is_not_written(tmp_path):
    """An empty mask cannot give any result (issue 14: no empty outputs with exit 0): the
    quality gate stops processing before anything is written."""
    from facette.errors import InsufficientData

    sc = sphere_on_plane(24, 24)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    with pytest.raises(InsufficientData, match="the given mask holds no pixel of the object"):
        process(tmp_path / "scan", outputs=["gltf"], out_dir=tmp_path / "o",
                mask=np.zeros((24, 24), bool), fit_options={"model": "lambert"})
    assert not (tmp_path / "o" / "model.glb").exists()


@pytest.mark.parametrize("encoding", ["srgb", "linear"])
def test_rti_files_hold_what_the_viewers_show_in_the_encoding_asked_for(tmp_path, encoding):
    """relight.ptm and relight.rti read back as RTIViewer/Relight read them give the fits'
    displayed values; relight.rti's header says the encoding; a wrong encoding is refused."""
    from facette.errors import BadInputError
    from facette.io.ptm import read_ptm
    from facette.io.rti import read_hsh_rti
    from facette.recon import display_hsh, display_ptm
    sc = sphere_on_plane(24, 32)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    res = process(tmp_path / "scan", outputs=["ptm", "rti"], out_dir=tmp_path / "o", rti_encoding=encoding)
    assert res.ptm.encoding == res.hsh.encoding == encoding
    ptm, rti = read_ptm(tmp_path / "o" / "relight.ptm"), read_hsh_rti(tmp_path / "o" / "relight.rti")
    assert rti.encoding == encoding and any(f"encoding: {encoding}" in c for c in rti.comments)
    obj = res.object_mask
    for d in L[::4]:
        assert np.abs(ptm.relight(d) - display_ptm(res.ptm, d))[obj].mean() < 0.01
        assert np.abs(rti.relight(d) - display_hsh(res.hsh, d))[obj].mean() < 0.01
    assert np.median(ptm.relight(L[0])[obj]) > 0.2                     # not black
    with pytest.raises(BadInputError, match="rti_encoding"):
        process(tmp_path / "scan", outputs=["ptm"], rti_encoding="gamma")


def _diligent(folder, n_lights, saturate=None):
    """A DiLiGenT-style folder of a matte sphere under the first `n_lights` thesis lights;
    `saturate`: (rows, cols, lights) set to 65535 (unusable) in those images."""
    from facette.io.diligent import write_diligent
    sc = sphere_on_plane(24, 32)
    imgs = render(sc, L[:n_lights], "matte")
    u16 = np.round(imgs / imgs.max() * 50000).astype(np.uint16)
    if saturate is not None:
        rows, cols, lights = saturate
        for i in lights:
            u16[i, rows, cols] = 65535
    write_diligent(folder, u16, L[:n_lights], np.ones((n_lights, 3)), sc.mask)
    return folder


def _ptm_coeff_bytes(path, w, h):
    data = path.read_bytes()
    head = data.split(b"\n", 6)
    return np.frombuffer(head[6], np.uint8, w * h * 6).reshape(h, w, 6)[::-1], head[5]


def test_fewer_lights_than_hsh_terms_fit_order_2_and_say_so(tmp_path, capsys):
    """6 lights cannot determine 9 HSH terms: order 2 is fitted (never an all-zero file)."""
    folder = _diligent(tmp_path / "six", 6)
    assert main(["process", str(folder), "-o", str(tmp_path / "o"), "--outputs", "normals,ptm,rti"]) == 0
    text = capsys.readouterr().out
    assert "relight.rti: HSH order 2 (4 terms) instead of 3 (9 terms): 6 lights" in text
    from facette.io.rti import read_hsh_rti
    rti = read_hsh_rti(tmp_path / "o" / "relight.rti")
    assert rti.terms == 4 and rti.coeffs.shape == (24, 32, 3, 4)
    assert np.median(rti.relight(L[0])) > 0.05 and np.ptp(rti.coeffs[..., 0]) > 0.1      # not blank
    import re
    rms = float(re.search(r"hsh_relative_rms\D*([0-9.]+)", text).group(1))
    assert rms < 0.5


def test_too_few_lights_for_a_ptm_write_none_and_say_so(tmp_path, capsys):
    folder = _diligent(tmp_path / "four", 4)
    assert main(["process", str(folder), "-o", str(tmp_path / "o"), "--outputs", "normals,ptm,rti"]) == 0
    text = capsys.readouterr().out
    assert "relight.rti: HSH order 2 (4 terms) instead of 3 (9 terms): 4 lights" in text
    assert "relight.ptm not written: no pixel of the mask has the 6 usable lights" in text
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["normal.exr", "process.json", "relight.rti"]
    assert hsh_order_for(3, 3) == (None, "relight.rti not written: 3 light(s) cannot determine even the 4 "
                                         "terms of HSH order 2 (scan at least 4 lights)")
    assert hsh_order_for(9, 3) == (3, None) and hsh_order_for(9, 2) == (2, None)


def test_clipped_pixels_are_fitted_as_photographed_at_full_brightness(tmp_path):
    """7 of 12 photographs clip on a patch (unknown to photometric stereo): the files show it white
    there under those lights, as the photographs do, and nothing is left out."""
    from facette.io.ptm import read_ptm
    from facette.io.rti import read_hsh_rti
    rows, cols = slice(10, 14), slice(14, 18)                      # on the sphere
    folder = _diligent(tmp_path / "sat", 12, (rows, cols, range(7)))
    res = process(folder, outputs=["ptm", "rti"], out_dir=tmp_path / "o")
    assert res.ps is None and not any("usable lights" in n for n in res.notes)
    assert res.rti_exposure.source == "photographs" and res.rti_exposure.encoding == "linear"
    ptm, rti = read_ptm(tmp_path / "o" / "relight.ptm"), read_hsh_rti(tmp_path / "o" / "relight.rti")
    # unclipped, the patch shows 0.54-0.60 under every light; clipped, the fits reach 0.77-1.00 there
    # (12 lights, 6 or 9 smooth terms: the clipped and the unclipped lights pull against each other)
    for f in (ptm, rti):
        clipped = np.mean([f.relight(L[k])[rows, cols].mean() for k in range(7)])
        assert clipped > 0.9 and np.mean([f.relight(L[k])[rows, cols].mean() for k in range(7, 12)]) < clipped - 0.2


def test_outputs_of_an_incomplete_scan_say_so_in_their_own_metadata(tmp_path):
    import json
    import pygltflib
    from facette.io.png import read_png_text
    sc = sphere_on_plane(24, 32)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    data = json.loads((tmp_path / "scan" / "scan.json").read_text())      # as a tool edits it
    data["exposures"].append({"index": 1, "time_us": 4000, "current_mA": 100, "mode": "camera"})
    (tmp_path / "scan" / "scan.json").write_text(json.dumps(data))         # a plan of 24 frames, 12 taken
    out = tmp_path / "o"
    res = process(tmp_path / "scan", outputs=["mask", "rti", "gltf"], out_dir=out, allow_incomplete=True,
                  fit_options={"model": "lambert"})
    said = "scan incomplete: 12 of 24 frames"
    assert said in read_png_text(out / "mask.png")["Comment"]
    assert f"# {said}".encode() in (out / "relight.rti").read_bytes().split(b"\n")[:6]
    glb = pygltflib.GLTF2().load(str(out / "model.glb"))
    assert glb.asset.extras == {"scan_incomplete": "12 of 24 frames"}
    assert json.loads((out / "process.json").read_text())["scan_incomplete"] == "12 of 24 frames"
    assert res.inputs.incomplete


def test_block_means_of_ragged_blocks_and_masked_pixels():
    """`block_means`: each f x f block's mean over its masked pixels (the last row and column of
    blocks smaller), read in bands of any multiple of f rows, 0 where a block has none."""
    from facette.pipeline._exports import block_means
    rng = np.random.default_rng(1)
    a = rng.random((11, 13, 3)).astype(np.float32)
    mask = rng.random((11, 13)) > 0.3
    mask[:3, :3] = False                                    # a block with no masked pixel
    for rows in (3, 6, 99):
        (got,), count = block_means((a,), mask, 3, rows=rows)
        assert got.shape == (4, 5, 3) and count.shape == (4, 5)
        for i in range(4):
            for j in range(5):
                sel = mask[3 * i:3 * i + 3, 3 * j:3 * j + 3]
                assert count[i, j] == sel.sum()
                want = a[3 * i:3 * i + 3, 3 * j:3 * j + 3][sel].mean(0) if sel.any() else 0
                np.testing.assert_allclose(got[i, j], want, rtol=1e-6)


def test_gltf_textures_of_a_large_scan_are_block_means_and_validate(tmp_path, capsys, khronos_validate,
                                                                    monkeypatch):
    """Above GLTF_TEXTURE_MAX texels (here forced to 16) model.glb's textures are the maps'
    block means at a viewer's size, the mesh's UVs land on them, the file validates, and the
    report's notes say so."""
    import io

    import pygltflib
    from PIL import Image

    import facette.pipeline._exports as exports
    monkeypatch.setattr(exports, "GLTF_TEXTURE_MAX", 16)
    sc = sphere_on_plane(32, 40)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "matte"), pitch=0.1)
    assert main(["process", str(tmp_path / "scan"), "-o", str(tmp_path / "o"), "--brdf-model", "lambert",
                 "--outputs", "normals,albedo,height,mesh,gltf,brdf,samples"]) == 0
    assert "glTF textures 14 x 11 (block means of 3 x 3 pixels" in capsys.readouterr().out
    glb = tmp_path / "o" / "model.glb"
    assert khronos_validate(glb)["issues"]["numErrors"] == 0
    g = pygltflib.GLTF2().load(str(glb))
    blob = g.binary_blob()
    sizes = set()
    for image in g.images:
        view = g.bufferViews[image.bufferView]
        sizes.add(Image.open(io.BytesIO(blob[view.byteOffset:view.byteOffset + view.byteLength])).size)
    assert sizes == {(14, 11)}
    acc = g.accessors[g.meshes[0].primitives[0].attributes.TEXCOORD_0]
    view = g.bufferViews[acc.bufferView]
    uv = np.frombuffer(blob, np.float32, acc.count * 2, view.byteOffset + (acc.byteOffset or 0)).reshape(-1, 2)
    # the sphere's vertices sit inside the image: their texels inside the 14 x 11 texture
    assert uv.min() > 0 and uv.max() < 1 and np.ptp(uv[:, 0]) > 0.3


def _normal_map_whole(normals, height, mask, pitch, step):
    """The tangent-space normal map of the formula in one pass over the whole image (the reference
    the band-wise form must give byte for byte)."""
    from scipy.ndimage import uniform_filter
    hgt = np.where(mask, height.astype(np.float64), 0.0)
    if step > 1:
        hgt = uniform_filter(hgt, size=step, mode="nearest")
    gy, gx = (g.astype(np.float32) for g in np.gradient(hgt, pitch))
    hx, hy = gx, -gy
    inv_n, inv_t = 1 / np.sqrt(hx * hx + hy * hy + 1), 1 / np.sqrt(hx * hx + 1)
    nx, ny, nz = (normals[..., k].astype(np.float32) for k in range(3))
    ts = np.stack([(nx + nz * hx) * inv_t, (-nx * hy * hx + ny * (hx * hx + 1) + nz * hy) * inv_n * inv_t,
                   (-nx * hx - ny * hy + nz) * inv_n], -1)
    ok = mask & (nx * nx + ny * ny + nz * nz > 0.25)
    ts = np.where(ok[..., None], ts, np.array([0, 0, 1], np.float32))
    ts /= np.maximum(np.sqrt((ts * ts).sum(-1, keepdims=True)), np.float32(1e-12))
    return np.round((ts + 1) * np.float32(127.5)).clip(0, 255).astype(np.uint8)


@pytest.mark.parametrize("step", [1, 2, 7])
def test_normal_map_by_bands_equals_the_whole_image_formula(step):
    from facette.pipeline._exports import ROWS, tangent_space_normal_map
    rng = np.random.default_rng(step)
    h, w = 3 * ROWS + 5, 41                       # bands, a ragged last one, halos across each seam
    height = np.cumsum(rng.normal(size=(h, w)), 0).astype(np.float32)
    n = rng.normal(size=(h, w, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    mask = rng.random((h, w)) > 0.1
    np.testing.assert_array_equal(tangent_space_normal_map(n, height, mask, 0.05, step),
                                  _normal_map_whole(n, height, mask, 0.05, step))
    # one row: flat across rows, the slope along it (the whole-image gradient cannot be taken)
    one = tangent_space_normal_map(n[:1], height[:1], mask[:1], 0.05, step)
    assert one.shape == (1, w, 3) and one.dtype == np.uint8


@pytest.mark.parametrize("mesh_step", [1, 5])
def test_block_mean_textures_by_texel_bands_give_the_same_model_glb(tmp_path, monkeypatch, mesh_step):
    """The block-mean textures (a map over GLTF_TEXTURE_MAX texels, here 16) made two texel rows
    at a time, seams and the normal map's halo included, write the same model.glb as in one band."""
    import facette.pipeline._exports as exports
    monkeypatch.setattr(exports, "GLTF_TEXTURE_MAX", 16)
    sc = sphere_on_plane(32, 40)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "glossy"), pitch=0.1)
    glbs = []
    for rows in (10 ** 6, 2):
        monkeypatch.setattr(exports, "TEXEL_ROWS", rows)
        out = tmp_path / f"o{rows}"
        assert main(["process", str(tmp_path / "scan"), "-o", str(out), "--method", "rank_trimmed",
                     "--mesh-step", str(mesh_step), "--outputs", "normals,albedo,height,mesh,gltf,brdf,samples"]) == 0
        glbs.append((out / "model.glb").read_bytes())
    assert glbs[0] == glbs[1]
