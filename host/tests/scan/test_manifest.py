"""scan.json's typed records (scan/manifest.py): a scan.json facette wrote comes back byte for
byte, a tool's record keeps its unknown keys and its absent ones, the records are frozen, and a
record without the keys it needs is named."""
import dataclasses
import json

import pytest

from facette.scan import Exposure, Frame, Hdr, HdrLight, Light, Manifest, ScanDirectory, ScanDirectoryError


def _frame(light, exposure, **kw):
    return {"file": f"raw/L{light:02d}_E{exposure:02d}.dng", "light": light, "exposure": exposure,
            "time_us": 200000, "current_set_mA": 500, "current_meas_mA": 498, "start_us": 100000 * exposure,
            "sync": True, "retry": False, "run": 0, "ring": exposure, "sha256": "ab" * 32, **kw}


def _hdr_light(index):
    return {"index": index, "file": f"hdr/light_{index:02d}.exr", "var_file": f"hdr/light_{index:02d}_var.exr",
            "frames": [f"raw/L{index:02d}_E00.dng"],
            "inputs": [{"file": f"raw/L{index:02d}_E00.dng", "sha256": "ab" * 32, "size": 1234,
                        "mtime_ns": 1764754517705000000}],
            "outputs": {f"hdr/light_{index:02d}.exr": {"size": 9, "mtime_ns": 1}},
            "missing": [{"exposure": 1, "file": None, "reason": "not captured"}],
            "basis": {"method": "inverse_variance", "current": "measured", "unit": "DN/(us*mA)",
                      "sensor": {"gain_e_per_dn": 1.5}},
            "saturated_fraction": 0.0, "no_sample_fraction": 0.03125,
            "time_s": {"read": 0.012, "merge": 0.004, "write": 0.001}}


# every key of schema 2 as facette writes it (ScanDirectory.save: indent 1, a final newline)
SCHEMA_2 = {
    "schema": 2, "rig": {"fw_version": "1.0", "serial_number": 7}, "profile": None, "pixel_pitch_mm": 0.25,
    "lights": [{"index": 0, "channel": 3, "direction": [0.5, 0.0, 0.8660254037844386], "position_mm": None,
                "intensity": [1.0, 1.0, 1.0]},
               {"index": 1, "channel": 12, "direction": None, "position_mm": [10.0, 20.0, 300.0],
                "intensity": [0.9, 0.95, 1.0]}],
    "exposures": [{"index": 0, "time_us": 200000, "current_mA": 500, "mode": "camera"},
                  {"index": 1, "time_us": 20000, "current_mA": 500, "mode": "camera"}],
    "plan": {"lights": [3, 12], "exposures": [[200000, 0], [20000, 0]], "light_current_mA": [500, 500],
             "mode": "camera", "retries": 1, "timing": {}},
    "created": "2026-12-03T09:25:17.705+00:00", "bracketing": {"name": "explicit"}, "sensor": None,
    "radiometric_scale": None,
    "frames": [_frame(0, 0), _frame(0, 1), _frame(1, 0, sync=False, retry=True)],
    "runs": 1, "rig_time_s": 1.44,
    "hdr": {"method": "inverse_variance", "unit": "DN/(us*mA)", "current": "measured", "resolution": "half-size",
            "sensor": {"gain_e_per_dn": 1.5}, "sensor_source": "given", "lights": [_hdr_light(0)],
            "merge_time_s": 0.017, "created": "2026-12-03T09:25:18+00:00"},
    "complete": False, "truth": None, "faults_seen": [{"step": "no_sync", "light": 1, "exposure": 0}]}


def test_a_scan_json_facette_wrote_comes_back_byte_for_byte(tmp_path):
    text = json.dumps(SCHEMA_2, indent=1) + "\n"
    (tmp_path / "scan.json").write_text(text)
    sd = ScanDirectory(tmp_path)
    m = sd.manifest
    assert all(isinstance(x, Light) for x in m.lights) and all(isinstance(x, Exposure) for x in m.exposures)
    assert all(isinstance(f, Frame) for f in m.frames) and isinstance(m.hdr, Hdr)
    assert isinstance(m.hdr.lights[0], HdrLight)
    sd.save()
    assert (tmp_path / "scan.json").read_text() == text
    assert m.to_dict() == SCHEMA_2


def test_records_are_read_through_attributes(tmp_path):
    m = Manifest.from_dict(SCHEMA_2)
    light = m.lights[1]
    assert light.channel == 12 and light.direction is None and light.position_mm == (10.0, 20.0, 300.0)
    assert m.exposures[1].time_us == 20000 and m.exposures[1].mode == "camera"
    f = m.frames[2]
    assert f.key == (1, 0) and f.sync is False and not f.synced and f.retry and f.sha256 == "ab" * 32
    assert m.light_frames(0) == [m.frames[0], m.frames[1]] and m.frame_lights() == [0, 1]
    rec = m.hdr_lights()[0]
    assert rec.file == "hdr/light_00.exr" and rec.inputs[0]["size"] == 1234
    assert rec.missing == ({"exposure": 1, "file": None, "reason": "not captured"},)
    assert rec.seconds() == pytest.approx(0.017) and m.hdr.sensor_source == "given"


def test_a_tools_records_keep_their_unknown_keys_and_their_absent_ones():
    """A tool's frame without sync, retry or sha256 (and with a key of its own) is written back
    as it was: nothing invented, nothing lost; a frame without a sync record counts as synced."""
    tool = {"file": "raw/L00_E00.dng", "light": 0, "exposure": 0, "time_us": 1000, "by_the_tool": 1}
    f = Frame.from_json(tool)
    assert f.sync is None and f.synced and f.sha256 is None and f.extra == {"by_the_tool": 1}
    assert f.to_json() == tool and list(f.to_json()) == list(tool)
    hashed = f.replace(sha256="cd" * 32)
    assert hashed.to_json() == {**tool, "sha256": "cd" * 32} and f.to_json() == tool
    old_hdr = {"method": "inverse_variance", "lights": [{"index": 0, "file": "hdr/light_00.exr"}]}
    hdr = Hdr.from_json(old_hdr)
    assert hdr.to_json() == old_hdr and hdr.lights[0].inputs is None and hdr.lights[0].seconds() == 0


def test_records_are_frozen():
    m = Manifest.from_dict(SCHEMA_2)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.frames[0].sha256 = "00"
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.hdr.lights[0].index = 3
    with pytest.raises(TypeError):
        m.lights[0].direction[0] = 1.0      # a tuple


@pytest.mark.parametrize("where, bad, words", [
    ("frames", {"light": 0, "exposure": 0}, "a frame record lacks ['file']"),
    ("lights", {"channel": 0}, "a light record lacks ['index']"),
    ("frames", "raw/L00_E00.dng", "a frame record is str, not an object"),
])
def test_a_record_without_what_it_needs_is_named(tmp_path, where, bad, words):
    data = json.loads(json.dumps(SCHEMA_2))
    data[where][0] = bad
    (tmp_path / "scan.json").write_text(json.dumps(data))
    with pytest.raises(ScanDirectoryError) as exc:
        ScanDirectory(tmp_path)
    assert str(tmp_path / "scan.json") in str(exc.value) and words in str(exc.value)
