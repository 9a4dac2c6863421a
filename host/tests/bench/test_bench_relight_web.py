"""`facette bench relight_web` on a tiny capture: it makes the capture, runs process and relight each in a
process of its own and prints their figures; again on the capture it made, other outputs, read as a
machine with much free memory would."""
import json

from facette.bench import relight_web


def test_the_bench_runs_and_prints_its_figures(tmp_path, capsys):
    assert relight_web.main(["--size", "60", "80", "--lights", "12", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "80x60 (0.0 MP), 12 JPEG photographs" in out
    assert "process --outputs relight-web (read auto):" in out and "peak" in out
    assert "relight OUT/relight_web (image, one light)" in out
    assert (tmp_path / "out" / "relight_web" / "info.json").is_file() and (tmp_path / "lit.png").is_file()
    again = tmp_path / "again"
    assert relight_web.main(["--capture", str(tmp_path / "capture"), "--outputs", "ptm", "--read", "whole",
                             "--out", str(again)]) == 0
    out = capsys.readouterr().out
    assert "capture:" not in out and "process --outputs ptm (read whole):" in out and "relight OUT" not in out
    notes = json.loads((again / "out" / "process.json").read_text())["notes"]
    # told of 64 GB free: a budget of 31 GB, the relighting files alone over bands all the same
    assert any("a budget of 31.0 GB" in n and "read band by band" in n for n in notes), notes
