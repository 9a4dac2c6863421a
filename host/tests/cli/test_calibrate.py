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
])
def test_bad_arguments(no_rig, capsys, tmp_path, args, words):
    try:
        code = main(["calibrate", "--rig", "sim", "--yes", "-o", str(tmp_path / "p"), *args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and words in err and "Traceback" not in err, err
    assert not (tmp_path / "p").exists()
