"""`facette batch` on a local Dask cluster: simulated scans, one of them corrupted."""
import csv
import json
import shutil

import pytest

import facette
from facette.cli.main import main
from facette.scan import merge_scan
from facette.pipeline import batch
from facette.pipeline._batch import result_folders
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
    assert main(["batch", str(tmp_path / "nowhere"), "-o", str(out), "--quiet",     # bad input, before any
                 "--outputs", "normals"]) == 2                                      # worker starts (issue 51)
    assert "nowhere (no such folder)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:          # checked by argparse, as `facette process` does
        main(["batch", str(collection[2]), "-o", str(out), "--outputs", "normal"])
    assert exc.value.code == 2 and "unknown output" in capsys.readouterr().err


def test_a_running_scheduler_is_used_by_its_address(collection, tmp_path):
    """--scheduler ADDRESS: the collection runs on a cluster that batch did not start."""
    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=":0") as cluster:   # any free port: never 8787 taken
        rows = batch(collection[2:], tmp_path / "out", scheduler=cluster.scheduler_address,
                     outputs=["normals"], progress=False)
        assert [r["status"] for r in rows] == ["ok", "failed"]
        assert cluster.scheduler.address == cluster.scheduler_address    # still up: not closed by batch


def test_result_folders_are_unique_and_stable_whatever_the_other_scans(tmp_path):
    a, b = tmp_path / "site1" / "vase", tmp_path / "site2" / "vase"
    names = result_folders([a, b], tmp_path / "out")
    assert names[0] == "vase" and names[1].startswith("vase-") and len(set(names)) == 2
    third = tmp_path / "site3" / names[1]                 # named like the de-duplicated one
    names3 = result_folders([a, b, third], tmp_path / "out")
    assert len(set(names3)) == 3 and names3[:2] == names
    # b alone keeps its folder once a's results own "vase" (batch.json says whose)
    (tmp_path / "out" / "vase").mkdir(parents=True)
    (tmp_path / "out" / "vase" / "batch.json").write_text(json.dumps({"row": {"source": str(a)}}))
    assert result_folders([b], tmp_path / "out") == names[1:]
    assert result_folders([b, a], tmp_path / "out") == [names[1], "vase"]


def test_an_output_folder_in_or_as_the_scans_is_refused_before_any_task(sim_scans, tmp_path, capsys):
    scans = [shutil.copytree(s, tmp_path / "scans" / s.name) for s in sim_scans]
    before = {p: p.stat().st_mtime_ns for s in scans for p in s.rglob("*")}
    for out in (tmp_path / "scans", scans[0] / "results", scans[0]):
        assert main(["batch", *map(str, scans), "-o", str(out), "--quiet", "--outputs", "normals"]) == 2
        err = capsys.readouterr().err
        assert "facette never writes its inputs" in err or "into" in err, err
    assert {p: p.stat().st_mtime_ns for s in scans for p in s.rglob("*")} == before
    assert not (scans[0] / "results").exists()


def test_bad_options_are_refused_before_any_worker_starts(sim_scans, tmp_path, capsys):
    out = tmp_path / "out"
    for bad, said in ((["--brdf-model", "lamber"], "invalid choice: 'lamber'"), (["--outputs", ""], "(none given)")):
        with pytest.raises(SystemExit) as exc:          # argparse's exit, as `facette process`
            main(["batch", str(sim_scans[0]), "-o", str(out), *bad])
        assert exc.value.code == 2 and said in capsys.readouterr().err
    assert not out.exists()


def test_a_subset_rerun_keeps_the_other_rows_and_remakes_lost_outputs(sim_scans, tmp_path):
    scans = [shutil.copytree(s, tmp_path / "scans" / s.name) for s in sim_scans]
    # the HDR images left to processing: it merges them and records them in scan.json
    shutil.rmtree(scans[1] / "hdr")
    manifest = json.loads((scans[1] / "scan.json").read_text())
    manifest.pop("hdr", None)
    (scans[1] / "scan.json").write_text(json.dumps(manifest))
    out = tmp_path / "out"
    rows = batch(scans, out, workers=1, outputs=["normals", "mask"], options=OPTIONS, progress=False)
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert (scans[1] / "hdr").is_dir()
    # processing's own writes (the HDR merge) do not make the scan look changed
    rows = batch(scans, out, workers=1, outputs=["normals", "mask"], options=OPTIONS, progress=False)
    assert [r["status"] for r in rows] == ["skipped", "skipped"]
    (out / "object2" / "normal.exr").unlink()                  # an output lost
    (out / "object1" / "mask.png").write_bytes(b"damaged")     # an output changed
    rows = batch(scans[1:], out, workers=1, outputs=["normals", "mask"], options=OPTIONS, progress=False)
    assert [r["status"] for r in rows] == ["ok"] and (out / "object2" / "normal.exr").is_file()
    table = _summary(out)
    assert [t["scan"] for t in table] == ["object1", "object2"]       # the subset kept object1's row
    rows = batch(scans[:1], out, workers=1, outputs=["normals", "mask"], options=OPTIONS, progress=False)
    assert rows[0]["status"] == "ok" and (out / "object1" / "mask.png").stat().st_size > 10


def test_batch_has_the_allow_incomplete_its_errors_advise(tmp_path):
    from facette.bench._sim_scan import write_scan
    from facette.cli.main import build_parser
    from facette.pipeline import process_scan
    from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
    sc = sphere_on_plane(24, 32)
    scan = write_scan(tmp_path / "s", sc, render(sc, thesis_light_directions(), "matte"))
    m = json.loads((scan / "scan.json").read_text())
    m["exposures"] = [{"index": 0, "time_us": 1000}]
    m["frames"] = []                              # a plan of 12 frames, none taken (hdr/ made by hand)
    (scan / "scan.json").write_text(json.dumps(m))
    row = process_scan(scan, tmp_path / "o", outputs=["normals"])
    assert row["status"] == "failed" and "--allow-incomplete" in row["error"]
    args = build_parser("batch").parse_args(["batch", str(scan), "-o", str(tmp_path / "o"), "--allow-incomplete"])
    assert args.allow_incomplete
    row = process_scan(scan, tmp_path / "o", outputs=["normals"], options={"allow_incomplete": True})
    assert row["status"] == "ok", row["error"]
