"""`facette calibrate`: bad arguments are refused before any rig starts (the wizard's own steps on
the simulated rig: hil_tests/test_calibrate_wizard.py)."""
import pytest

import facette.scan
from facette.cli.main import main


@pytest.fixture
def no_rig(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("a rig was started before the arguments were checked")
    monkeypatch.setattr(facette.scan, "connect", refuse)


@pytest.mark.parametrize("args, words", [
    (["--only", "noise,focus"], "unknown step(s) ['focus']"),
    (["--sim-raw-size", "10"], "--sim-raw-size: '10' is not a size"),
    (["--sim-speed", "-1"], "'-1' must be > 0"),
    (["--current", "0"], "--current 0 mA is outside 1..1500 mA"),          # issue 51: each was taken (or a
    (["--current", "99999"], "outside 1..1500 mA"),                         # traceback) before
    (["--leds", "-3"], "--leds must be in [4, 16]"),
    (["--led-distance", "nan"], "--led-distance must be > 0"),
    (["--led-distance", "-5"], "--led-distance must be > 0"),
    (["--sim-intensity-error", "nan"], "--sim-intensity-error must be in [0, 1]"),
    (["--sim-direction-error", "-1"], "--sim-direction-error must be in [0, 45]"),
    (["--sim-seed", "-1"], "--sim-seed must be >= 0"),
])
def test_bad_arguments(no_rig, capsys, tmp_path, args, words):
    try:
        code = main(["calibrate", "--rig", "sim", "--yes", "-o", str(tmp_path / "p"), *args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and words in err and "Traceback" not in err, err
    assert not (tmp_path / "p").exists()
