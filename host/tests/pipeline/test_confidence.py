"""`process` writes each normal's uncertainty: a channel of normal.exr, a summary in process.json,
a map in report.html (pipeline/_confidence.py), on a DiLiGenT-style folder made here."""
import json

import numpy as np

from facette.io.diligent import write_diligent
from facette.io.exr import read_exr
from facette.pipeline import process
from facette.pipeline._confidence import UNCERTAINTY_CHANNEL
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def test_process_writes_the_uncertainty(tmp_path):
    L = thesis_light_directions()
    sc = sphere_on_plane(32, 40)
    imgs = render(sc, L, "satin", noise=0.01)
    u16 = np.round(np.clip(imgs / imgs.max(), 0, 1) * 50000).astype(np.uint16)
    write_diligent(tmp_path / "in", u16, L, None, sc.mask)
    res = process(tmp_path / "in", outputs=["normals", "report"], out_dir=tmp_path / "out", method="rank_trimmed")
    img, channels = read_exr(tmp_path / "out" / "normal.exr")
    assert channels == ("X", "Y", "Z", UNCERTAINTY_CHANNEL)
    u = img[..., 3]
    assert np.allclose(u, res.uncertainty) and np.all(u[~res.mask] == 0)
    assert np.all(u[res.mask] > 0) and np.all(u[res.mask] <= 90)
    rec = json.loads((tmp_path / "out" / "process.json").read_text())
    summary = rec["quality"]["normal_uncertainty"]
    assert 0 < summary["median_deg"] <= summary["p90_deg"] < 90
    assert "Uncertainty of the normal" in (tmp_path / "out" / "report.html").read_text()


def test_memory_bands_give_the_whole_images_uncertainty(tmp_path, monkeypatch, force_bands):
    L = thesis_light_directions()
    sc = sphere_on_plane(24, 32)
    imgs = render(sc, L, "matte")
    write_diligent(tmp_path / "in", np.round(imgs / imgs.max() * 50000).astype(np.uint16), L, None, sc.mask)
    whole = process(tmp_path / "in", outputs=["normals"], method="rank_trimmed")
    force_bands(5)    # bands (one would hold it all)
    res = process(tmp_path / "in", outputs=["normals"], out_dir=tmp_path / "out", method="rank_trimmed",
                  memory="2GB")
    _, channels = read_exr(tmp_path / "out" / "normal.exr")     # over bands too (pipeline._band_uncertainty)
    assert channels == ("X", "Y", "Z", "uncertainty_deg") and any("bands" in n for n in res.notes)
    np.testing.assert_array_equal(res.uncertainty, whole.uncertainty)
    assert res.quality["normal_uncertainty"] == whole.quality["normal_uncertainty"]
