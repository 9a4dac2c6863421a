"""`facette batch` on a local Dask cluster: simulated scans, one of them corrupted."""
import csv
import shutil

import pytest

import facette
from facette.cli.main import main
from facette.scan import merge_scan
from facette.pipeline import batch
from facette._data import sim_profile_dir

OUTPUTS = ["normals", "mesh", "brdf", "ptm"]
OPTIONS = {"fit_options": {"model": "lambert"}}


@pytest.fixture(scope="session")
def sim_scans(tmp_path_factory):
    """Two small scans on the simulated rig (128x96 RAW, default bracket), HDR merged, made once."""
    root = tmp_path_factory.mktemp("sim_scans")
    profile = sim_profile_dir()
    dirs = []
    for seed in (1, 2):
        with facette.connect("sim", raw_shape=(96, 128), seed=seed) as rig:
            rig.scan(root / f"object{seed}", profile=str(profile), button="press", progress=False)
        merge_scan(root / f"object{seed}")
        dirs.append(root / f"object{seed}")
    return dirs


@pytest.fixture
def collection(sim_scans, tmp_path):
    """Four scans: the two simulated ones, a copy, and a copy with a truncated HDR image whose
    RAW frames are gone (with them, processing would merge the image again)."""
    scans = [shutil.copytree(s, tmp_path / "scans" / s.name) for s in sim_scans]
    scans.append(shutil.copytree(sim_scans[0], tmp_path / "scans" / "copy"))
    bad = shutil.copytree(sim_scans[1], tmp_path / "scans" / "corrupted")
    exr = bad / "hdr" / "light_03.exr"
    exr.write_bytes(exr.read_bytes()[:3000])
    for raw in (bad / "raw").glob("L03_E*"):
        raw.unlink()
    scans.append(bad)
    return scans


def _summary(out):
    with open(out / "summary.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_failed_scan_is_reported_and_the_others_are_processed(collection, tmp_path):
    out = tmp_path / "out"
    rows = batch(collection, out, workers=2, outputs=OUTPUTS, options=OPTIONS, progress=False)
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "failed"]
    assert "light_03.exr: cannot read this HDR image" in rows[3]["error"]
    for r in rows[:3]:
        assert (out / r["scan"] / "relight.ptm").is_file() and (out / r["scan"] / "normal.exr").is_file()
        assert r["valid_pixels"] > 1000 and r["normal_median_deg"] < 15 and 0 < r["ptm_relative_rms"] < 0.5
        assert r["brdf_model"] == "lambert" and 0 < r["kd_r"] < 2
    table = _summary(out)
    assert [t["scan"] for t in table] == ["object1", "object2", "copy", "corrupted"]
    assert table[3]["status"] == "failed" and "cannot read this HDR image" in table[3]["error"]
    assert float(table[0]["normal_median_deg"]) == pytest.approx(rows[0]["normal_median_deg"])
    page = (out / "summary.html").read_text()
    assert "3 processed, 0 already done" in page and "1 failed" in page and "class='failed'" in page


def test_a_rerun_skips_what_is_done_and_redoes_what_changed(collection, tmp_path):
    out = tmp_path / "out"
    batch(collection, out, workers=2, outputs=OUTPUTS, options=OPTIONS, progress=False)
    # object2's inputs change; the corrupted one is repaired
    shutil.copy(collection[0] / "hdr" / "light_00.exr", collection[1] / "hdr" / "light_00.exr")
    shutil.copy(collection[1] / "hdr" / "light_03.exr", collection[3] / "hdr" / "light_03.exr")
    rows = batch(collection, out, workers=1, outputs=OUTPUTS, options=OPTIONS, progress=False)
    assert [r["status"] for r in rows] == ["skipped", "ok", "skipped", "ok"], rows[3].get("error")
    # other options: not the same results, so not done
    rows = batch(collection[:1], out, workers=1, outputs=OUTPUTS, options={}, progress=False)
    assert rows[0]["status"] == "ok"


def test_cli_exit_status_names_the_failed_scan(collection, tmp_path, capsys):
    out = tmp_path / "out"
    status = main(["batch", *map(str, collection[2:]), "-o", str(out), "--workers", "2",
                   "--outputs", "normals,ptm", "--quiet"])
    captured = capsys.readouterr()
    assert status == 1
    assert "2 scans: 1 processed, 0 already done, 1 failed" in captured.out
    assert "failed: corrupted: BadInputError:" in captured.err
    assert main(["batch", str(tmp_path / "nowhere"), "-o", str(out), "--quiet",
                 "--outputs", "normals"]) == 1
    assert "no scan.json" in capsys.readouterr().err
    assert main(["batch", str(collection[2]), "-o", str(out), "--outputs", "normal"]) == 2
    assert "unknown output" in capsys.readouterr().err


def test_a_running_scheduler_is_used_by_its_address(collection, tmp_path):
    """--scheduler ADDRESS: the collection runs on a cluster that batch did not start."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=None) as cluster:
        rows = batch(collection[2:], tmp_path / "out", scheduler=cluster.scheduler_address,
                     outputs=["normals"], progress=False)
        assert [r["status"] for r in rows] == ["ok", "failed"]
        assert cluster.scheduler.address == cluster.scheduler_address    # still up: not closed by batch
