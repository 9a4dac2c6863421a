"""The bad-input suite: every mistake a user can make with `facette scan`, `facette device` and a
scan directory gets a clear message (what was wrong, what to do) and a documented exit code, and
loses nothing (every frame of scan.json on disk with its sha256, no file gone).

Exit codes (facette.errors): 1 a stopped scan or a device fault, 2 bad input, 3 data that cannot
give a result. The simulated rig is the real firmware core over a pty.
"""
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from facette.cli.main import main
from facette.io.checksum import sha256_file
from facette.scan import ScanDirectory

FACETTE = [sys.executable, "-m", "facette.cli.main"]
SMALL = ["--raw-size", "32x24", "--lights", "0,1,2,3", "--exposures", "1/5,1/50", "--quiet"]


def run_cli(capsys, *argv):
    """`facette ARGV` in this process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def frames_intact(scan_dir):
    """Every frame listed in scan.json is on disk with the sha256 recorded at capture; returns
    the number of frames (a scan directory where this fails has lost something)."""
    m = ScanDirectory(scan_dir).manifest
    for f in m.frames:
        p = Path(scan_dir) / f.file
        assert p.is_file(), f"{f['file']} listed in scan.json is missing"
        assert sha256_file(p) == f.sha256, f"{f.file} differs from its sha256 in scan.json"
    return len(m.frames)


def tree(path):
    """{relative path: sha256} of every file under `path` (to show that nothing changed)."""
    path = Path(path)
    return {str(p.relative_to(path)): sha256_file(p) for p in sorted(path.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def small_scan(tmp_path_factory):
    """One complete 4 lights × 2 exposures simulated scan (32x24 RAW), not processed; tests copy it."""
    d = tmp_path_factory.mktemp("scan") / "s"
    code = main(["scan", "--sim", "--press-button", "--no-process", *SMALL, str(d)])
    assert code == 0
    return d


@pytest.fixture
def scan_copy(small_scan, tmp_path):
    d = tmp_path / "s"
    shutil.copytree(small_scan, d)
    return d


# ---------------------------------------------------------------- arguments, before anything starts
@pytest.mark.parametrize("args, words", [
    (["--lights", "0,0,1"], "light 0 is listed twice"),
    (["--lights", "0,x"], "--lights"),
    (["--current", "-100"], "--current -100"),
    (["--current", "0"], "--current 0"),
    (["--current", "2000"], "1500 mA"),
    (["--exposures", "0.5us"], "shorter than 1"),
    (["--exposures", "40"], "30 s"),
    (["--exposures", "1/5@-3"], "current"),
    (["--exposures", ""], "--exposures"),
    (["--raw-size", "0x10"], "--raw-size"),
    (["--speed", "0"], "--speed"),
])
def test_scan_arguments_are_refused_before_the_rig_starts(capsys, tmp_path, args, words):
    d = tmp_path / "s"
    with pytest.raises(SystemExit) as exc:
        main(["scan", "--sim", "--press-button", "--no-process", "--quiet", *args, str(d)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and words in err, err
    assert "Traceback" not in err
    assert not d.exists()                                      # nothing created


def test_a_current_above_the_device_limit_is_refused_before_the_directory_exists(capsys, tmp_path):
    """Finding 2: the device's max_current_mA (1000 by default) is read and applied by the host."""
    d = tmp_path / "s"
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL,
                             "--current", "1200", str(d))
    assert code == 2, err
    assert "max_current_mA" in err and "1000 mA" in err and "1200" in err
    assert "faults []" not in err and "Traceback" not in err
    assert not d.exists()


def test_an_exposure_above_the_device_pulse_limit_is_refused(capsys, tmp_path):
    d = tmp_path / "s"
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", "--quiet",
                             "--raw-size", "32x24", "--lights", "0", "--exposures", "25",
                             "--mode", "led", str(d))
    assert code == 2, err
    assert "max_pulse_us" in err and "20 s" in err
    assert not d.exists()


def test_a_refused_scan_leaves_no_directory_so_a_valid_rerun_works(capsys, tmp_path):
    """Finding 6: a plan is checked before anything is written."""
    d = tmp_path / "s"
    code, _, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL,
                           "--lights", "0,13", str(d))
    assert code == 2 and "13" in err and not d.exists(), err
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL, str(d))
    assert code == 0, err
    assert frames_intact(d) == 8


# ---------------------------------------------------------------- the scan directory
def test_two_scans_into_one_directory_the_second_is_refused_and_nothing_is_lost(tmp_path):
    """Finding 1: one writer at a time (an flock the kernel drops when a process dies)."""
    d = tmp_path / "s"
    cmd = FACETTE + ["scan", "--sim", "--press-button", "--no-process", "--speed", "1",
                     "--raw-size", "32x24", "--lights", "0,1,2,3", "--exposures", "1/5,1/50,1/500",
                     "--quiet", str(d)]
    first = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not _frames_recorded(d) and time.monotonic() < deadline:
        time.sleep(0.02)                       # until the first scan holds the directory (~4 s left)
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    out1, err1 = first.communicate(timeout=120)
    assert first.returncode == 0, err1
    assert second.returncode == 2, second.stderr
    assert "another facette process" in second.stderr and "Traceback" not in second.stderr
    assert frames_intact(d) == 12
    assert not (d / "raw" / "unmatched").exists()
    assert ScanDirectory(d).manifest.complete


def _frames_recorded(d):
    try:
        return len(json.loads((d / "scan.json").read_text())["frames"]) >= 1
    except (OSError, ValueError):
        return False


def test_a_lock_left_by_a_killed_scan_does_not_block_the_next(tmp_path):
    d = tmp_path / "s"
    cmd = FACETTE + ["scan", "--sim", "--press-button", "--no-process", "--speed", "50",
                     "--raw-size", "32x24", "--lights", "0,1", "--exposures", "1/5,1/50", "--quiet", str(d)]
    first = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not (d / "scan.json").exists() and time.monotonic() < deadline:
        time.sleep(0.02)
    first.kill()
    first.wait(timeout=30)
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert frames_intact(d) == 4


def test_a_corrupt_frame_is_reshot_on_resume_and_the_damaged_file_kept(capsys, scan_copy):
    """Finding 5: a frame whose sha256 fails is taken again (only a missing one was)."""
    m = ScanDirectory(scan_copy).manifest
    bad = scan_copy / m.frames[2].file
    data = bytearray(bad.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL, scan_copy)
    assert code == 0, err
    assert "sha256" in out and m.frames[2].file in out
    assert frames_intact(scan_copy) == 8
    kept = list((scan_copy / "raw" / "damaged").iterdir())
    assert len(kept) == 1 and kept[0].read_bytes() == bytes(data)


@pytest.mark.parametrize("damage, words", [
    (lambda d: (d / "scan.json").write_text("{ not json"), "scan.json"),
    (lambda d: (d / "scan.json").write_text("[]"), "scan.json"),
])
def test_a_damaged_scan_json_is_named_and_nothing_is_touched(capsys, scan_copy, damage, words):
    damage(scan_copy)
    before = tree(scan_copy)
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL, scan_copy)
    assert code == 2, err
    assert str(scan_copy / "scan.json") in err and "journal.jsonl" in err and "Traceback" not in err
    assert tree(scan_copy) == before
    code, out, err = run_cli(capsys, "process", scan_copy, "-o", scan_copy.parent / "r")
    assert code == 2 and str(scan_copy / "scan.json") in err and "Traceback" not in err, err


def test_a_directory_holding_another_plan_says_which_setting_differs(capsys, scan_copy):
    before = tree(scan_copy)
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", "--quiet",
                             "--raw-size", "32x24", "--lights", "0,1,2,3", "--exposures", "1/5", scan_copy)
    assert code == 2, err
    assert "exposures" in err and "choose a new directory" in err and "Traceback" not in err
    assert tree(scan_copy) == before


def test_the_scan_output_path_is_a_file(capsys, tmp_path):
    f = tmp_path / "taken"
    f.write_text("mine")
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL, f)
    assert code == 2 and str(f) in err and "Traceback" not in err, err
    assert f.read_text() == "mine"


def read_only_folder(tmp_path):
    """A folder this process cannot create anything in: a chmod 500 one, or /sys for root
    (which ignores permission bits)."""
    if os.geteuid() == 0:
        return Path("/sys")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    return ro


def test_the_scan_output_path_is_read_only(capsys, tmp_path):
    ro = read_only_folder(tmp_path)
    try:
        code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL,
                                 ro / "s")
    finally:
        ro.chmod(0o700) if ro != Path("/sys") else None
    assert code == 2 and str(ro / "s") in err and "write" in err and "Traceback" not in err, err


def test_a_profile_with_a_bad_checksum_is_named(capsys, tmp_path):
    src = Path(__file__).resolve().parent.parent / "calibration" / "profiles" / "sim-default"
    prof = tmp_path / "prof"
    shutil.copytree(src, prof)
    pj = prof / "profile.json"
    data = json.loads(pj.read_text())
    data["pixel_pitch_mm"] = 0.123
    pj.write_text(json.dumps(data))
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL,
                             "--profile", prof, tmp_path / "s")
    assert code == 2 and str(pj) in err and "checksum" in err and "Traceback" not in err, err
    assert not (tmp_path / "s").exists()


def test_scan_exits_non_zero_when_its_processing_step_fails(capsys, tmp_path):
    """Finding 7: the scan's own processing failing is not a success. One light cannot
    give photometric stereo: the data cannot carry the result (exit 3)."""
    d = tmp_path / "s"
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--quiet", "--raw-size", "32x24",
                             "--lights", "0", "--exposures", "1/5", d)
    assert code == 3, (out, err)
    assert "photometric stereo needs at least 4 lights" in err and "capture with more lights" in err
    assert frames_intact(d) == 1


# ---------------------------------------------------------------- derived files follow their inputs
def _incomplete_scan(d, stop_after=3):
    """A 3 lights × 2 exposures scan aborted after `stop_after` frames (library, simulated rig)."""
    import facette
    from facette.scan import ScanAborted

    rig = facette.connect("sim", raw_shape=(24, 32), speed=20)   # slow enough to abort mid-scan
    try:
        taken = []

        def abort(rec):
            taken.append(rec)
            if len(taken) == stop_after:
                rig.abort()
        with pytest.raises(ScanAborted):
            rig.scan(d, lights=[0, 1, 2], exposures=[(200_000, 0), (20_000, 0)], progress=False,
                     on_frame=abort, profile=Path(__file__).resolve().parent.parent / "calibration"
                     / "profiles" / "sim-default")
    finally:
        rig.close()


def test_an_incomplete_scan_is_processed_only_on_request_and_says_so(capsys, tmp_path):
    """Finding 4 (second half): not "Capture with more lights" but "the scan is incomplete"."""
    d = tmp_path / "s"
    _incomplete_scan(d)
    before = tree(d)
    code, out, err = run_cli(capsys, "process", d, "-o", tmp_path / "r")
    assert code == 2, err
    assert "the scan is incomplete" in err and "run the same scan command to resume" in err
    assert "--allow-incomplete" in err and tree(d) == before and not (tmp_path / "r").exists()
    code, out, err = run_cli(capsys, "process", d, "-o", tmp_path / "r", "--allow-incomplete",
                             "--outputs", "normals,mesh,report")
    assert code in (0, 3), err                     # 3: too few frames may not carry normals
    if code == 0:
        assert "the scan is incomplete" in out
        rec = json.loads((tmp_path / "r" / "process.json").read_text())
        assert rec["scan_incomplete"] and "the scan is incomplete" in (tmp_path / "r" / "report.html").read_text()
        from facette.io.exr import read_exr_header

        assert "incomplete" in read_exr_header(tmp_path / "r" / "normal.exr")["scan"]
        assert b"scan incomplete" in (tmp_path / "r" / "mesh.ply").read_bytes()[:300]


def test_hdr_made_before_a_frame_was_reshot_is_merged_again(capsys, scan_copy, tmp_path):
    """Finding 4: hdr/ is not reused once its frames changed (here a deleted frame re-shot; a
    resumed scan is the same case: other frames than the merge took)."""
    from facette.io.exr import read_exr

    assert run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r1", "--outputs", "normals")[0] == 0
    (scan_copy / "raw" / "L02_E01.dng").unlink()
    code, out, err = run_cli(capsys, "scan", "--sim", "--press-button", "--no-process", *SMALL, scan_copy)
    assert code == 0, err
    code, out, err = run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r2", "--outputs", "normals")
    assert code == 0, err
    assert "hdr/light_02.exr was merged from other frames" in out
    assert "light_00" not in out and "light_03" not in out          # the others are still good
    m = ScanDirectory(scan_copy).manifest
    hdr, frames = m.hdr, m.frames
    assert sorted((i["file"], i["sha256"]) for i in hdr.lights[2].inputs) == \
        sorted((f.file, f.sha256) for f in frames if f.light == 2)
    fresh = tmp_path / "fresh"
    shutil.copytree(scan_copy, fresh, ignore=shutil.ignore_patterns("hdr"))
    assert run_cli(capsys, "process", fresh, "-o", tmp_path / "r3", "--outputs", "normals")[0] == 0
    for li in range(4):
        a, _ = read_exr(scan_copy / "hdr" / f"light_{li:02d}.exr")
        b, _ = read_exr(fresh / "hdr" / f"light_{li:02d}.exr")
        assert (a == b).all()
    assert frames_intact(scan_copy) == 8


def test_an_edited_hdr_file_is_merged_again_and_named(capsys, scan_copy, tmp_path):
    """Finding 3 (last case): +Inf in one HDR file; the file is named, and since the scan
    directory owns its derived files, it is merged again from raw/."""
    import numpy as np

    from facette.io.exr import read_exr, write_exr

    assert run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r1", "--outputs", "normals")[0] == 0
    img, names = read_exr(scan_copy / "hdr" / "light_01.exr")
    img[3:6, 3:6] = np.inf
    write_exr(scan_copy / "hdr" / "light_01.exr", img, names)
    code, out, err = run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r2", "--outputs", "normals")
    assert code == 0, err
    assert "hdr/light_01.exr changed since it was merged" in out
    assert np.isfinite(read_exr(scan_copy / "hdr" / "light_01.exr")[0]).all()
    a = (tmp_path / "r1" / "normal.exr").read_bytes()
    assert a == (tmp_path / "r2" / "normal.exr").read_bytes()


def test_a_damaged_hdr_file_that_looks_unchanged_is_named(capsys, scan_copy, tmp_path):
    """Same size and time as the merge recorded, but not an EXR any more: named, with what to do."""
    assert run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r1", "--outputs", "normals")[0] == 0
    p = scan_copy / "hdr" / "light_03_var.exr"
    st = p.stat()
    p.write_bytes(b"\0" * st.st_size)
    os.utime(p, ns=(st.st_atime_ns, st.st_mtime_ns))
    code, out, err = run_cli(capsys, "process", scan_copy, "-o", tmp_path / "r2", "--outputs", "normals")
    assert code == 2 and "light_03_var.exr: cannot read this HDR image" in err, err
    assert "delete it: processing merges it again from raw/" in err and "Traceback" not in err
    assert frames_intact(scan_copy) == 8
