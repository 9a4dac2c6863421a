"""`process(..., memory=...)` / `facette process --memory`: photometric stereo over row bands
gives the untiled results (bands forced to a few rows), for a DiLiGenT-style folder and a scan
directory (HDR EXR with variances, near lights), without ever loading the whole images when the
outputs need none after photometric stereo; whole-image methods and bad budgets are refused."""
import json

import numpy as np
import pytest

from facette.bench._sim_scan import write_scan
from facette.cli.main import main
from facette.io.diligent import write_diligent
from facette.io.exr import write_exr
from facette.pipeline import BANDED_METHODS, ProcessOptions, process
from facette.pipeline import _whole as process_module   # where the whole reading loads the capture
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()
STREAMED = ["normals", "albedo", "mask", "height", "mesh", "report"]
ROWS = 5
M = "rank_trimmed"      # a per-pixel method (the process default, li_alternating, needs the whole image)

# --memory solves the normals on the mean of R, G, B in every band, as the untiled run's default does
# (pipeline._tiled_process: the same appended channel, `_channels.with_solve_channel`)
WHOLE_CHANNELS = "mean"
# the cast-shadow step over bands too (pipeline._shadows.hidden_over_bands)
WHOLE = {"channels": WHOLE_CHANNELS}
SHADOW_TIMES = ("cpu_seconds", "seconds_before_solve", "cpu_seconds_before_solve")


def _figures(quality):
    """quality without the cast-shadow step's seconds."""
    shadows = {k: v for k, v in quality.get("shadows", {}).items() if k not in SHADOW_TIMES}
    return {**quality, **({"shadows": shadows} if shadows else {})}


def _angle_deg(a, b):
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


@pytest.fixture(scope="module")
def diligent(tmp_path_factory):
    """A glossy sphere on a plane, 36x44 px, 16-bit PNGs, some values clipped (NaN on reading)."""
    scene = sphere_on_plane(36, 44, border=2)
    images = render(scene, L, material="glossy", noise=0.002, rng=np.random.default_rng(3))
    raw = np.clip(np.rint(images * 3.0 * 65535), 0, 65535).astype(np.uint16)
    assert (raw == 65535).any()
    path = tmp_path_factory.mktemp("memory") / "dil"
    write_diligent(path, raw, L, np.full((len(L), 3), 3.0), scene.mask)
    return path


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    """A satin sphere on a plane as a scan directory: radiance and variance EXRs (a few values
    saturated: infinite variance), lights at finite positions (near-light directions and fall-off)."""
    scene = sphere_on_plane(34, 46)
    images = render(scene, L, "satin", noise=0.002, rng=np.random.default_rng(5)).astype(np.float32)
    path = write_scan(tmp_path_factory.mktemp("memory") / "scan", scene, images)
    rng = np.random.default_rng(6)
    for i in range(len(L)):
        var = (0.01 * images[i]) ** 2 + 1e-8
        var[rng.integers(0, 34, 6), rng.integers(0, 46, 6)] = np.inf      # saturated in every frame
        write_exr(path / "hdr" / f"light_{i:02d}_var.exr", var)
    manifest = json.loads((path / "scan.json").read_text())
    for light in manifest["lights"]:
        light["position_mm"] = (np.asarray(light["direction"]) * 40.0).tolist()   # near: 40 mm away
    (path / "scan.json").write_text(json.dumps(manifest))
    return path


@pytest.fixture
def small_bands(monkeypatch, force_bands):
    """Bands of ROWS rows whatever the budget."""
    force_bands(ROWS)


def _same(whole, tiled):
    assert tiled.ps.info["tiles"] > 1 and tiled.ps.info["rows_per_tile"] == ROWS
    assert np.array_equal(whole.mask, tiled.mask)
    assert np.array_equal(whole.object_mask, tiled.object_mask)
    sel = whole.mask
    assert sel.sum() > 500
    assert _angle_deg(whole.normals[sel], tiled.normals[sel]).max() < 0.01
    np.testing.assert_allclose(tiled.albedo, whole.albedo, rtol=1e-5, atol=1e-7)
    if whole.height is not None:
        span = np.ptp(whole.height[sel])
        assert span > 0 and np.abs(whole.height - tiled.height)[sel].max() <= 1e-3 * span
    # the uncertainty map over bands, with the rows around each it reads (pipeline._band_uncertainty)
    assert _figures(whole.quality) == _figures(tiled.quality) and "normal_uncertainty" in tiled.quality
    if np.array_equal(whole.normals, tiled.normals):
        np.testing.assert_array_equal(tiled.uncertainty, whole.uncertainty)
    else:        # woodham1980's least squares moves in the last bits with the block's size: the map follows
        np.testing.assert_allclose(tiled.uncertainty, whole.uncertainty, atol=1e-3)


def _never_whole(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("the whole images were loaded")
    monkeypatch.setattr(process_module, "load_input", refuse)


@pytest.mark.parametrize("method", ["rank_trimmed", "woodham1980"])
def test_diligent_folder_in_bands_gives_the_untiled_results(diligent, tmp_path, small_bands, monkeypatch, method):
    whole = process(diligent, **WHOLE, outputs=STREAMED, out_dir=tmp_path / "whole", method=method)
    _never_whole(monkeypatch)
    tiled = process(diligent, outputs=STREAMED, out_dir=tmp_path / "tiled", method=method, memory="1GB")
    _same(whole, tiled)
    record = json.loads((tmp_path / "tiled" / "process.json").read_text())
    assert record["options"]["memory"] == "1GB"
    assert "memory" not in json.loads((tmp_path / "whole" / "process.json").read_text())["options"]
    assert any("read band by band" in n for n in record["notes"])
    assert any("report shows no mask over the photograph" in n for n in record["notes"])
    assert (tmp_path / "tiled" / "mesh.ply").is_file()
    assert "12 lights on 44 × 36 pixels" in (tmp_path / "tiled" / "report.html").read_text()


def test_scan_directory_in_bands_gives_the_untiled_results(scan, tmp_path, small_bands, monkeypatch):
    whole = process(scan, **WHOLE, outputs=STREAMED, out_dir=tmp_path / "whole", method=M)
    _never_whole(monkeypatch)
    tiled = process(scan, outputs=STREAMED, out_dir=tmp_path / "tiled", memory="1GB", method=M)
    assert tiled.ps.info["channels"]["channels"] == "mean" and not any("solved on green" in n for n in tiled.notes)
    _same(whole, tiled)
    assert any("near lights" in n for n in tiled.notes)
    assert whole.errors and tiled.errors["normal_median_deg"] == pytest.approx(whole.errors["normal_median_deg"],
                                                                               abs=1e-4)


def test_ptm_with_the_samples_is_fitted_over_bands_too(scan, tmp_path, small_bands, monkeypatch):
    outputs = ["normals", "height", "samples", "ptm"]
    whole = process(scan, **WHOLE, outputs=outputs, method=M)
    _never_whole(monkeypatch)
    tiled = process(scan, outputs=outputs, memory="1GB", method=M)
    _same(whole, tiled)
    note = [n for n in tiled.notes if n.startswith("--memory")]
    assert len(note) == 1 and "never held whole" in note[0]
    assert np.array_equal(tiled.filtered.count, whole.filtered.count)      # the same shadows left out
    assert tiled.fit_errors["ptm_relative_rms"] == pytest.approx(whole.fit_errors["ptm_relative_rms"], rel=1e-6)


@pytest.mark.parametrize("source", ["scan", "diligent"])
def test_samples_and_brdf_taken_band_by_band_give_the_untiled_sensor_and_fit(request, tmp_path, small_bands,
                                                                            monkeypatch, source):
    src = request.getfixturevalue(source)
    outputs = ["normals", "samples", "brdf", "gltf"]
    whole = process(src, **WHOLE, outputs=outputs, out_dir=tmp_path / "whole", method=M)
    _never_whole(monkeypatch)
    tiled = process(src, outputs=outputs, out_dir=tmp_path / "tiled", memory="1GB", method=M)
    _same(whole, tiled)
    assert whole.filtered.count.sum() > 1000
    assert np.array_equal(tiled.filtered.count, whole.filtered.count)
    filled = whole.filtered.count > 0
    np.testing.assert_allclose(tiled.filtered.mean[filled], whole.filtered.mean[filled], rtol=1e-5)
    # the raw subset is drawn band by band: about as many samples, from the same pixels' set
    assert 0.8 < len(tiled.samples) / len(whole.samples) < 1.2
    assert np.isin(tiled.samples.pixel, np.flatnonzero(whole.mask)).all()
    assert tiled.brdf.params.keys() == whole.brdf.params.keys()
    for key, value in whole.brdf.params.items():
        np.testing.assert_allclose(tiled.brdf.params[key], value, rtol=1e-4)
    assert (tmp_path / "tiled" / "model.glb").is_file() and (tmp_path / "tiled" / "brdf.json").is_file()


def test_a_given_mask_is_used_in_bands(diligent, tmp_path, small_bands):
    mask = np.zeros((36, 44), bool)
    mask[6:30, 5:40] = True
    whole = process(diligent, **WHOLE, outputs=["normals"], mask=mask, method=M)
    tiled = process(diligent, outputs=["normals"], mask=mask, memory="1GB", method=M)
    _same(whole, tiled)
    assert not tiled.mask[:6].any()


def test_a_whole_image_method_with_memory_is_refused_naming_the_banded_ones():
    with pytest.raises(ValueError, match="over bands of rows") as err:
        ProcessOptions(method="rpca_wu2010", memory="2GB")
    assert all(name in str(err.value) for name in BANDED_METHODS)


# li_alternating with its coarse pass (and so its model fitted across the bands) at this small size
LI = {"method": "li_alternating", "ps_options": {"coarse_pixels": 400}}


def test_the_default_method_in_bands_gives_the_untiled_results(scan, tmp_path, small_bands, monkeypatch):
    # a scan: near lights (per-pixel directions, fall-off), variances; the DiLiGenT folder on Dask below
    src = scan
    outputs = ["normals", "albedo", "mask", "height"]
    whole = process(src, **WHOLE, **LI, outputs=outputs, out_dir=tmp_path / "whole")
    _never_whole(monkeypatch)
    tiled = process(src, **LI, outputs=outputs, memory="1GB", out_dir=tmp_path / "tiled")
    assert tiled.ps.method == "li_alternating" and tiled.ps.info["coarse"]["factor"] == 2
    assert tiled.ps.info["materials"][0]["sigma"] == whole.ps.info["materials"][0]["sigma"]
    _same(whole, tiled)
    np.testing.assert_array_equal(tiled.normals, whole.normals)        # the same values
    np.testing.assert_array_equal(tiled.albedo, whole.albedo)
    for name in ("normal.exr", "albedo.exr", "mask.png", "height.exr"):     # and the same files
        assert (tmp_path / "tiled" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name


def test_interreflections_with_memory_are_refused():
    with pytest.raises(ValueError, match="whole images"):
        ProcessOptions(memory="2GB", interreflections=True, method=M)


@pytest.mark.parametrize("text", ["2 apples", "GB", "-1GB", "0", ""])
def test_a_budget_that_is_not_a_size_is_refused(text):
    with pytest.raises(ValueError, match="memory must be"):
        ProcessOptions(memory=text)


def test_a_budget_too_small_for_the_image_says_how_much(diligent):
    with pytest.raises(ValueError, match="give at least"):
        process(diligent, outputs=["normals"], memory="1MB", method=M)


def test_cli_memory(capsys, diligent, tmp_path):
    with pytest.raises(SystemExit) as stop:       # argparse checks the size before any work
        main(["process", str(diligent), "-o", str(tmp_path / "a"), "--outputs", "normals,height",
              "--memory", "lots"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "memory must be a size" in err and not (tmp_path / "a").exists()
    code = main(["process", str(diligent), "-o", str(tmp_path / "b"), "--outputs", "normals,height",
                 "--memory", "2GB", "--method", "rpca_wu2010"])
    err = capsys.readouterr().err
    assert code == 2 and "li_alternating" in err
    code = main(["process", str(diligent), "-o", str(tmp_path / "d"), "--outputs", "normals,height",
                 "--memory", "500MB"])          # the libraries alone take 0.45 GB of it
    err = capsys.readouterr().err
    assert code == 2 and "held besides" in err and "give at least 0.7" in err
    code = main(["process", str(diligent), "-o", str(tmp_path / "c"), "--outputs", "normals,height",
                 "--memory", "1GB"])
    out = capsys.readouterr().out
    assert code == 0 and "fits one band" in out          # its one band holds the capture: read whole
    assert json.loads((tmp_path / "c" / "process.json").read_text())["options"]["method"] == "li_alternating"
    assert json.loads((tmp_path / "c" / "process.json").read_text())["options"]["memory"] == "1GB"


@pytest.fixture(scope="module")
def cluster():
    """A dask.distributed LocalCluster of 2 workers × 1 thread, in this process."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as c:
        yield c


@pytest.mark.parametrize("source, how", [("scan", {"method": M}), ("diligent", {"method": M}), ("diligent", LI)])
def test_bands_on_a_dask_cluster_give_the_untiled_results(request, cluster, tmp_path, small_bands, monkeypatch,
                                                          source, how):
    src = request.getfixturevalue(source)
    whole = process(src, **WHOLE, outputs=["normals", "height"], **how)
    _never_whole(monkeypatch)
    def bands_run():                     # _ps_task tasks the scheduler has seen finish (counts of transitions)
        prefix = cluster.scheduler.task_prefixes.get("ps_task")
        return 0 if prefix is None else prefix.state_counts.get("memory", 0)

    before = bands_run()
    tiled = process(src, outputs=["normals", "height"], memory="1GB", scheduler=cluster.scheduler_address, **how)
    _same(whole, tiled)
    assert bands_run() - before == tiled.ps.info["tiles"]
    assert any(f"on the scheduler {cluster.scheduler_address}" in n for n in tiled.notes)


def test_a_scheduler_without_memory_is_refused():
    with pytest.raises(ValueError, match="give --memory too"):
        ProcessOptions(scheduler="tcp://127.0.0.1:8786")


def test_weighted_channels_with_memory_fall_back_to_green_and_say_so(diligent, small_bands):
    tiled = process(diligent, outputs=["normals"], method=M, memory="1GB", channels="weighted")
    assert tiled.ps.info["channels"]["channels"] == "green"
    assert any("channels: weighted asked; with --memory the normals are solved on green" in n for n in tiled.notes)
