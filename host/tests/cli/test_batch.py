"""`facette batch`: what it refuses before any worker starts (exit 2, nothing written), and that
its advice works. Every case hashes the scans and the output folder before and after."""
import json
import socket
import time

import pytest

from facette.bench._sim_scan import write_scan

from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

from . import run_cli_joined as _run


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    sc = sphere_on_plane(24, 32)
    return write_scan(tmp_path_factory.mktemp("batch") / "object1", sc,
                      render(sc, thesis_light_directions(), "matte", noise=0.002))


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_result_folder_holding_a_users_files_is_not_written_without_overwrite(scan, tmp_path, capsys, unchanged):
    out = tmp_path / "out"
    (out / "object1").mkdir(parents=True)
    (out / "object1" / "normal.exr").write_bytes(b"the user's own normals")
    with unchanged(scan, out):
        code, said = _run(capsys, "batch", scan, "-o", out, "--outputs", "normals", "--quiet", "--workers", "1")
    assert code == 2 and "no facette run recorded (normal.exr)" in said and "--overwrite" in said
    # the hint followed: --overwrite writes the results beside / over them, and the scan is untouched
    with unchanged(scan):
        code, said = _run(capsys, "batch", scan, "-o", out, "--outputs", "normals", "--quiet", "--workers", "1",
                          "--overwrite")
    assert code == 0, said
    assert json.loads((out / "object1" / "process.json").read_text())["state"] == "done"


@pytest.mark.parametrize("given, words", [("scans/*", "no scan matches"), ("nowhere", "no such folder")])
def test_a_scan_that_is_not_there_is_refused_before_any_folder_is_made(scan, tmp_path, capsys, unchanged,
                                                                        given, words):
    out = tmp_path / "out"
    with unchanged(scan, tmp_path):
        code, said = _run(capsys, "batch", scan, tmp_path / given, "-o", out, "--quiet")
    assert code == 2 and words in said, said
    assert not out.exists()


def test_a_scheduler_nothing_listens_at_is_bad_input_within_seconds(scan, tmp_path, capsys, unchanged):
    t0 = time.monotonic()
    with unchanged(scan, tmp_path):
        code, said = _run(capsys, "batch", scan, "-o", tmp_path / "out", "--scheduler",
                          f"tcp://127.0.0.1:{_free_port()}", "--quiet")
    assert code == 2 and "nothing listens at 127.0.0.1" in said and "leave --scheduler out" in said, said
    assert "Traceback" not in said and "bug in facette" not in said
    assert time.monotonic() - t0 < 30            # dask's own wait was 30 s; here the connection is refused


@pytest.mark.parametrize("argv, words", [
    (["--scheduler", "http://host:8786"], "not a scheduler's address"),
    (["--scheduler", "tcp://host"], "not a scheduler's address"),
    (["--scheduler", "tcp://host:99999"], "not a scheduler's address"),
    (["--workers", "0"], "--workers must be in [1, 256]"),
    (["--workers", "two"], "not a whole number")])
def test_bad_options_are_refused_before_any_work(scan, tmp_path, capsys, unchanged, argv, words):
    with unchanged(scan, tmp_path):
        code, said = _run(capsys, "batch", scan, "-o", tmp_path / "out", *argv)
    assert code == 2 and words in said, said
    assert not (tmp_path / "out").exists()
