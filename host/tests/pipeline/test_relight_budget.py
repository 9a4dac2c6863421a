"""pipeline._relight_budget: the relighting model of a capture whose whole reading would exceed
MODEL_WHOLE_BYTES is read band by band in at most MODEL_BANDS_BYTES, whatever the free memory;
smaller captures and runs that cannot go over bands are left to the default budget."""
import numpy as np

from facette.pipeline import ProcessOptions, _budget, _relight_budget, process, stages_needed
from facette.pipeline._relight import light_from_angles
from test_process_memory import WHOLE, _never_whole, diligent  # noqa: F401

LARGE = 10 ** 6         # bytes a pixel and light: the 12 photographs of 36 x 44 px as if they needed ~19 GB whole


def _budget_of(source, outputs, free, **options):
    return _relight_budget.model_budget(source, ProcessOptions(**options), outputs, free=free)


def test_a_large_model_goes_over_bands_in_at_most_3_gb_whatever_the_free_memory(diligent, monkeypatch):
    monkeypatch.setattr(_budget, "WHOLE_BYTES_PER_PIXEL_LIGHT", LARGE)
    o, notes = _budget_of(diligent, ["relight"], 64e9)
    assert o.memory_bytes == 3 * 10 ** 9 and o.method == ProcessOptions().method
    assert len(notes) == 1 and "read band by band in 3.0 GB (its maps on disk)" in notes[0]
    assert "a budget of 31.0 GB" in notes[0]
    o, _ = _budget_of(diligent, ["normals", "relight", "report"], 3e9)
    assert o.memory_bytes == 10 ** 9                  # the default budget's, when it is smaller
    # the relighting files alone keep their own budget (no photometric stereo)
    o, notes = _relight_budget.relighting_budget(diligent, ProcessOptions(), stages_needed(["rti"]), ["rti"], 64e9)
    assert o.memory_bytes == 4 * 10 ** 9 and "no photometric stereo" in notes[0]


def test_what_the_model_budget_leaves_to_the_default_budget(diligent, tmp_path, monkeypatch):
    assert _budget_of(diligent, ["relight"], 64e9) is None                     # fits: ~0.5 GB whole
    monkeypatch.setattr(_budget, "WHOLE_BYTES_PER_PIXEL_LIGHT", LARGE)
    assert _budget_of(diligent, ["normals", "height"], 64e9) is None          # no model asked for
    assert _budget_of(diligent, ["relight"], 64e9, memory="8GB") is None      # --memory as given
    assert _budget_of(diligent, ["relight"], 64e9, method="rpca_wu2010") is None   # needs every pixel at once
    assert _budget_of(diligent, ["relight"], 64e9, interreflections=True) is None
    assert _budget_of(tmp_path / "nothing.png", ["relight"], 64e9) is None     # not a capture's folder


def test_the_model_over_bands_on_a_large_machine(diligent, tmp_path, monkeypatch):
    whole = process(diligent, outputs=["relight"], method="rank_trimmed", **WHOLE)
    monkeypatch.setattr(_budget, "WHOLE_BYTES_PER_PIXEL_LIGHT", LARGE)
    monkeypatch.setattr(_budget, "free_memory", lambda: 64 * 10 ** 9)
    _never_whole(monkeypatch)
    banded = process(diligent, outputs=["relight"], out_dir=tmp_path / "out", method="rank_trimmed")
    assert any("read band by band in 3.0 GB" in n for n in banded.notes)
    a, b = whole.relight_model, banded.relight_model
    assert isinstance(b.rho, np.memmap) or isinstance(b.rho.base, np.memmap)     # its maps on disk
    np.testing.assert_array_equal(a.mask, b.mask)
    for az, el in ((0.0, 15.0), (135.0, 45.0), (250.0, 70.0)):
        light = light_from_angles(az, el)
        assert np.abs(a.display(light) - b.display(light)).max() < 0.01
    assert (tmp_path / "out" / "relight_model.npz").is_file()
