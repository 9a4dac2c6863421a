"""Advice that works (issue 51): the hints `facette scan` and `facette process` print about a scan
are followed here, on the simulated rig, and do what they say. Every case hashes the scan's files
before and after the command that only reads them."""
import hashlib
import json
import shutil
from pathlib import Path

import pytest

import facette
from facette.cli.main import main
from facette.scan import ScanAborted, ScanDirectory

PROFILE = Path(__file__).resolve().parent.parent / "calibration" / "profiles" / "sim-default"
# the command that made the scan below, as a person would type it
SCAN = ["scan", "--sim", "--press-button", "--no-process", "--quiet", "--raw-size", "32x24",
        "--exposures", "1/5,1/50", "--profile", str(PROFILE)]


def _tree(path):
    """sha256 of what a scan's capture made: its frames (raw/) and scan.json without the HDR record
    that processing adds (hdr/ and that record are derived from the frames, docs/scan-format.md)."""
    path = Path(path)
    out = {str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
           for p in sorted((path / "raw").rglob("*")) if p.is_file()}
    manifest = json.loads((path / "scan.json").read_text())
    manifest.pop("hdr", None)
    out["scan.json"] = hashlib.sha256(json.dumps(manifest, sort_keys=True).encode()).hexdigest()
    return out


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _stopped_at(d, lights_done):
    """The scan of SCAN (12 lights x 2 exposures) stopped once `lights_done` lights are taken."""
    rig = facette.connect("sim", raw_shape=(24, 32), speed=20)
    try:
        taken = []

        def abort(rec):
            taken.append(rec)
            if len(taken) == 2 * lights_done:
                rig.abort()
        with pytest.raises(ScanAborted):
            rig.scan(d, exposures=[(200_000, 0), (20_000, 0)], progress=False, on_frame=abort, profile=PROFILE)
    finally:
        rig.close()


def test_a_scan_stopped_at_2_of_12_lights_is_told_to_resume_and_resuming_works(capsys, tmp_path):
    d = tmp_path / "s"
    _stopped_at(d, 2)
    k = len({f.light for f in ScanDirectory(d).manifest.frames})     # 2, or 3 when a frame came after the abort
    assert k in (2, 3)
    before = _tree(d)
    code, out, err = _run(capsys, "process", d, "-o", tmp_path / "r", "--allow-incomplete", "--outputs", "normals")
    assert code == 3 and f"the scan stopped at {k} of its 12 lights" in err and "resumes" in err, err
    assert "capture with more lights" not in err and _tree(d) == before
    # the hint followed: the scan command again, the same directory
    code, out, err = _run(capsys, *SCAN, d)
    assert code == 0, err
    m = ScanDirectory(d).manifest
    assert len({(f.light, f.exposure) for f in m.frames}) == m.n_planned == 24
    code, out, err = _run(capsys, "process", d, "-o", tmp_path / "r", "--outputs", "normals")
    assert code == 0, err


def test_the_command_a_failed_processing_after_the_scan_gives_processes_it(capsys, tmp_path, monkeypatch):
    from facette.cli import _scan
    from facette.errors import BadInputError

    def refuse(*a, **k):
        raise BadInputError("0.50 GB cannot hold the outputs kept", hint="give at least 0.72 GB")
    d = tmp_path / "s"
    with monkeypatch.context() as m:
        m.setattr(_scan, "_process", refuse)
        code, out, err = _run(capsys, *[a for a in SCAN if a != "--no-process"], d)
    assert code == 2 and f"the scan is complete and kept in {d}" in err, err
    hinted = err.split("process it with: facette ")[1].split()
    before = _tree(d)
    code, out, err = _run(capsys, *hinted, "--outputs", "normals")
    assert code == 0, err
    assert (d / "results" / "normal.exr").is_file()
    assert _tree(d) == before


def test_a_scan_being_acquired_is_not_advised_a_flag_the_lock_refuses(capsys, tmp_path):
    import subprocess
    import sys
    d = tmp_path / "s"
    _stopped_at(d, 1)
    holder = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, os, time\n"
        f"fh = open({str(d / '.facette.lock')!r}, 'a+')\n"
        "fcntl.flock(fh.fileno(), fcntl.LOCK_EX)\n"
        "fh.write(f'pid {os.getpid()}\\n'); fh.flush()\n"
        "print('locked', flush=True)\n"
        "time.sleep(60)\n")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        before = _tree(d)
        code, out, err = _run(capsys, "process", d, "-o", tmp_path / "r", "--outputs", "normals")
        assert code == 2 and "being acquired" in err and "--allow-incomplete" not in err, err
        assert "run this command again" in err and _tree(d) == before
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    shutil.rmtree(tmp_path / "r", ignore_errors=True)
    # the hint followed once the scan command ended (here: it is resumed to its end)
    assert _run(capsys, *SCAN, d)[0] == 0
    assert _run(capsys, "process", d, "-o", tmp_path / "r", "--outputs", "normals")[0] == 0
