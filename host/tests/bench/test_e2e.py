"""bench e2e's "maps ready": when the last of the maps was written, beside the last result file."""
import math
import os

from facette.bench.e2e import MAPS, _maps_written, _results_written


def test_maps_ready_is_the_last_map_written_and_ready_the_last_file(tmp_path):
    for k, name in enumerate(MAPS + ("report.html", "process.json")):
        (tmp_path / name).write_bytes(b"x")
        os.utime(tmp_path / name, (1000.0 + k, 1000.0 + k))
    os.utime(tmp_path / "normal.exr", (1010.0, 1010.0))      # rewritten after the others
    assert _maps_written(tmp_path) == 1010.0
    assert _results_written(tmp_path) == 1010.0
    os.utime(tmp_path / "process.json", (1020.0, 1020.0))
    assert _results_written(tmp_path) == 1020.0 and _maps_written(tmp_path) == 1010.0
    (tmp_path / "height.exr").unlink()                        # --outputs without heights: the others
    assert _maps_written(tmp_path) == 1010.0


def test_no_map_written_gives_nan(tmp_path):
    (tmp_path / "relight.rti").write_bytes(b"x")
    assert math.isnan(_maps_written(tmp_path))


def test_cpu_after_last_frame_from_the_journal(tmp_path):
    import json

    from facette.bench.e2e import cpu_after_last_frame

    entries = [{"t": "2026-01-01T00:00:00+00:00", "step": "captured", "cpu_s": 3.0},
               {"t": "2026-01-01T00:00:01+00:00", "step": "captured", "cpu_s": 5.5},
               {"t": "2026-01-01T00:00:02+00:00", "step": "hdr_light", "light": 0}]
    (tmp_path / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in entries))
    assert cpu_after_last_frame(tmp_path, 20.0) == 14.5
    older = [{k: v for k, v in e.items() if k != "cpu_s"} for e in entries]
    (tmp_path / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in older))
    assert math.isnan(cpu_after_last_frame(tmp_path, 20.0))      # an older journal: no figure
