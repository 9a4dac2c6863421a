"""The one-button scan on the simulated rig: adaptive by default, merged during acquisition."""
import json
import subprocess
import sys

import numpy as np
import pytest

from facette.io.exr import read_exr
from facette.scan import ScanAborted, ScanDirectory
from facette.sim.device_process import REPO_ROOT

FACETTE = [sys.executable, "-m", "facette.cli.main"]
PROFILE = REPO_ROOT / "calibration" / "profiles" / "sim-default"
SHORT = [(200_000, 0), (20_000, 0), (2_000, 0)]

SMALL = ["--raw-size", "128x96"]   # the default 1024x768 costs seconds per scan here


def _steps(scan_dir, step):
    lines = (scan_dir / "journal.jsonl").read_text().splitlines()
    return [json.loads(l) for l in lines if json.loads(l)["step"] == step]


def test_facette_scan_is_adaptive_by_default_and_the_thesis_bracket_on_request(tmp_path):
    run = subprocess.run(FACETTE + ["scan", "--sim", "--press-button", "--quiet", "--no-process", *SMALL,
                                    str(tmp_path / "a")], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    m = json.loads((tmp_path / "a" / "scan.json").read_text())
    b = m["bracketing"]
    assert b["name"] == "adaptive" and b["meter_dirs"] == ["meter"]
    assert all(p["target_met"] and p["snr_db_min"] >= 39.9 for p in b["predicted"])
    assert len(m["exposures"]) < 7 and len(m["frames"]) == 12 * len(m["exposures"])
    # the metering is part of the rig time; the thesis bracket alone takes 12 x 28.3 s
    assert b["meter_rig_time_s"] > 0 and m["rig_time_s"] < 12 * 28.3
    assert m["rig_time_s"] >= b["meter_rig_time_s"] + 12 * sum(e["time_us"] for e in m["exposures"]) * 1e-6
    # no highlight of the object clipped: every object pixel has a finite variance
    truth = np.load(tmp_path / "a" / "truth.npz")
    subprocess.run(FACETTE + ["process", str(tmp_path / "a"), "-o", str(tmp_path / "a" / "r"),
                              "--outputs", "normals"], check=True, capture_output=True, timeout=300)
    for li in range(12):
        var, _ = read_exr(tmp_path / "a" / "hdr" / f"light_{li:02d}_var.exr")
        assert np.isfinite(var[truth["mask"]]).all()
    fixed = subprocess.run(FACETTE + ["scan", "--sim", "--press-button", "--quiet", "--no-process", *SMALL,
                                      "--exposures", "thesis", "--lights", "0", str(tmp_path / "t")],
                           capture_output=True, text=True, timeout=300)
    assert fixed.returncode == 0, fixed.stderr
    t = json.loads((tmp_path / "t" / "scan.json").read_text())
    assert t["bracketing"]["name"] == "thesis2016" and len(t["exposures"]) == 7
    assert not (tmp_path / "t" / "meter").exists()


def test_lights_are_merged_during_acquisition_and_a_resume_merges_only_the_rest(sim_rig_factory, tmp_path):
    rig = sim_rig_factory()
    taken = []

    def abort_in_light_5(record):
        taken.append(record)
        if record.light == 5 and record.exposure == 0:
            rig.abort()

    with pytest.raises(ScanAborted):
        rig.scan(tmp_path / "s", exposures=SHORT, progress=False, merge_hdr=True,
                 on_frame=abort_in_light_5)
    sd = ScanDirectory(tmp_path / "s")
    merged = sorted(r.index for r in sd.manifest.hdr.lights)
    assert merged == [0, 1, 2, 3, 4]                  # every complete light, nothing else
    rec3 = next(r for r in sd.manifest.hdr.lights if r.index == 3)
    sha = {f.file: f.sha256 for f in sd.manifest.frames}
    assert [(i["file"], i["sha256"]) for i in rec3.inputs] == \
        [(f, sha[f]) for f in (f"raw/L03_E{e:02d}.dng" for e in range(3))]
    first = (tmp_path / "s" / "hdr" / "light_00.exr").stat().st_mtime_ns
    scan = rig.scan(tmp_path / "s", exposures=SHORT, progress=False, merge_hdr=True, hold_hdr=True)
    sd = ScanDirectory(tmp_path / "s")
    assert sorted(r.index for r in sd.manifest.hdr.lights) == list(range(12))
    assert sorted(e["light"] for e in _steps(tmp_path / "s", "hdr_light")) == list(range(12))
    assert (tmp_path / "s" / "hdr" / "light_00.exr").stat().st_mtime_ns == first
    # process finds the HDR up to date: no merge of its own; the lights this run merged come
    # from memory (held by the ScanDirectory the scan returned), with the values a process
    # reading every file finds
    from facette.pipeline import process

    assert scan.held_lights() == list(range(5, 12)) and sd.held_lights() == []
    held = process(scan, outputs=["normals"])
    assert _steps(tmp_path / "s", "hdr_begin") == []
    assert scan.held_lights() == [] and scan.take_held_light(11) is None    # taken: memory given back
    files = process(tmp_path / "s", outputs=["normals"])
    assert np.array_equal(held.inputs.images, files.inputs.images, equal_nan=True)
    assert np.array_equal(held.inputs.usable, files.inputs.usable)
    assert np.array_equal(held.normals, files.normals)
