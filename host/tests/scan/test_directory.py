"""Scan directory: journal, manifest, recovery of an interrupted move, run grouping."""
import json

import pytest

from facette.scan import ScanDirectory, default_plan, frame_name, sha256_file
from facette.scan.acquire import THESIS_BRACKET_US, _groups, _recover


def _new(tmp_path):
    sd = ScanDirectory(tmp_path / "s")
    plan = default_plan(2, exposures=[1000, 500])
    sd.create({"fw_version": "1.0"}, None, 0.5, [], [], plan.to_dict())
    return sd


def test_manifest_is_written_atomically_and_frames_are_kept_sorted(tmp_path):
    sd = _new(tmp_path)
    for light, exp in [(1, 0), (0, 1), (0, 0)]:
        f = sd.path / frame_name(light, exp)
        f.write_bytes(bytes([light, exp]) * 10)
        sd.add_frame({"file": frame_name(light, exp), "light": light, "exposure": exp, "sha256": sha256_file(f)})
    m = json.loads((sd.path / "scan.json").read_text())
    assert [(f["light"], f["exposure"]) for f in m["frames"]] == [(0, 0), (0, 1), (1, 0)]
    assert not list(sd.path.glob(".*partial"))
    assert sd.verify() == []
    (sd.path / frame_name(0, 1)).write_bytes(b"tampered")
    assert sd.verify() == ["raw/L00_E01.dng: sha256 differs from scan.json"]
    assert set(sd.frames_done()) == {(0, 0), (0, 1), (1, 0)}
    (sd.path / frame_name(1, 0)).unlink()
    assert set(sd.frames_done()) == {(0, 0), (0, 1)}


def test_journal_survives_a_truncated_last_line(tmp_path):
    sd = _new(tmp_path)
    sd.journal("begin", plan={"a": 1})
    sd.journal("start", run=0)
    with open(sd.path / "journal.jsonl", "a") as fh:
        fh.write('{"step": "capt')                       # power cut mid-write
    steps = [e["step"] for e in sd.read_journal()]
    assert steps == ["begin", "start"]


def test_an_interrupted_move_is_completed_from_the_journal(tmp_path):
    sd = _new(tmp_path)
    camera = tmp_path / "camera"
    camera.mkdir()
    src = camera / "DSC_0001.dng"
    src.write_bytes(b"frame data")
    record = {"file": frame_name(0, 0), "light": 0, "exposure": 0, "time_us": 1000}
    sd.journal("capture", src=str(src), record=record)       # the host died here
    _recover(ScanDirectory(sd.path), None)
    sd2 = ScanDirectory(sd.path)
    assert not src.exists() and (sd.path / frame_name(0, 0)).read_bytes() == b"frame data"
    assert sd2.manifest["frames"][0]["sha256"] == sha256_file(sd.path / frame_name(0, 0))
    assert sd2.read_journal()[-1]["step"] == "recovered"


def test_missing_frames_are_grouped_into_lights_by_exposures_runs():
    pending = {(3, 1), (3, 2)} | {(l, e) for l in range(4, 12) for e in range(3)}
    assert _groups(pending, 12) == [([3], [1, 2]), (list(range(4, 12)), [0, 1, 2])]
    assert _groups({(0, 0), (2, 0)}, 3) == [([0, 2], [0])]


def test_default_plan_is_the_thesis_bracket_and_checks_currents():
    plan = default_plan(12)
    assert [t for t, _ in plan.exposures] == list(THESIS_BRACKET_US)
    assert plan.lights == list(range(12)) and plan.light_current_mA == [500] * 12
    with pytest.raises(ValueError, match="2 light currents for 3 lights"):
        default_plan(3, light_current_mA=[1, 2])
