"""pipeline._budget: a memory budget by default, from the free memory, said in a note; a capture
that does not fit whole is read band by band in it."""
import numpy as np

from facette.bench._sim_scan import write_scan
from facette.pipeline import ProcessOptions, _budget, process
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _scan(tmp_path):
    sc = sphere_on_plane(48, 64)
    return write_scan(tmp_path / "scan", sc, render(sc, thesis_light_directions(), "matte", noise=0.002))


def test_the_budget_is_the_free_memory_less_a_margin():
    assert _budget.default_budget(10e9) == int(0.5 * 10e9 - 1e9)
    assert _budget.default_budget(0.5e9) == 10 ** 9            # never below 1 GB
    assert _budget.free_memory() > 0


def test_a_capture_that_fits_is_read_whole_and_the_budget_said(tmp_path):
    scan = _scan(tmp_path)
    o, notes = _budget.with_default_budget(scan, ProcessOptions(), ["normals"], free=6e9)
    assert o.memory is None and o.method == ProcessOptions().method
    assert notes == ["memory: a budget of 2.0 GB (50% of the 6.0 GB free, less 1 GB; --memory to set it): the capture "
                     "(12 photographs of 64x48 px, ~0.5 GB whole) is read whole"]
    given = ProcessOptions(memory="2GB", method="rank_trimmed")
    assert _budget.with_default_budget(scan, given, ["normals"]) == (given, [])


def test_a_capture_too_large_is_read_in_bands_in_the_budget(tmp_path, monkeypatch):
    scan = _scan(tmp_path)
    monkeypatch.setattr(_budget, "WHOLE_BYTES_PER_PIXEL_LIGHT", 10 ** 6)      # as if 12 x 3 k pixels were 37 GB
    monkeypatch.setattr(_budget, "free_memory", lambda: 4.8e9)
    res = process(scan, outputs=["normals"])
    note = next(n for n in res.notes if n.startswith("memory: a budget of 1.4 GB"))
    assert note.endswith("read band by band in 1.4 GB")         # the default method still: li_alternating
    assert res.ps.method == "li_alternating" and any("read band by band (never held whole)" in n for n in res.notes)
    given = process(scan, outputs=["normals"], memory=str(int(1.4e9)))
    np.testing.assert_array_equal(res.normals, given.normals)
