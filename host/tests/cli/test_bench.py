"""`facette bench`: an unknown benchmark is named with the list of known ones."""
from facette.cli.main import main


def test_an_unknown_benchmark_lists_the_known_ones(capsys):
    assert main(["bench", "no_such_bench"]) == 2
    err = capsys.readouterr().err
    assert "unknown benchmark 'no_such_bench'" in err and "hdr" in err
