"""The inter-reflection decision on binned images (`pipeline._interreflections.decide_lobe_free`, an
image over DECIDE_SIDE a side): its li_alternating runs BINNED_ROUNDS rounds there (its model is not
reused, only its diffuse albedo read), and where it leaves the images as they are the normals are those
of the decision with every round."""
import numpy as np

from facette.pipeline import _interreflections, process

from satin_scene import satin_sphere_on_a_plane


def test_a_binned_decision_runs_its_rounds_and_keeps_the_normals(tmp_path, monkeypatch):
    folder = satin_sphere_on_a_plane(tmp_path / "objPNG")
    monkeypatch.setattr(_interreflections, "DECIDE_SIDE", 24)       # 40 x 48 px: binned 2 x 2
    rounds = []
    li = _interreflections.ps_li_alternating
    monkeypatch.setattr(_interreflections, "ps_li_alternating",
                        lambda *a, **k: rounds.append(k.get("rounds")) or li(*a, **k))
    binned = process(folder, outputs=["normals"])
    monkeypatch.setattr(_interreflections, "BINNED_ROUNDS", 4)          # li_alternating's own default
    every = process(folder, outputs=["normals"])
    assert rounds == [1, 4]          # the binned decision: round 1 only
    for res in (binned, every):
        assert res.interreflections["scale_identified"] is False and not res.interreflections["model_reused"]
    a, b = binned.interreflections["scale_estimate"], every.interreflections["scale_estimate"]
    assert abs(a["diffuse_correlation"] - b["diffuse_correlation"]) < 0.05, (a, b)
    np.testing.assert_array_equal(binned.normals, every.normals)
