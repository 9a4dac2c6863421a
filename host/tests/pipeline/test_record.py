"""process.json: one run per results folder, interrupted runs redone by the same command,
inputs never written (facette.pipeline._record)."""
import hashlib
import json
import shutil

import numpy as np
import pytest

import facette
import facette.pipeline._process as process_module
from facette._data import sim_profile_dir
from facette.bench._sim_scan import write_scan
from facette.cli.main import main
from facette.errors import EXIT_BAD_INPUT, EXIT_NO_RESULT
from facette.io.diligent import write_diligent
from facette.pipeline import process
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

OUTS = ["normals", "albedo", "mask"]


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _tree(folder):
    return {p.relative_to(folder).as_posix(): _sha(p) for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    sc = sphere_on_plane(24, 32)
    return write_scan(tmp_path_factory.mktemp("rec") / "scan", sc,
                      render(sc, thesis_light_directions(), "satin", noise=0.002))


@pytest.fixture(scope="module")
def diligent(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dil") / "obj"
    sc = sphere_on_plane(24, 32)
    L = thesis_light_directions()
    imgs = render(sc, L, "satin", noise=0.002)
    write_diligent(folder, np.round(imgs / imgs.max() * 60000).astype(np.uint16), L, np.ones((len(L), 3)), sc.mask)
    return folder


def _interrupt_at_mask(monkeypatch):
    real = process_module.write_mask

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt          # Ctrl-C (or a kill) while the maps are written

    monkeypatch.setattr(process_module, "write_mask", stopped)
    return real


def test_an_interrupted_processing_is_redone_by_the_same_command(scan, monkeypatch):
    out = scan / "results"
    _interrupt_at_mask(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        process(scan, outputs=OUTS, out_dir=out)
    assert json.loads((out / "process.json").read_text())["state"] == "running"
    left = sorted(p.name for p in out.iterdir())
    assert "mask.png" not in left and not [n for n in left if n.endswith(".partial")]
    monkeypatch.undo()
    # no --overwrite: the record says these files are an unfinished run of this scan
    assert main(["process", str(scan), "-o", str(out), "--outputs", ",".join(OUTS)]) == 0
    rec = json.loads((out / "process.json").read_text())
    assert rec["state"] == "done" and rec["files"] == ["albedo.exr", "mask.png", "normal.exr"]


def test_a_scans_own_results_without_a_record_are_replaced(scan, tmp_path):
    """What an interrupted processing left before records were written first: only facette's
    file names, in the scan's own results/ folder."""
    out = scan / "results"
    shutil.rmtree(out, ignore_errors=True)
    process(scan, outputs=OUTS, out_dir=out)
    (out / "process.json").unlink()
    (out / "normal.exr").write_bytes(b"truncated")
    process(scan, outputs=OUTS, out_dir=out)
    assert (out / "normal.exr").stat().st_size > 1000


def test_foreign_files_and_other_sources_are_still_refused(scan, diligent, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["process", str(scan), "-o", str(out), "--outputs", "mask"]) == EXIT_BAD_INPUT
    assert "no facette process run recorded" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine"
    # a finished run of another source: refused without --overwrite
    done = tmp_path / "done"
    process(diligent, outputs=["mask"], out_dir=done)
    before = _tree(done)
    assert main(["process", str(scan), "-o", str(done), "--outputs", "mask"]) == EXIT_BAD_INPUT
    assert "holds the results of another run" in capsys.readouterr().err and _tree(done) == before


def test_an_input_folder_is_never_an_output_folder(diligent, capsys):
    before = _tree(diligent)
    for extra in ([], ["--overwrite"]):
        code = main(["process", str(diligent), "-o", str(diligent), "--outputs", "mask"] + extra)
        assert code == EXIT_BAD_INPUT
        err = capsys.readouterr().err
        assert "is the input folder" in err and "facette never writes its inputs" in err
    assert _tree(diligent) == before          # mask.png and every image unchanged


def test_a_mask_file_in_the_output_folder_is_refused(diligent, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mask.png").write_bytes((diligent / "mask.png").read_bytes())
    before = _sha(out / "mask.png")
    assert main(["process", str(diligent), "-o", str(out), "--mask", str(out / "mask.png"),
                 "--overwrite", "--outputs", "mask"]) == EXIT_BAD_INPUT
    assert "holds the --mask file" in capsys.readouterr().err and _sha(out / "mask.png") == before


def test_process_onto_a_full_disk_says_so_and_leaves_nothing_truncated(scan, small_disk, capsys):
    disk = small_disk(48)
    code = main(["process", str(scan), "-o", str(disk / "out"), "--outputs", "normals,albedo,mask,samples"])
    err = capsys.readouterr().err
    assert code == EXIT_NO_RESULT, err
    assert f"(mounted at {disk}) is full" in err and "run the same command again" in err
    assert "bug" not in err and "Traceback" not in err
    out = disk / "out"
    assert not [p for p in out.iterdir() if p.name.endswith(".partial")]
    for name in ("normal.exr", "albedo.exr"):      # either whole or absent
        p = out / name
        assert not p.exists() or p.stat().st_size > 24 * 32 * 3 * 4


def test_interreflections_on_a_simulated_scan_are_warned_about(tmp_path):
    sc = sphere_on_plane(24, 32)
    folder = write_scan(tmp_path / "sim", sc, render(sc, thesis_light_directions(), "matte", noise=0.002))
    with np.load(folder / "truth.npz") as z:
        truth = {k: z[k] for k in z.files}
    np.savez(folder / "truth.npz", sensor=np.str_("{}"), **truth)      # the rig simulator's truth
    res = process(folder, outputs=["normals"], interreflections=True)
    assert any(n.startswith("--interreflections on a simulated scan: the simulator renders no") for n in res.notes)
    res = process(folder, outputs=["normals"])
    assert not any("simulated scan" in n for n in res.notes)


def test_a_profile_light_below_the_horizon_is_said(tmp_path):
    sc = sphere_on_plane(24, 32)
    folder = write_scan(tmp_path / "s", sc, render(sc, thesis_light_directions(), "matte", noise=0.002))
    data = json.loads((folder / "scan.json").read_text())
    data["lights"][4]["direction"][2] *= -1
    (folder / "scan.json").write_text(json.dumps(data))
    res = process(folder, outputs=["normals"])
    assert any("1 light(s) below the horizon (z < 0; light 4) left out" in n for n in res.notes)   # io.lights


def test_a_scan_being_acquired_is_said_so_not_resume(tmp_path, capsys):
    import subprocess
    import sys
    sc = sphere_on_plane(24, 32)
    folder = write_scan(tmp_path / "s", sc, render(sc, thesis_light_directions(), "matte", noise=0.002))
    data = json.loads((folder / "scan.json").read_text())
    data["exposures"] = [{"index": 0, "time_us": 1000}]
    data["frames"] = [{"file": "raw/L00_E00.dng", "light": 0, "exposure": 0, "sha256": ""}]
    (folder / "scan.json").write_text(json.dumps(data))
    holder = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, os, sys, time\n"
        f"fh = open({str(folder / '.facette.lock')!r}, 'a+')\n"
        "fcntl.flock(fh.fileno(), fcntl.LOCK_EX)\n"
        "fh.write(f'pid {os.getpid()}\\n'); fh.flush()\n"
        "print('locked', flush=True)\n"
        "time.sleep(60)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert main(["process", str(folder), "-o", str(tmp_path / "o"), "--outputs", "normals"]) == EXIT_BAD_INPUT
        err = capsys.readouterr().err
        assert f"is being acquired by another facette process (pid {holder.pid}): 1 of 12 frames so far" in err
        assert "wait for the scan command to end" in err and "resume" not in err and "--allow-incomplete" not in err
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    assert main(["process", str(folder), "-o", str(tmp_path / "o"), "--outputs", "normals"]) == EXIT_BAD_INPUT
    assert "run the same scan command to resume" in capsys.readouterr().err


def test_a_read_only_scan_that_needs_merging_is_named_not_the_output(small_disk, tmp_path, capsys):
    import subprocess
    disk = small_disk(16 * 1024)
    scan = disk / "scan"
    with facette.connect("sim", raw_shape=(48, 64), seed=3) as rig:
        rig.scan(scan, profile=str(sim_profile_dir()), button="press", progress=False)
    shutil.rmtree(scan / "hdr", ignore_errors=True)             # left to processing to merge
    before = _tree(scan)
    subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
    code = main(["process", str(scan), "-o", str(tmp_path / "o"), "--outputs", "normals"])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT
    assert f"the scan {scan} cannot be written (Read-only file system)" in err and "copy the scan" in err
    assert _tree(scan) == before


def test_a_diligent_report_captions_heights_in_pixels(diligent, tmp_path):
    process(diligent, outputs=["height", "report"], out_dir=tmp_path / "px")
    page = (tmp_path / "px" / "report.html").read_text()
    assert "Height (px)" in page and "Height (mm)" not in page
    process(diligent, outputs=["height", "report"], out_dir=tmp_path / "mm", pixel_pitch_mm=0.1)
    assert "Height (mm)" in (tmp_path / "mm" / "report.html").read_text()


def test_the_record_says_when_each_file_was_written(diligent, tmp_path):
    import datetime as dt
    out = tmp_path / "out"
    process(diligent, outputs=OUTS + ["height"], out_dir=out, method="woodham1980")
    rec = json.loads((out / "process.json").read_text())
    assert sorted(rec["written"]) == rec["files"] == ["albedo.exr", "height.exr", "mask.png", "normal.exr"]
    for name, when in rec["written"].items():
        assert dt.datetime.fromisoformat(when).timestamp() == pytest.approx((out / name).stat().st_mtime, abs=1e-3)
