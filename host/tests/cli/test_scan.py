"""`facette scan`: its arguments and the checks made before any rig (or simulator) starts.
(Scans on the simulated rig, and the device's own limits: hil_tests/test_bad_input.py.)"""
import argparse
import json
import shutil
from pathlib import Path

import pytest

import facette.scan
from facette.cli import _scan
from facette.cli.main import build_parser, main

REPO = Path(__file__).resolve().parents[3]


def test_exposures_parse_seconds_fractions_microseconds_and_currents():
    assert _scan._exposures("2,1/5, 250us@800") == [(2_000_000, 0), (200_000, 0), (250, 800)]


@pytest.mark.parametrize("text, words", [
    ("1/0", "is not a time"), ("abc", "is not a time"), ("0.5us", "shorter than 1 µs"),
    ("31", "longer than the device's hard limit of 30 s"), ("1/5@0", "1..1500 mA"),
    ("1/5@2000", "1..1500 mA"), ("1/5,,1/50", "not a list of exposures"), (",".join(["1"] * 17), "1..16"),
])
def test_bad_exposures(text, words):
    with pytest.raises(argparse.ArgumentTypeError, match=None) as exc:
        _scan._exposures(text)
    assert words in str(exc.value)


@pytest.mark.parametrize("text, words", [
    ("0,0,1", "light 0 is listed twice"), ("0,a", "is not a list of LED channels"),
    ("16", "LED channel 16 does not exist: channels are 0..15"), ("-1", "does not exist"), (",", "no LED"),
])
def test_bad_lights(text, words):
    with pytest.raises(argparse.ArgumentTypeError) as exc:
        _scan._lights(text)
    assert words in str(exc.value)


def test_currents_and_sizes():
    assert _scan._current("1000") == 1000 and _scan._shape("128x96") == (96, 128)
    for bad in ("0", "1501", "-100", "1.5"):
        with pytest.raises(argparse.ArgumentTypeError):
            _scan._current(bad)
    for bad in ("0x10", "7x8", "128", "axb"):
        with pytest.raises(argparse.ArgumentTypeError):
            _scan._shape(bad)


@pytest.fixture
def no_rig(monkeypatch):
    """Any attempt to connect (which would start the simulated rig) fails the test."""
    def refuse(*a, **k):
        raise AssertionError("a rig was started before the arguments were checked")
    monkeypatch.setattr(facette.scan, "connect", refuse)


def _cli(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


def test_a_damaged_profile_is_named_before_the_rig_starts(no_rig, capsys, tmp_path):
    prof = tmp_path / "prof"
    shutil.copytree(REPO / "calibration" / "profiles" / "sim-default", prof)
    data = json.loads((prof / "profile.json").read_text())
    data["lights"][0]["intensity"] = [0, 1, 1]
    (prof / "profile.json").write_text(json.dumps(data))
    code, err = _cli(capsys, "scan", "--sim", "--profile", prof, tmp_path / "s")
    assert code == 2 and f"{prof / 'profile.json'} does not match its checksum" in err, err
    code, err = _cli(capsys, "scan", "--sim", "--profile", tmp_path / "none", tmp_path / "s")
    assert code == 2 and "no calibration profile at" in err, err
    assert not (tmp_path / "s").exists()


def test_a_profile_without_an_id_is_named_not_a_key_error(no_rig, capsys, tmp_path):
    from facette.calib.profile import _checksum

    prof = tmp_path / "prof"
    shutil.copytree(REPO / "calibration" / "profiles" / "sim-default", prof)
    data = json.loads((prof / "profile.json").read_text())
    del data["id"]
    data["checksum"] = _checksum(data)
    (prof / "profile.json").write_text(json.dumps(data))
    code, err = _cli(capsys, "scan", "--sim", "--profile", prof, tmp_path / "s")
    assert code == 2 and "lacks id" in err and "KeyError" not in err, err


def test_a_profile_with_a_non_positive_intensity_says_which_light(tmp_path):
    from facette.calib import ProfileError
    from facette.calib.profile import Lights

    with pytest.raises(ProfileError, match=r"light\(s\) \[1\] have \[1.0, 0.0, 1.0\]"):
        Lights(directions=[[0, 0, 1], [0, 0, 1]], intensities=[[1, 1, 1], [1, 0, 1]])


@pytest.mark.parametrize("args, words", [
    (["--press-button"], "--press-button needs --sim"),
    ([], "say which rig"),
    (["--device", "/dev/ttyACM0"], "a real rig needs a camera"),
])
def test_which_rig_and_camera_are_asked_for_first(no_rig, capsys, tmp_path, args, words):
    code, err = _cli(capsys, "scan", *args, tmp_path / "s")
    assert code == 2 and words in err, err
    assert not (tmp_path / "s").exists()


def test_an_output_path_that_is_a_file_is_refused_before_the_rig_starts(no_rig, capsys, tmp_path):
    f = tmp_path / "f"
    f.write_text("x")
    code, err = _cli(capsys, "scan", "--sim", f)
    assert code == 2 and f"{f} is a file" in err and f.read_text() == "x", err


def test_the_scan_hands_its_directory_to_process_and_drops_what_it_did_not_take(monkeypatch, tmp_path, capsys):
    """`facette scan` processes the ScanDirectory the scan returned (its held lights with it),
    with `facette process`'s default options, by a call: no argv, no module-level store."""
    import facette.pipeline
    from facette.scan import ScanDirectory

    class Held:
        def arrays(self):
            return "radiance", "variance"

    sd = ScanDirectory(tmp_path / "s")
    sd.hold_light(0, Held())
    sd.hold_light(1, Held())
    calls = []

    def process(source, **kw):
        calls.append((source, kw))
        assert source.take_held_light(0) == ("radiance", "variance")      # what load_input does
        return "result"

    monkeypatch.setattr(facette.pipeline, "process", process)
    monkeypatch.setattr(_scan, "print_result", lambda res: print(f"printed {res}"))
    assert _scan._process(sd) == tmp_path / "s" / "results"
    [(source, kw)] = calls
    assert source is sd and kw == {"out_dir": tmp_path / "s" / "results",
                                   "fit_options": {"model": "auto", "method": "least_squares"}}
    assert sd.held_lights() == [] and "printed result" in capsys.readouterr().out


def test_the_scan_processing_options_are_facette_process_defaults():
    """A later `facette process SCAN -o SCAN/results` finds the scan's own run, not another."""
    from facette.cli import _process

    parser = argparse.ArgumentParser()
    _process.register(parser.add_subparsers())
    args = parser.parse_args(["process", "scan", "-o", "out"])
    # every option process.json records, as `facette process` builds them from its own flags,
    # against those of the scan's call (PROCESS_FIT_OPTIONS is the one thing the scan passes)
    from facette.pipeline import ProcessOptions
    assert _process.options(args).recorded() == \
        ProcessOptions(fit_options=dict(_scan.PROCESS_FIT_OPTIONS)).recorded()


def test_the_scan_command_does_not_import_the_command_line_entry():
    """No cycle cli.main <-> cli._scan: the scan command imports no facette.cli.main, even
    inside a function."""
    import ast

    tree = ast.parse(Path(_scan.__file__).read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert "facette.cli.main" not in names and "facette.cli" not in names


def test_a_scan_with_a_memory_budget_processes_as_process_memory_does(monkeypatch, tmp_path, capsys):
    """`facette scan --memory 2GB` hands the budget on: the default method, the outputs that
    stream (or those asked for), the same fit options as ever."""
    import facette.pipeline
    from facette.pipeline._tiled_process import STREAMED_OUTPUTS
    from facette.scan import ScanDirectory

    calls = []
    monkeypatch.setattr(facette.pipeline, "process", lambda source, **kw: calls.append(kw) or "result")
    monkeypatch.setattr(_scan, "print_result", lambda res: None)
    sd = ScanDirectory(tmp_path / "s")
    _scan._process(sd, memory="2GB")
    _scan._process(sd, memory="2GB", outputs=["normals", "height"])
    assert calls[0]["memory"] == "2GB" and calls[0]["outputs"] == list(STREAMED_OUTPUTS)
    assert "method" not in calls[0]           # the default, li_alternating, runs over bands too
    assert calls[1]["outputs"] == ["normals", "height"]
    assert calls[0]["fit_options"] == dict(_scan.PROCESS_FIT_OPTIONS)
    assert "--memory: photometric stereo with" not in capsys.readouterr().out


def test_a_memory_budget_that_is_not_a_size_is_refused_before_the_rig_starts(no_rig, capsys, tmp_path):
    code, err = _cli(capsys, "scan", "--sim", "--memory", "2 apples", tmp_path / "s")
    assert code == 2 and "--memory" in err and "2GB" in err, err
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("memory, words", [("100MB", "cannot hold the processing after the last frame"),
                                           ("1TB", "more than this machine's")])
def test_a_memory_budget_processing_cannot_keep_is_refused_before_the_scan(no_rig, capsys, tmp_path, memory, words):
    code, err = _cli(capsys, "scan", "--sim", "--memory", memory, tmp_path / "s")
    assert code == 2 and words in err, err
    assert not (tmp_path / "s").exists()
    if "give --memory" in err:             # the hint followed: its budget passes the checks made before the rig
        hinted = err.split("give --memory ")[1].split()[0]
        args = build_parser("scan").parse_args(["scan", "--sim", "--memory", hinted,
                                                                     str(tmp_path / "s")])
        assert _scan._check_arguments(args) is not None
        code, err = _cli(capsys, "scan", "--sim", "--memory", memory, "--no-process", tmp_path / "s2")
        assert "cannot hold" not in err and "a rig was started" in err    # --no-process, the other advice: checks pass


def test_a_processing_that_failed_after_the_scan_says_the_scan_is_kept(tmp_path):
    from facette.errors import BadInputError, InsufficientData
    exc = _scan._scan_kept(BadInputError("0.50 GB cannot hold ...", hint="give at least 0.72 GB"), tmp_path / "s")
    assert f"the scan is complete and kept in {tmp_path / 's'}" in exc.message
    assert exc.hint.endswith(f"then process it with: facette process {tmp_path / 's'} -o {tmp_path / 's' / 'results'}")
    exc = _scan._scan_kept(InsufficientData("too few lights", hint="capture with more lights"), tmp_path / "s")
    assert exc.hint == "capture with more lights"        # the scan cannot give results: no command to redo
