"""`facette` (cli/main.py): one error path, documented exit codes, a traceback only for a bug."""
import errno

import pytest

from facette.cli import main as cli
from facette.errors import BadInputError, InsufficientData, StoppedError


def test_help_and_an_unknown_command(capsys):
    assert cli.main([]) == 0
    assert "COMMAND" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        cli.main(["nonsense"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'nonsense'" in err and "usage" not in err and len(err.splitlines()) == 2


@pytest.mark.parametrize("exc, code, first", [
    (BadInputError("the file x is bad", hint="fix it"), 2, "the file x is bad"),
    (StoppedError("the scan stopped"), 1, "the scan stopped"),
    (InsufficientData("too dark", hint="lengthen the exposures"), 3, "too dark"),
    (SystemExit("say which rig"), 2, "say which rig"),
    (PermissionError(errno.EACCES, "Permission denied", "/x/y"), 2, "/x/y: Permission denied"),
    (IsADirectoryError(errno.EISDIR, "Is a directory", "/x"), 2, "/x: Is a directory"),
])
def test_expected_failures_get_their_exit_code_and_one_or_two_lines(exc, code, first):
    got, lines = cli.explain(exc)
    assert got == code and lines[0] == first and 1 <= len(lines) <= 2


def _raise_from_numpy():
    import numpy as np

    np.zeros(3).reshape(7)          # a ValueError from inside numpy: a bug of ours


def test_a_value_error_raised_by_facette_is_bad_input_one_from_numpy_is_a_bug(capsys):
    from facette.pipeline import stages_needed

    try:
        stages_needed(["nothing"])
    except ValueError as exc:
        code, lines = cli.explain(exc)
    assert code == 2 and lines[0].startswith("unknown output(s) ['nothing']")
    try:
        _raise_from_numpy()
    except ValueError as exc:
        code, lines = cli.explain(exc)
    assert code == 70 and "bug in facette" in lines[0] and "report" in lines[0]
    assert "Traceback" in capsys.readouterr().err


def test_a_bug_in_a_command_prints_its_traceback_and_asks_for_a_report(monkeypatch, capsys):
    import facette.cli._bench as bench

    monkeypatch.setattr(bench, "run", lambda args: {}["missing"])
    assert cli.main(["bench", "x"]) == 70
    err = capsys.readouterr().err
    assert "Traceback" in err and "KeyError" in err and "please report it" in err


def test_a_facette_error_in_a_command_ends_in_its_lines(monkeypatch, capsys):
    import facette.cli._bench as bench

    def run(args):
        raise InsufficientData("light 3 is saturated", hint="shorten the exposures")
    monkeypatch.setattr(bench, "run", run)
    assert cli.main(["bench", "x"]) == 3
    assert capsys.readouterr().err == "facette bench: light 3 is saturated\n  shorten the exposures\n"


def test_ctrl_c_is_130(monkeypatch, capsys):
    import facette.cli._bench as bench

    def run(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(bench, "run", run)
    assert cli.main(["bench", "x"]) == 130
    assert "interrupted" in capsys.readouterr().err


@pytest.mark.parametrize("command, words", [("scan", "the same command resumes the scan"),
                                            ("process", "the same command redoes it"),
                                            ("batch", "the same command processes the others"),
                                            ("relight", "nothing of yours was changed")])
def test_ctrl_c_says_what_it_leaves_for_each_command(monkeypatch, capsys, command, words):
    import importlib

    from facette.cli.main import COMMANDS

    def interrupted(args):
        raise KeyboardInterrupt
    monkeypatch.setattr(importlib.import_module(COMMANDS[command][0]), "run", interrupted)
    argv = {"scan": ["scan", "--sim", "x"], "process": ["process", "x", "-o", "y"], "batch": ["batch", "x", "-o", "y"],
            "relight": ["relight", "x.ptm"]}[command]
    assert cli.main(argv) == 130
    err = capsys.readouterr().err
    assert err.startswith(f"facette {command}: interrupted; ") and words in err
    assert command == "scan" or "scan resumes" not in err
