"""bench e2e's line of where the seconds after the last frame went (bench/_e2e_after.py), from the
journal, the stage times the scan command prints and process.json's `written`."""
import datetime as _dt
import json
import math
import os

from facette.bench._e2e_after import stage_times, timeline, timeline_line

T0 = _dt.datetime(2026, 1, 1, tzinfo=_dt.timezone.utc)


def _at(s):
    return (T0 + _dt.timedelta(seconds=s)).isoformat(timespec="milliseconds")


def _scan(tmp_path, written):
    entries = [{"t": _at(0), "step": "captured"}, {"t": _at(0.5), "step": "hdr_light", "light": 0},
               {"t": _at(10), "step": "captured"}, {"t": _at(11.25), "step": "hdr_light", "light": 1}]
    (tmp_path / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in entries) + '{"t": "cut')
    results = tmp_path / "results"
    results.mkdir()
    (results / "process.json").write_text(json.dumps({"written": {k: _at(v) for k, v in written.items()}}))
    os.utime(results / "process.json", (T0.timestamp() + 40, T0.timestamp() + 40))


def test_the_events_in_seconds_after_the_last_frame_in_the_order_they_happened(tmp_path):
    _scan(tmp_path, {"report.html": 38.0, "normal.exr": 22.5, "mask.png": 23.0})
    out = "rig: ...\n  times: load 1.50 s, ps 12.25 s, after_ps 9.00 s, shadows 3.10 s\n"
    t = timeline(tmp_path, out)
    assert t["merged"] == 1.25                  # the last light's merge, after the last frame (10 s)
    assert t["stages"] == {"load": 1.5, "ps": 12.25, "after_ps": 9.0, "shadows": 3.1}
    assert [n for n, _ in t["written"]] == ["normal.exr", "mask.png", "report.html", "process.json"]
    assert [round(s, 3) for _, s in t["written"]] == [12.5, 13.0, 28.0, 30.0]
    line = timeline_line(t)
    assert "merge stored +1.25" in line and "load 1.50, shadows 3.10, ps 12.25, after_ps 9.00" in line
    assert "normal.exr +12.50" in line and line.endswith("process.json +30.00")


def test_a_run_without_times_or_record_says_so(tmp_path):
    (tmp_path / "journal.jsonl").write_text(json.dumps({"t": _at(0), "step": "captured"}) + "\n")
    t = timeline(tmp_path, "")
    assert math.isnan(t["merged"]) and t["stages"] == {} and t["written"] == []
    assert stage_times("no times here") == {}
    assert timeline_line(t).endswith("stages: -; files written: -")
