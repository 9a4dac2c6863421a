"""Scans at any size on the simulated rig: a rig rendered in bands takes the frames of one
rendered whole, and a resumed scan merges during acquisition only the lights it lacks."""
import json

import numpy as np
import pytest

from facette.camera.raw import read_raw_mosaic
from facette.scan import ScanDirectory

SHORT = [(200_000, 0), (20_000, 0)]


def _mosaics(scan):
    return [read_raw_mosaic(scan.path / f.file)[0] for f in scan.manifest.frames]


def test_a_rig_rendered_in_bands_takes_the_frames_of_one_rendered_whole(sim_rig_factory, tmp_path):
    whole = sim_rig_factory()
    banded = sim_rig_factory(render_rows=10)          # 48 rows of half-size pixels: 5 bands
    assert not whole.sim.banded and banded.sim.banded
    a = whole.scan(tmp_path / "whole", lights=[1, 7], exposures=SHORT, progress=False)
    b = banded.scan(tmp_path / "banded", lights=[1, 7], exposures=SHORT, progress=False)
    assert len(a.manifest.frames) == len(b.manifest.frames) == 4
    for x, y in zip(_mosaics(a), _mosaics(b)):
        assert np.array_equal(x, y)
    with np.load(a.path / "truth.npz") as ta, np.load(b.path / "truth.npz") as tb:
        assert sorted(ta.files) == sorted(tb.files)
        for k in ta.files:
            np.testing.assert_array_equal(ta[k], tb[k], err_msg=k)   # NaN positions: far LEDs


def test_a_resumed_scan_merges_only_the_lights_it_lacks(sim_rig_factory, tmp_path):
    rig = sim_rig_factory(render_rows=16)

    def die(record):
        if record.light == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rig.scan(tmp_path / "s", lights=[0, 1, 2, 3, 4], exposures=SHORT, progress=False,
                 merge_hdr=True, hold_hdr=False, on_frame=die)
    first = ScanDirectory(tmp_path / "s").manifest.hdr_lights()
    assert sorted(first) == [0, 1, 2]                  # merged and recorded before the stop
    stamps = {i: (tmp_path / "s" / r.file).stat().st_mtime_ns for i, r in first.items()}
    scan = rig.scan(tmp_path / "s", lights=[0, 1, 2, 3, 4], exposures=SHORT, progress=False,
                    merge_hdr=True, hold_hdr=False)
    assert sorted(scan.manifest.hdr_lights()) == [0, 1, 2, 3, 4]
    # the lights merged before the stop were not merged again: their files are the same files
    assert all((tmp_path / "s" / first[i].file).stat().st_mtime_ns == t for i, t in stamps.items())
    journal = [json.loads(line) for line in (tmp_path / "s" / "journal.jsonl").read_text().splitlines()]
    merged = [e["light"] for e in journal if e.get("step") == "hdr_light"]
    assert sorted(merged) == [0, 1, 2, 3, 4]           # each light merged once over both runs
