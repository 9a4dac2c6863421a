"""`facette sim`: bad arguments are refused before the simulated rig starts (its happy path, the
first line `port: ...` and commands on standard input: hil_tests/test_rig_cli.py)."""
import pytest

from facette.cli.main import main


@pytest.mark.parametrize("args, words", [
    (["--speed", "0"], "--speed: '0' must be > 0"),
    (["--raw-size", "0x0"], "even and at least 8"),
    (["--seed", "x"], "'x' is not a whole number"),
    (["--seed", "-1"], "--seed must be >= 0"),
])
def test_bad_arguments(capsys, args, words):
    with pytest.raises(SystemExit) as exc:
        main(["sim", *args])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and words in err and len(err.splitlines()) == 2, err
