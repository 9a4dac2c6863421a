"""Scan directory: raw/ DNGs listed in scan.json -> hdr/light_XX.exr (+ _var), load_hdr."""
import hashlib
import json
import os

import numpy as np
import pytest

import facette
from facette.camera.raw import read_raw
from facette.camera.sensor import SensorModel, bayer_mosaic_rggb
from facette.hdr import plan_adaptive
from facette.io.exr import read_exr
from facette.scan import LightMerger, MissingFrameWarning, ScanDirectory, load_hdr, merge_scan
from facette.scan.hdr import merge_light
from facette.sim.dng import write_dng

SENSOR = SensorModel()
EXPOSURES = [(200_000, 500), (20_000, 500), (2_000, 800)]  # (time_us, mA)


def _make_scan(tmp_path, n_lights=2, h=24, w=32, seed=0, exposures=EXPOSURES):
    """A scan directory as the acquisition writes it (docs/scan-format.md), with known radiance."""
    rng = np.random.default_rng(seed)
    (tmp_path / "raw").mkdir()
    truth = np.exp(rng.uniform(np.log(1e-6), np.log(7e-3), size=(n_lights, h, w, 3)))  # DN/(µs·mA)
    frames = []
    for li in range(n_lights):
        for e, (t_us, i_ma) in enumerate(exposures):
            electrons = bayer_mosaic_rggb(truth[li] * SENSOR.gain_e_per_dn * t_us * i_ma)
            mosaic = SENSOR.expose_charge(electrons, t_us * 1e-6, rng)
            name = f"raw/L{li:02d}_E{e:02d}.dng"
            write_dng(tmp_path / name, mosaic, SENSOR.black_level_dn, SENSOR.white_level_dn,
                      t_us * 1e-6, 400)
            frames.append({"file": name, "light": li, "exposure": e, "time_us": t_us,
                           "current_set_mA": i_ma, "current_meas_mA": i_ma, "start_us": 0,
                           "sync": True,
                           "sha256": hashlib.sha256((tmp_path / name).read_bytes()).hexdigest()})
    lights = [{"index": li, "direction": [0.0, 0.0, 1.0], "position_mm": None,
               "intensity": [1.0, 1.0, 1.0]} for li in range(n_lights)]
    data = {"schema": 1, "rig": {"name": "test"}, "profile": None, "pixel_pitch_mm": 0.1,
            "lights": lights,
            "exposures": [{"index": e, "time_us": t, "current_mA": i, "mode": "led"}
                          for e, (t, i) in enumerate(exposures)],
            "frames": frames, "rig_time_s": 1.0, "truth": None}
    (tmp_path / "scan.json").write_text(json.dumps(data))
    return truth


def test_merge_scan_writes_exr_and_records_it(tmp_path):
    truth = _make_scan(tmp_path)
    rec = merge_scan(tmp_path, sensor=SENSOR)
    img, names = read_exr(tmp_path / "hdr" / "light_01.exr")
    var, _ = read_exr(tmp_path / "hdr" / "light_01_var.exr")
    assert names == ("R", "G", "B") and img.shape == (24, 32, 3) and img.dtype == np.float32
    z = (img - truth[1]) / np.sqrt(var)
    assert abs(z.mean()) < 0.2 and 0.8 < z.std() < 1.2
    m = ScanDirectory(tmp_path).manifest
    assert m.hdr == rec
    assert rec.unit == "DN/(us*mA)" and rec.sensor_source == "given"
    assert [l.file for l in rec.lights] == ["hdr/light_00.exr", "hdr/light_01.exr"]
    assert m.frames and m.rig_time_s == 1.0  # the rest of the manifest kept
    steps = [json.loads(l)["step"] for l in (tmp_path / "journal.jsonl").read_text().splitlines()]
    assert steps == ["hdr_begin", "hdr_done"]


def test_a_held_light_has_its_files_values_until_a_file_changes(tmp_path):
    _make_scan(tmp_path, exposures=EXPOSURES[:2])     # the brightest pixels saturate in both frames
    sd = ScanDirectory(tmp_path)
    paths = [(tmp_path / "hdr" / f"light_{i:02d}.exr", tmp_path / "hdr" / f"light_{i:02d}_var.exr")
             for i in range(2)]
    merger = LightMerger(tmp_path, SENSOR, hold=True)
    for li in range(2):
        merger.submit(sd.manifest, li)
    finished = merger.collect(wait=True)
    merger.close()
    assert sorted(light for light, _, _ in finished) == [0, 1]
    for light, rec, held in finished:
        assert rec.index == light and held is not None
        sd.hold_light(light, held)
    assert sd.held_lights() == [0, 1]
    rad, green = sd.take_held_light(0)
    file_rad, file_var = read_exr(paths[0][0])[0], read_exr(paths[0][1])[0]
    assert np.array_equal(rad, file_rad, equal_nan=True)
    unknown = ~np.isfinite(file_var).all(axis=-1)
    assert 0 < unknown.sum() < unknown.size
    assert np.array_equal(np.isnan(green), unknown)
    assert np.array_equal(green[~unknown], file_var[..., 1][~unknown])
    assert sd.take_held_light(0) is None                # taken once: memory given back
    st = paths[1][1].stat()                             # the variance file touched since
    os.utime(paths[1][1], ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert sd.take_held_light(1) is None
    assert sd.take_held_light(7) is None and sd.held_lights() == []
    assert ScanDirectory(tmp_path).take_held_light(0) is None     # held by one object, not by the module


def test_without_hold_nothing_is_kept(tmp_path):
    _make_scan(tmp_path, n_lights=1, exposures=EXPOSURES[:2])
    merger = LightMerger(tmp_path, SENSOR)
    merger.submit(ScanDirectory(tmp_path).manifest, 0)
    [(light, rec, held)] = merger.collect(wait=True)
    merger.close()
    assert light == 0 and rec.file == "hdr/light_00.exr" and held is None


def test_per_microsecond_unit(tmp_path):
    truth = _make_scan(tmp_path, n_lights=1, exposures=[(200_000, 400), (20_000, 400), (2_000, 400)])
    rec = merge_scan(tmp_path, sensor=SENSOR, per="us")
    img, _ = read_exr(tmp_path / "hdr" / "light_00.exr")
    assert rec.unit == "DN/us" and rec.current is None
    assert np.median(img / (truth[0] * 400)) == pytest.approx(1.0, abs=0.005)
    with pytest.raises(ValueError, match="per must be"):
        merge_scan(tmp_path, sensor=SENSOR, per="s")


def test_load_hdr_merges_when_needed_and_uses_scan_sensor(tmp_path):
    truth = _make_scan(tmp_path, n_lights=3)
    data = json.loads((tmp_path / "scan.json").read_text())
    data["sensor"] = SENSOR.to_profile_dict()
    (tmp_path / "scan.json").write_text(json.dumps(data))
    images, variances, lights = load_hdr(tmp_path)
    assert images.shape == variances.shape == (3, 24, 32, 3)
    assert [l.index for l in lights] == [0, 1, 2]
    assert np.median(np.abs(images - truth) / truth) < 0.01
    assert ScanDirectory(tmp_path).manifest.hdr.sensor_source == "scan.json sensor"
    with pytest.raises(FileNotFoundError, match="merge_scan"):
        (tmp_path / "hdr" / "light_02.exr").unlink()
        load_hdr(tmp_path, merge_missing=False)


def test_missing_frame_is_skipped_with_warning_and_recorded(tmp_path):
    truth = _make_scan(tmp_path)
    (tmp_path / "raw" / "L00_E00.dng").unlink()
    with pytest.warns(MissingFrameWarning, match="light 0"):
        rec = merge_scan(tmp_path, sensor=SENSOR)
    assert rec.lights[0].missing[0]["exposure"] == 0
    assert rec.lights[1].missing == ()
    img, _ = read_exr(tmp_path / "hdr" / "light_00.exr")
    assert np.median(np.abs(img - truth[0]) / truth[0]) < 0.03  # still a valid, noisier merge


def test_light_without_frames_and_changed_file_are_errors(tmp_path):
    _make_scan(tmp_path)
    for e in range(len(EXPOSURES)):
        (tmp_path / "raw" / f"L01_E{e:02d}.dng").unlink()
    with pytest.raises(FileNotFoundError, match="light 1"), pytest.warns(MissingFrameWarning):
        merge_scan(tmp_path, sensor=SENSOR)
    p = tmp_path / "raw" / "L00_E01.dng"
    p.write_bytes(p.read_bytes()[:-4] + b"\0\0\0\1")
    with pytest.raises(ValueError, match="sha256"):
        merge_scan(tmp_path, sensor=SENSOR, lights=[0])


def test_not_a_scan_directory(tmp_path):
    with pytest.raises(FileNotFoundError, match="scan.json"):
        merge_scan(tmp_path)


def test_unsynced_frame_skipped_and_mismatched_sizes_named(tmp_path):
    _make_scan(tmp_path)
    data = json.loads((tmp_path / "scan.json").read_text())
    data["frames"][1]["sync"] = False
    (tmp_path / "scan.json").write_text(json.dumps(data))
    with pytest.warns(MissingFrameWarning, match="no flash sync"):
        rec = merge_scan(tmp_path, sensor=SENSOR, lights=[0])
    assert rec.lights[0].missing == ({"exposure": 1, "file": "raw/L00_E01.dng", "reason": "no flash sync"},)
    # A frame from another camera size in light 1.
    big = SENSOR.expose(np.zeros((30, 40, 3)), 0.01, 0)
    name = data["frames"][4]["file"]
    write_dng(tmp_path / name, big, SENSOR.black_level_dn, SENSOR.white_level_dn, 0.02, 400)
    with pytest.raises(ValueError, match=r"light 1 .*different sizes.*L01_E00"):
        merge_scan(tmp_path, sensor=SENSOR, lights=[1], verify_sha256=False)


# -- end to end on the simulated rig (posix device + rig simulator): meter, plan, scan, merge.
# The merged HDR must equal the renderer's radiance (known truth) within the variance it
# reports, through the real device, DNG files, decode and scan.json.
LIGHTS = [0, 3, 7]


def test_meter_plan_scan_merge_matches_truth(tmp_path):
    with facette.connect("sim", raw_shape=(48, 64), seed=3) as rig:
        sensor = rig.sim.sensor
        truth = rig.sim.radiance[LIGHTS] / sensor.gain_e_per_dn  # DN per µs·mA
        # 1. Metering: one LED-defined frame per light.
        meter = (100_000, 500)
        m = rig.scan(tmp_path / "meter", exposures=[meter], lights=LIGHTS, mode="led",
                     progress=False)
        meter_dir = getattr(m, "path", tmp_path / "meter")
        frames = sorted(read_scan_frames(meter_dir), key=lambda f: f.light)
        meters = [read_raw(meter_dir / f.file) for f in frames]
        # 2. Plan: one exposure list for every light, as the device runs it.
        plan = plan_adaptive(meters, [meter] * len(LIGHTS), sensor, target_snr_db=35.0,
                             shared=True, mode="led")
        assert all(p["target_met"] for p in plan.predicted)
        # 3. Scan with the plan, merge, compare with the renderer's radiance.
        scan = rig.scan(tmp_path / "scan", lights=LIGHTS, progress=False, **plan.scan_kwargs())
    scan_dir = getattr(scan, "path", tmp_path / "scan")
    rec = merge_scan(scan_dir, sensor=sensor)
    assert [l.index for l in rec.lights] == [0, 1, 2]
    images, variances, lights = load_hdr(scan_dir)
    assert images.shape == truth.shape
    sel = truth > 0.05 * truth.max()
    z = (images - truth)[sel] / np.sqrt(variances[sel])
    assert abs(np.median(images[sel] / truth[sel]) - 1) < 0.01
    assert abs(z.mean()) < 0.2 and 0.8 < z.std() < 1.25


def read_scan_frames(scan_dir):
    return list(ScanDirectory(scan_dir).manifest.frames)


def _hdr_steps(folder):
    lines = (folder / "journal.jsonl").read_text().splitlines()
    return [json.loads(l)["lights"] for l in lines if json.loads(l)["step"] == "hdr_begin"]


def test_merge_scan_redoes_only_what_changed(tmp_path):
    truth = _make_scan(tmp_path, n_lights=3)
    rec = merge_scan(tmp_path, sensor=SENSOR)
    assert [i["file"] for i in rec.lights[1].inputs] == [f"raw/L01_E{e:02d}.dng" for e in range(3)]
    before = (tmp_path / "hdr" / "light_00.exr").stat().st_mtime_ns
    assert merge_scan(tmp_path, sensor=SENSOR) == rec          # up to date: nothing merged
    assert _hdr_steps(tmp_path) == [[0, 1, 2]]
    # Light 1's exposure 2 is re-shot (new file, new sha256 in scan.json): only light 1 again.
    data = json.loads((tmp_path / "scan.json").read_text())
    rng = np.random.default_rng(9)
    t_us, i_ma = EXPOSURES[2]
    mosaic = SENSOR.expose_charge(bayer_mosaic_rggb(truth[1] * SENSOR.gain_e_per_dn * t_us * i_ma),
                                  t_us * 1e-6, rng)
    write_dng(tmp_path / "raw" / "L01_E02.dng", mosaic, SENSOR.black_level_dn,
              SENSOR.white_level_dn, t_us * 1e-6, 400)
    fr = next(f for f in data["frames"] if f["file"] == "raw/L01_E02.dng")
    fr["sha256"] = hashlib.sha256((tmp_path / fr["file"]).read_bytes()).hexdigest()
    (tmp_path / "scan.json").write_text(json.dumps({**data}))
    rec2 = merge_scan(tmp_path, sensor=SENSOR)
    assert _hdr_steps(tmp_path)[-1] == [1]
    assert rec2.lights[1].inputs[2]["sha256"] == fr["sha256"]
    assert (tmp_path / "hdr" / "light_00.exr").stat().st_mtime_ns == before
    # Another sensor model is another basis: everything again; a file edited behind the
    # record's back is caught by its sha256.
    merge_scan(tmp_path, sensor=SensorModel(gain_e_per_dn=2.0))
    assert _hdr_steps(tmp_path)[-1] == [0, 1, 2]
    with open(tmp_path / "raw" / "L02_E00.dng", "ab") as fh:
        fh.write(b"\0")
    with pytest.raises(ValueError, match="L02_E00.dng does not match the sha256"):
        merge_scan(tmp_path, sensor=SensorModel(gain_e_per_dn=2.0))


def test_the_scan_package_keeps_no_state_in_module_globals():
    """A result is returned and passed on (the held lights travel with the ScanDirectory), never
    parked in a module-level container for someone else to pick up: no module of facette.scan
    binds a dict, list or set at module level (besides __all__) or declares a global."""
    import ast
    import pathlib

    import facette.scan

    mutable = (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp, ast.SetComp)
    found = []
    for path in sorted(pathlib.Path(facette.scan.__file__).parent.glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in tree.body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names = [t.id for t in targets if isinstance(t, ast.Name)]
                call = isinstance(node.value, ast.Call) and getattr(node.value.func, "id", "") in (
                    "dict", "list", "set", "defaultdict", "OrderedDict")
                if (isinstance(node.value, mutable) or call) and names != ["__all__"]:
                    found.append(f"{path.name}: {names}")
        found += [f"{path.name}: global {n.names}" for n in ast.walk(tree) if isinstance(n, ast.Global)]
    assert found == []
