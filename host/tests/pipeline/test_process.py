"""`facette process` end to end: DiLiGenT-style folders and scan directories."""
import json

import numpy as np
import pytest

from facette.cli.main import main
from facette.io.diligent import write_diligent
from facette.io.exr import read_exr, write_exr
from facette.io.ply import read_ply
from facette.io.png import read_mask
from facette.errors import InsufficientData
from facette.pipeline import ProcessOptions, process, stages_needed
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()


@pytest.fixture(scope="module")
def diligent_dir(tmp_path_factory):
    """A small DiLiGenT-style folder: a glossy sphere on a plane, 12 lights, 16-bit PNGs."""
    folder = tmp_path_factory.mktemp("diligent")
    sc = sphere_on_plane(48, 64)
    imgs = render(sc, L, "glossy", noise=0.002)
    inten = np.tile([1.0, 0.8, 1.2], (12, 1)) * np.linspace(0.8, 1.2, 12)[:, None]
    scale = 60000 / float((imgs * inten[:, None, None, :]).max())
    u16 = np.round(imgs * inten[:, None, None, :] * scale).astype(np.uint16)
    mask = sc.mask.copy()
    mask[:2] = False
    write_diligent(folder, u16, L, inten, mask)
    return folder, sc, mask


def test_cli_processes_a_diligent_folder_end_to_end(diligent_dir, tmp_path, capsys):
    folder, sc, mask = diligent_dir
    out = tmp_path / "out"
    outputs = "normals,albedo,mask,height,mesh,samples,report"     # brdf: see the scan test
    # the Lambertian albedo's scale is what is checked here, named whatever PROCESS_DEFAULT is:
    # li_alternating writes the LI K_d, clipped to [0, 1], which an uncalibrated scale (a DiLiGenT folder) saturates
    assert main(["process", str(folder), "-o", str(out), "--outputs", outputs, "--method", "rank_trimmed"]) == 0
    text = capsys.readouterr().out
    assert "diligent" in text and "valid pixels" in text
    normals, names = read_exr(out / "normal.exr")
    assert names == ("X", "Y", "Z", "uncertainty_deg") and normals.shape == (48, 64, 4)
    normals = normals[..., :3]
    got_mask = read_mask(out / "mask.png")
    assert not got_mask[:2].any() and got_mask[mask].mean() > 0.97
    err = angular_error_deg(normals, sc.normals, got_mask)
    assert np.median(err) < 1.0 and np.percentile(err, 95) < 3.0
    albedo, _ = read_exr(out / "albedo.exr")
    # images were divided by the intensities: the albedo is the rendered one up to one scale
    ratio = albedo[got_mask & ~sc.sphere] / np.array([0.6, 0.5, 0.4])
    assert np.std(ratio) / np.mean(ratio) < 0.02
    height, _ = read_exr(out / "height.exr", ("Z",))
    r, c = np.unravel_index(np.argmax(sc.height), sc.height.shape)
    assert height[r, c, 0] > np.median(height[got_mask & ~sc.sphere]) + 5   # the sphere stands out
    v, f = read_ply(out / "mesh.ply")
    assert len(v) == got_mask.sum() and len(f) > len(v)
    with np.load(out / "samples.npz") as z:
        assert z["filtered_mean"].shape[2] == 3 and z["raw_f"].shape[1] == 3
        assert z["filtered_count"].sum() > 0
    page = (out / "report.html").read_text()
    # normal, albedo, shadow flags, height, error against truth (the hierarchy adds its triplet maps)
    assert page.count("data:image/png;base64,") >= 5 and "Filtered reflectance per incidence" in page
    # no BRDF asked for: the fit section says so, and the viewer draws the relighting model instead
    assert "not requested (--outputs without brdf)" in page and "no BRDF was fitted" not in page
    assert "facette's relighting model" in page and not (out / "relight_model.npz").exists()   # for the page only


def test_outputs_limit_the_stages(diligent_dir, tmp_path):
    folder, _, _ = diligent_dir
    assert stages_needed(["normals"]) == ["load", "ps"]
    assert stages_needed(["mesh", "samples"]) == ["load", "ps", "integrate", "mesh", "samples"]
    res = process(folder, outputs=["normals"], out_dir=tmp_path)
    assert "integrate" not in res.timings and "samples" not in res.timings
    assert res.height is None and res.filtered is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["normal.exr", "process.json"]
    with pytest.raises(ValueError, match="unknown output"):
        process(folder, outputs=["normal"])


def test_process_takes_one_options_object_and_records_it(diligent_dir, tmp_path):
    folder, _, _ = diligent_dir
    o = ProcessOptions(method="least_squares", mesh_step=2, fit_options={"model": "lambert"})
    res = process(folder, outputs=["normals"], out_dir=tmp_path / "o", options=o, theta0_deg=5.0)
    rec = json.loads((tmp_path / "o" / "process.json").read_text())["options"]
    assert rec == {**o.recorded(), "theta0_deg": 5.0}                  # a keyword overrides a field
    assert res.options == {**o.reported(), "theta0_deg": 5.0, "outputs": ["normals"]}
    assert res.ps.method == "woodham1980"
    with pytest.raises(ValueError, match="unknown photometric-stereo method 'magic'"):
        process(tmp_path / "nothing", method="magic")                 # checked before reading
    with pytest.raises(TypeError, match="nope"):
        process(folder, nope=1)


def test_least_squares_method_and_bad_sources(diligent_dir, tmp_path, capsys):
    folder, sc, _ = diligent_dir
    res = process(folder, outputs=["normals"], method="woodham1980")
    assert res.ps.method == "woodham1980" and res.mask.any()
    assert main(["process", str(tmp_path), "-o", str(tmp_path / "o")]) == 2
    assert "neither scan.json" in capsys.readouterr().err
    with pytest.raises(FileNotFoundError, match="not a directory"):
        process(tmp_path / "nothing")


def _write_scan(folder, sc, imgs, pitch, positions=None):
    m = len(L)
    inten = np.full((m, 3), 2.0)
    lights = [{"index": i, "direction": L[i].tolist(),
               "position_mm": None if positions is None else positions[i].tolist(),
               "intensity": inten[i].tolist()} for i in range(m)]
    frames = [{"file": f"raw/L{i:02d}_E00.dng", "light": i, "exposure": 0, "time_us": 1000,
               "current_set_mA": 100, "current_meas_mA": 100, "start_us": 0, "sync": True,
               "sha256": ""} for i in range(m)]
    (folder / "hdr").mkdir(parents=True)
    for i in range(m):
        write_exr(folder / "hdr" / f"light_{i:02d}.exr", imgs[i] * inten[i])
        var = np.full(imgs[i].shape, 1e-6, np.float32)
        var[0, 0] = np.inf                       # a pixel saturated in every frame
        write_exr(folder / "hdr" / f"light_{i:02d}_var.exr", var)
    np.savez(folder / "truth.npz", normals=sc.normals, height_mm=sc.height * pitch,
             mask=sc.mask, albedo=np.zeros(sc.normals.shape), light_dirs=L,
             light_intensity=inten, brdf=json.dumps({"model": "lambert"}))
    (folder / "scan.json").write_text(json.dumps({
        "schema": 1, "rig": {"id": "test"}, "profile": None, "pixel_pitch_mm": pitch,
        "lights": lights, "exposures": [{"index": 0, "time_us": 1000, "current_mA": 100,
                                         "mode": "camera"}],
        "frames": frames, "rig_time_s": 0.0, "truth": "truth.npz"}))


def test_scan_directory_with_truth(tmp_path):
    sc = sphere_on_plane(40, 40)
    imgs = render(sc, L, "matte")
    _write_scan(tmp_path / "scan", sc, imgs, pitch=0.05)
    res = process(tmp_path / "scan", outputs=["normals", "height", "brdf", "report"],
                  out_dir=tmp_path / "o", fit_options={"model": "lambert"})
    assert res.inputs.kind == "scan" and res.inputs.pixel_pitch_mm == 0.05
    assert res.light_gains is None              # a scan's intensities are the Spectralon's: never read again
    assert not res.mask[0, 0]                   # unknown everywhere: no normal there
    assert res.errors["normal_median_deg"] < 0.5
    assert "height_rms_mm" in res.errors
    assert "Error against the scan" in (tmp_path / "o" / "report.html").read_text()
    # images / intensities = (rho / pi) n.s: the Lambert fit finds rho per channel
    brdf = json.loads((tmp_path / "o" / "brdf.json").read_text())
    assert brdf["model"] == "lambert"
    np.testing.assert_allclose(np.ravel(brdf["parameters"]["kd"]), [0.6, 0.5, 0.4], rtol=0.02)


def test_heights_keep_an_object_level_on_a_dark_leaning_table(tmp_path):
    # a bump on a dark table (albedo 0.04 against 0.6) whose normals lean by 0.5 deg, as a black
    # cloth's do: the table's lean is taken from the table's pixels (the lit pixels darker than
    # the object) and out of its slopes alone, so the bump keeps its shape; the image's mean slope
    # taken out of every pixel (no background known) tilts the bump by the table's share of it
    from facette.recon import integrate
    from facette.recon.synthetic import Scene
    h, w, pitch = 64, 96, 0.1
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    x, y = xx - w / 2, -(yy - h / 2)
    z = 12.0 * np.exp(-(x ** 2 + y ** 2) / (2 * 9.0 ** 2))
    on = z > 0.05
    n = np.stack([x / 81 * z, y / 81 * z, np.ones_like(z)], -1)
    lean = np.deg2rad(0.5)
    n[~on] = [-np.sin(lean), 0.0, np.cos(lean)]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    sc = Scene(n, z, np.ones((h, w), bool), on, (h / 2, w / 2), 0.0)
    imgs = render(sc, L, "matte", cast_shadows=False)
    imgs[:, ~on] *= 0.04 / 0.6
    _write_scan(tmp_path / "scan", sc, imgs, pitch)
    res = process(tmp_path / "scan", outputs=["normals", "height"])
    assert any("the table's lean" in note for note in res.notes), res.notes
    # mask.png is the object, not every lit pixel of the table
    assert (res.object_mask == on).mean() > 0.99, (res.object_mask.sum(), on.sum())

    def tilt_rms(hgt):
        d = (hgt - z * pitch)[on]
        return float(np.sqrt(np.mean((d - d.mean()) ** 2)))

    level, tilted = tilt_rms(res.height), tilt_rms(integrate(res.normals, pitch))
    assert level < 0.2 * tilted, (level, tilted)
    # a scan with no dark background: the whole image's mean slope, no note
    plain = process(tmp_path / "scan", outputs=["normals", "height"], mask=np.ones((h, w), bool))
    assert not any("the table's lean" in note for note in plain.notes)
    # a dark class that does not surround the object (a slab filling the frame, its left third
    # a dark matrix) is part of the object, not a margin: no lean is taken from it
    imgs = render(sc, L, "matte", cast_shadows=False)
    imgs[:, :, : w // 3] *= 0.04 / 0.6
    _write_scan(tmp_path / "slab", sc, imgs, pitch)
    slab = process(tmp_path / "slab", outputs=["normals", "height"])
    assert (slab.inputs.mask & ~slab.inputs.material_mask).any()       # a dark class was found
    assert slab.inputs.background_mask() is None
    assert (slab.object_mask == slab.mask).all()      # the dark matrix is the slab's
    assert not any("the table's lean" in note for note in slab.notes)


def test_scan_with_near_lights_uses_positions(tmp_path):
    sc = sphere_on_plane(40, 40)
    pitch = 1.0
    pos = L * 150.0
    from facette.recon import near_light_directions
    dirs, fall = near_light_directions(pos, sc.normals.shape[:2], pitch)
    shade = np.maximum(np.einsum("hwmi,hwi->mhw", dirs, sc.normals), 0) * np.transpose(fall, (2, 0, 1))
    imgs = (0.5 / np.pi * shade[..., None] * np.ones(3)).astype(np.float32)
    _write_scan(tmp_path / "scan", sc, imgs, pitch, positions=pos)
    # the geometry of near lights is checked, on the Lambertian solve, named whatever PROCESS_DEFAULT is
    # (li_alternating moves 36 of 1278 samples by 1 %)
    near = process(tmp_path / "scan", outputs=["normals", "samples"], method="rank_trimmed")
    far = process(tmp_path / "scan", outputs=["normals"], near_light=False, method="rank_trimmed")
    assert any("near lights" in n for n in near.notes)
    assert near.errors["normal_median_deg"] < 0.2 < far.errors["normal_median_deg"]
    # reflectance with the 1/r^2 fall-off divided out: the Lambertian 0.5 / pi everywhere
    _, _, f, count = near.filtered.flat(min_count=5)
    np.testing.assert_allclose(f, 0.5 / np.pi, rtol=0.01)
    # the inter-reflection removal takes the per-pixel directions (the mask leaves cells empty)
    ir = process(tmp_path / "scan", outputs=["normals"], interreflections=True)
    # (a convex Lambertian scene: it gathers too little to matter, and says so)
    assert ir.interreflections["passes"] and np.isfinite(ir.normals).all()
    assert any("inter-reflections" in n for n in ir.notes)


def test_brdf_aware_method_writes_its_materials_into_brdf_json(tmp_path):
    """process(method="li_alternating") on a Mitsuba glossy sphere: brdf.json carries the
    per-region (σ, n_i) with pixel counts and the pixels and seconds of each level."""
    from facette.bench._mitsuba_scenes import render_scene
    d = render_scene("sphere", "paint_0.10", size=48, spp=8, cache_dir=tmp_path / "cache")
    k = 60000 / float(np.nanmax(d["images"]))
    folder = tmp_path / "glossy"
    write_diligent(folder, np.round(d["images"] * k).astype(np.uint16), d["light_dirs"],
                   np.full((12, 3), k / 65535), d["mask"])
    res = process(folder, outputs=["normals", "albedo", "samples", "brdf"], out_dir=tmp_path / "out",
                  method="li_alternating")
    doc = json.loads((tmp_path / "out" / "brdf.json").read_text())
    ps = doc["photometric_stereo"]
    assert len(ps["materials"]) == 1 and ps["materials"][0]["pixels"] == int(res.mask.sum())
    assert abs(ps["materials"][0]["sigma"] - 0.1) < 0.04
    assert set(ps["levels"]) == {"init", "lambertian", "brdf_aware"}
    assert ps["levels"]["brdf_aware"]["pixels"] > 0
    # a render has no dark level (facette.recon.dark_offsets): nothing taken out, nothing said
    assert ps["dark_offset"]["applied"] is False and not any("dark level" in n for n in res.notes)
    albedo, _ = read_exr(tmp_path / "out" / "albedo.exr")
    np.testing.assert_allclose(np.median(albedo[res.mask], axis=0), d["params"]["kd"], rtol=0.1)
    # after BRDF-aware normals the fit evaluates the diffuse part as they did (eq 3.15 by tables, or
    # the coupled one where the model choice took it), after Lambertian ones by the approximate
    # formula; fit_options chooses
    want = "coupled" if ps["materials"][0]["diffuse"] == "coupled" else "tables"
    assert ps["materials"][0]["diffuse"] in ("li", "coupled") and doc["volume"] == res.brdf.volume == want
    ls = process(folder, outputs=["samples", "brdf"], method="woodham1980")
    assert ls.brdf.volume == "approx"
    assert process(folder, outputs=["samples", "brdf"], method="li_alternating",
                   fit_options={"volume": "approx"}).brdf.volume == "approx"


def _mitsuba_folder(tmp_path, shape, material, size=48, spp=16, intensity=1.0):
    from facette.bench._mitsuba_scenes import render_scene
    d = render_scene(shape, material, size=size, spp=spp, cache_dir=tmp_path / "cache")
    k = 60000 / float(np.nanmax(d["images"]))
    folder = tmp_path / f"{shape}_{material}"
    # intensities k / 65535: the reader's images are the renderer's radiance, the albedo a reflectance
    write_diligent(folder, np.round(d["images"] * k).astype(np.uint16), d["light_dirs"],
                   np.full((len(d["light_dirs"]), 3), intensity * k / 65535), d["mask"])
    return folder, d


def test_interreflections_removed_on_a_concave_object_and_recorded(tmp_path):
    folder, d = _mitsuba_folder(tmp_path, "relief", "plaster", size=64, spp=32)
    plain = process(folder, outputs=["normals", "albedo"], out_dir=None, method="woodham1980", interreflections=False)
    res = process(folder, outputs=["normals", "albedo", "samples", "brdf"], out_dir=tmp_path / "out",
                  method="woodham1980", interreflections=True)
    sel = d["mask"] & plain.mask & res.mask
    err = lambda r: angular_error_deg(r.normals, d["normals"])[sel].mean()
    assert res.interreflections["applied"] and err(res) < 0.85 * err(plain), (err(res), err(plain))
    assert any("inter-reflections removed" in n for n in res.notes)
    record = json.loads((tmp_path / "out" / "process.json").read_text())
    assert record["options"]["interreflections"] is True
    # the albedo is no longer brightened by the light the relief sends itself
    assert np.median(res.albedo[sel]) < np.median(plain.albedo[sel])


def test_brdf_aware_method_removes_glossy_interreflections_too(tmp_path):
    folder, d = _mitsuba_folder(tmp_path, "vase", "paint_0.08", size=64, spp=32)
    res = process(folder, outputs=["normals", "samples", "brdf"], out_dir=tmp_path / "out",
                  method="li_alternating", interreflections=True)
    glossy = res.interreflections["glossy"]
    assert res.interreflections["applied"] and glossy is not None and 0.06 < glossy["lobes"][0][0] < 0.11
    assert any(n.startswith("glossy inter-reflections removed") for n in res.notes)
    layered = res.ps.info["materials"][0]["diffuse"]
    assert res.brdf.volume == {"li": "tables", "coupled": "coupled"}[layered] and 0.06 < res.brdf.params["sigma"] < 0.11
    assert json.loads((tmp_path / "out" / "process.json").read_text())["options"]["interreflections"] is True


def test_interreflections_skipped_on_a_convex_object(tmp_path):
    folder, d = _mitsuba_folder(tmp_path, "sphere", "plaster")
    plain = process(folder, outputs=["normals"], out_dir=None)
    res = process(folder, outputs=["normals"], out_dir=None, interreflections=True)
    # the normals are solved on the channels the option chose, as without the removal
    assert res.ps.info["channels"] == plain.ps.info["channels"] and res.ps.info["channels"]["channels"] == "mean"
    assert res.interreflections["p95_fraction"] == 0.0 and not res.interreflections["applied"]
    assert any("too little to matter" in n for n in res.notes)
    np.testing.assert_array_equal(res.normals, plain.normals)


def test_interreflections_estimate_the_albedo_scale_where_no_spectralon_gave_it(tmp_path):
    # intensities given at a third of the truth: the albedo comes out at 3 x; without a Spectralon
    # the scale to a reflectance is estimated from the images (1/3 here) and said in a note
    folder, _ = _mitsuba_folder(tmp_path, "relief", "plaster", intensity=1 / 3)
    res = process(folder, outputs=["normals"], interreflections=True)
    assert res.interreflections["applied"]
    assert res.interreflections["reflectance_scale"] == pytest.approx(1 / 3, rel=0.2)
    assert any("scale to a reflectance estimated from the images" in n for n in res.notes)
