"""Scan directory: journal, manifest, recovery of an interrupted move, run grouping."""
import dataclasses
import json

import pytest

from facette.scan import Manifest, ScanDirectory, ScanDirectoryError, default_plan, frame_name, sha256_file
from facette.scan.directory import SCHEMA
from facette.scan._plan import device_run_groups
from facette.scan._resume import recover
from facette.scan.acquire import THESIS_BRACKET_US


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
    recover(ScanDirectory(sd.path))
    sd2 = ScanDirectory(sd.path)
    assert not src.exists() and (sd.path / frame_name(0, 0)).read_bytes() == b"frame data"
    assert sd2.manifest.frames[0].sha256 == sha256_file(sd.path / frame_name(0, 0))
    assert sd2.read_journal()[-1]["step"] == "recovered"


def test_missing_frames_are_grouped_into_lights_by_exposures_runs():
    pending = {(3, 1), (3, 2)} | {(l, e) for l in range(4, 12) for e in range(3)}
    assert device_run_groups(pending) == [([3], [1, 2]), (list(range(4, 12)), [0, 1, 2])]
    assert device_run_groups({(0, 0), (2, 0)}) == [([0, 2], [0])]


def test_default_plan_is_the_thesis_bracket_and_checks_currents():
    plan = default_plan(12)
    assert [t for t, _ in plan.exposures] == list(THESIS_BRACKET_US)
    assert plan.lights == list(range(12)) and plan.light_current_mA == [500] * 12
    with pytest.raises(ValueError, match="2 light currents for 3 lights"):
        default_plan(3, light_current_mA=[1, 2])


# scan.json as facette wrote it before the Manifest (schema 1: a scan of 2 lights x 1 exposure
# on the simulated rig, trimmed to one HDR light record); "sensor", "radiometric_scale",
# "bracketing", "runs", "hdr" and "faults_seen" came last, once known.
SCHEMA_1 = """{
 "schema": 1,
 "rig": {"fw_version": "1.0", "protocol_version": 1, "definition_hash": "0x78a5debe",
         "serial_number": 1509949441, "uptime_s": 312, "boot_count": 1, "reset_cause": "POWER_ON",
         "max_leds": 16, "ring_len": 16, "url": "/tmp/facette-rig-7s3tnj_y/device/tty"},
 "profile": {"id": "sim-default-2026-12-01T235946Z",
             "sha256": "be1a7d6d4f74ee6e66ee6fbeca5bf43952965b1fa9d0ccbb06427cef5ae53fda",
             "path": "/work/calibration/profiles/sim-default/profile.json", "image_size_px": [256, 192]},
 "pixel_pitch_mm": 0.46877642275026465,
 "lights": [
  {"index": 0, "channel": 0, "direction": [0.5006081850907894, 0.0027120382162629407, 0.8656697348693783],
   "position_mm": null, "intensity": [0.8628655239167928, 0.8539943220005266, 0.8715431161716842]},
  {"index": 1, "channel": 1, "direction": [0.22515743334383226, 0.1315362991259799, 0.965402678793807],
   "position_mm": null, "intensity": [0.9096298495986285, 0.8985028608386405, 0.9053103306071564]}],
 "exposures": [{"index": 0, "time_us": 200000, "current_mA": 500, "mode": "camera"}],
 "frames": [
  {"file": "raw/L01_E00.dng", "light": 1, "exposure": 0, "time_us": 200000, "current_set_mA": 500,
   "current_meas_mA": 500, "start_us": 920000, "sync": true, "retry": false, "run": 0, "ring": 1,
   "sha256": "03c345c7387bedea1b3194a1a9bb76ab57aa72ecc651a2a764060411ac5cac62"},
  {"file": "raw/L00_E00.dng", "light": 0, "exposure": 0, "time_us": 200000, "current_set_mA": 500,
   "current_meas_mA": 500, "start_us": 100000, "sync": true, "retry": false, "run": 0, "ring": 0,
   "sha256": "d9dc0765b97e71d1f21d501087f1d897334f24285e08ecdb0474c23c2066be8a"}],
 "rig_time_s": 1.44,
 "truth": "truth.npz",
 "plan": {"lights": [0, 1], "exposures": [[200000, 0]], "light_current_mA": [500, 500], "mode": "camera",
          "retries": 1, "timing": {}},
 "complete": true,
 "created": "2026-12-03T09:25:17.705+00:00",
 "sensor": {"gain_e_per_dn": 1.4990049393793343, "read_noise_e": 3.9877262586635775,
            "dark_current_e_per_s": 0.49381804173130267, "black_level_dn": 512, "white_level_dn": 16383},
 "radiometric_scale": [4.174220486049001e-05, 4.169443949736705e-05, 4.1611257596072455e-05],
 "bracketing": {"name": "explicit"},
 "runs": 1,
 "hdr": {"method": "inverse_variance", "unit": "DN/(us*mA)", "current": "measured", "resolution": "half-size",
         "sensor_source": "scan.json sensor", "merge_time_s": 0.02,
         "lights": [{"index": 0, "file": "hdr/light_00.exr", "var_file": "hdr/light_00_var.exr",
                     "frames": ["raw/L00_E00.dng"], "missing": []}]},
 "faults_seen": [{"faults": ["CAL_INVALID"], "step": "clear_faults", "t": "2026-12-03T09:25:17.710+00:00"}]
}"""

# the oldest form the code reads: a scan.json made by a tool (as bench/recon wrote it), with
# no plan, no completion flag and no creation time
SCHEMA_1_BY_A_TOOL = {"schema": 1, "rig": {"id": "bench"}, "profile": None, "pixel_pitch_mm": 0.1,
                      "lights": [{"index": 0, "direction": [0, 0, 1], "position_mm": None,
                                  "intensity": [1, 1, 1]}],
                      "exposures": [], "frames": [{"file": "raw/L00_E00.dng", "light": 0, "exposure": 0}],
                      "rig_time_s": 0.0, "truth": "truth.npz"}


def test_a_schema_1_scan_json_is_read_into_the_manifest_and_written_back_as_schema_2(tmp_path):
    (tmp_path / "scan.json").write_text(SCHEMA_1)
    m = ScanDirectory(tmp_path).manifest
    assert isinstance(m, Manifest)
    assert m.rig["serial_number"] == 1509949441 and m.profile["image_size_px"] == [256, 192]
    assert m.pixel_pitch_mm == pytest.approx(0.46877642275026465)
    assert [l.channel for l in m.lights] == [0, 1] and m.n_planned == 2
    assert [f.file for f in m.frames] == ["raw/L01_E00.dng", "raw/L00_E00.dng"]   # as read
    assert m.frame_lights() == [0, 1] and m.light_frames(0)[0].ring == 0
    assert m.rig_time_s == 1.44 and m.runs == 1 and m.complete and m.truth == "truth.npz"
    assert m.plan["exposures"] == [[200000, 0]] and m.bracketing == {"name": "explicit"}
    assert m.sensor["black_level_dn"] == 512 and m.radiometric_scale[0] == pytest.approx(4.174220486049001e-05)
    assert m.hdr.lights[0].file == "hdr/light_00.exr" and m.faults_seen[0]["step"] == "clear_faults"
    assert m.created == "2026-12-03T09:25:17.705+00:00" and m.extra == {}
    sd = ScanDirectory(tmp_path)
    sd.save()
    written = json.loads((tmp_path / "scan.json").read_text())
    assert written["schema"] == SCHEMA == 2
    old = json.loads(SCHEMA_1)
    assert {k: v for k, v in written.items() if k != "schema"} == {k: v for k, v in old.items() if k != "schema"}
    assert list(written) == ["schema", "rig", "profile", "pixel_pitch_mm", "lights", "exposures", "plan",
                             "created", "bracketing", "sensor", "radiometric_scale", "frames", "runs",
                             "rig_time_s", "hdr", "complete", "truth", "faults_seen"]


def test_a_tools_scan_json_gets_every_key_with_its_default(tmp_path):
    (tmp_path / "scan.json").write_text(json.dumps({**SCHEMA_1_BY_A_TOOL, "by_the_tool": [1, 2]}))
    sd = ScanDirectory(tmp_path)
    m = sd.manifest
    assert m.plan is None and m.created is None and not m.complete and m.runs == 0 and m.hdr is None
    assert m.sensor is None and m.bracketing is None and m.faults_seen == () and m.n_planned == 0
    sd.save()
    written = json.loads((tmp_path / "scan.json").read_text())
    assert written["schema"] == 2 and written["complete"] is False and written["hdr"] is None
    assert written["by_the_tool"] == [1, 2]          # a key this version does not know is kept


def test_the_manifest_is_set_through_its_methods_only(tmp_path):
    sd = _new(tmp_path)
    m = sd.manifest
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.complete = True
    with pytest.raises(AttributeError):
        m.frames.append({"file": "x"})               # a tuple: frames go through add_frame
    m.add_frame({"file": frame_name(0, 1), "light": 0, "exposure": 1})
    m.add_frame({"file": frame_name(0, 0), "light": 0, "exposure": 0})
    m.add_frame({"file": frame_name(0, 0), "light": 0, "exposure": 0, "retry": True})   # taken again
    assert [(f.exposure, f.retry) for f in m.frames] == [(0, True), (1, None)]
    assert m.start_run() == 0 and m.start_run() == 1 and m.runs == 2
    m.add_rig_time(1.5)
    m.set_bracketing({"name": "adaptive", "meter_rig_time_s": 2.25})   # the metering's time counts
    m.add_rig_time(0.5)
    assert m.rig_time_s == 2.75 and m.bracketing["name"] == "adaptive"
    m.finish([{"step": "no_sync"}])
    assert m.complete and m.faults_seen == ({"step": "no_sync"},)
    m.drop_frames([frame_name(0, 1)])
    assert not m.complete and [f.exposure for f in m.frames] == [0]
    sd.save()
    again = ScanDirectory(sd.path).manifest
    assert again.to_dict() == m.to_dict()


@pytest.mark.parametrize("content, words", [
    ({"schema": 3, "lights": [], "frames": []}, "schema 3; this facette reads schemas 1..2"),
    ({"schema": 2, "lights": []}, "no 'frames' and 'lights' lists"),
    ([], "no 'frames' and 'lights' lists"),
])
def test_a_scan_json_this_version_cannot_read_is_named(tmp_path, content, words):
    (tmp_path / "scan.json").write_text(json.dumps(content))
    with pytest.raises(ScanDirectoryError) as exc:
        ScanDirectory(tmp_path)
    assert str(tmp_path / "scan.json") in str(exc.value) and words in str(exc.value)
