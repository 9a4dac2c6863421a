"""Tests of facette.cli (a package: its test files share names with other subpackages' tests)."""
from facette.cli.main import main


def run_cli(capsys, *argv):
    """(exit code, stdout, stderr) of `facette ARGV`; argparse's refusals (SystemExit) included."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:         # argparse refuses before anything runs
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def run_cli_joined(capsys, *argv):
    """(exit code, stdout + stderr) of `facette ARGV`."""
    code, out, err = run_cli(capsys, *argv)
    return code, out + err
