"""`facette bench relight_web` on a tiny capture: it makes the capture, runs process and relight each in a
process of its own and prints their figures."""
from facette.bench import relight_web


def test_the_bench_runs_and_prints_its_figures(tmp_path, capsys):
    assert relight_web.main(["--size", "60", "80", "--lights", "12", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "80x60 (0.0 MP), 12 JPEG photographs" in out
    assert "process --outputs relight-web:" in out and "peak" in out
    assert "relight OUT/relight_web (image, one light)" in out
    assert (tmp_path / "out" / "relight_web" / "info.json").is_file() and (tmp_path / "lit.png").is_file()
