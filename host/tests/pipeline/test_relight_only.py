"""pipeline._relight_only: relight.ptm, relight.rti and relight_web/ alone are fitted over bands without
photometric stereo, the whole reading's bytes (an RTI capture of JPEGs with a table around the object, a
DiLiGenT folder, an HDR scan with near lights), the images never loaded whole; the budget it takes."""
import numpy as np
import pytest

from facette.pipeline import ProcessOptions, process, stages_needed
from facette.pipeline import _process, _relight_only, _streamed
from facette.recon import _rti as rti_fit
from test_process_memory import _never_whole, diligent, scan  # noqa: F401

OUTPUTS = ["ptm", "rti", "relight-web"]


@pytest.fixture
def rti_capture(tmp_path):
    """JPEGs + .lp of a matte sphere on a dark textured table (the object's mask leaves the table out)."""
    import cv2

    from facette.calib.lp import write_lp
    from facette.recon.synthetic import render, sphere_on_plane
    m = 16
    az = np.radians(np.arange(m) * 360.0 / m)
    el = np.radians(np.tile([30.0, 45.0, 60.0, 75.0], m // 4))
    dirs = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    scene = sphere_on_plane(36, 44, radius=12)
    tex = np.where(scene.height > 0, 1.0, 0.12 + 0.04 * np.random.default_rng(1).random(scene.height.shape))
    imgs = render(scene, dirs, "matte", albedo=(0.8, 0.7, 0.6), cast_shadows=False) * tex[..., None]
    folder = tmp_path / "cap"
    folder.mkdir()
    names = [f"p{k:02d}.jpg" for k in range(m)]
    for name, im in zip(names, np.clip(imgs / imgs.max(), 0, 1)):
        v = np.where(im <= 0.0031308, 12.92 * im, 1.055 * im ** (1 / 2.4) - 0.055)
        cv2.imwrite(str(folder / name), np.round(v[..., ::-1] * 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 95])
    write_lp(folder / "c.lp", names, dirs)
    return folder


def _files(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "process.json"}


@pytest.mark.parametrize("source,encoding", [("rti_capture", "auto"), ("diligent", "srgb"), ("scan", "linear")])
def test_the_relighting_files_over_bands_without_photometric_stereo_are_the_whole_readings(
        request, tmp_path, monkeypatch, source, encoding):
    src = request.getfixturevalue(source)
    monkeypatch.setattr(rti_fit, "_BLOCK", 16)        # both: bands of 8 rows start on the fits' blocks
    with monkeypatch.context() as whole_only:        # the whole reading, as a source that fits the budget had it
        whole_only.setattr(_process, "relighting_budget", lambda *a, **k: None)
        whole_only.setattr(_process, "with_default_budget", lambda s, o, out: (o, []))
        whole = process(src, outputs=OUTPUTS, out_dir=tmp_path / "whole", rti_encoding=encoding)
    assert not any("no photometric stereo" in n for n in whole.notes)
    _never_whole(monkeypatch)

    def no_ps(*a, **k):
        raise AssertionError("photometric stereo ran")
    monkeypatch.setattr(_streamed, "streamed_ps", no_ps)
    monkeypatch.setattr(_relight_only, "relight_band_rows", lambda *a: 8)
    tiled = process(src, outputs=OUTPUTS, out_dir=tmp_path / "tiled", rti_encoding=encoding)
    assert tiled.ps is None and tiled.normals is None
    assert any(n.startswith("memory: the relighting files alone need no photometric stereo") for n in tiled.notes)
    assert any("no photometric stereo" in n and "bands of 8 rows" in n for n in tiled.notes)
    a, b = _files(tmp_path / "whole"), _files(tmp_path / "tiled")
    assert len(a) >= 12 and a.keys() == b.keys()      # .ptm, .rti, the web folder's info.json and planes
    for name in a:
        assert a[name] == b[name], name
    np.testing.assert_array_equal(tiled.object_mask, whole.object_mask)
    assert tiled.fit_errors == whole.fit_errors and len(whole.fit_errors) == 2
    assert tiled.quality["rti_exposure"] == whole.quality["rti_exposure"]
    assert tiled.quality.get("object") == whole.quality.get("object")
    assert [n for n in tiled.notes if n.startswith("relight")] == [n for n in whole.notes if n.startswith("relight")]


def test_the_table_around_the_object_is_left_out_as_whole(rti_capture):
    """The dark table around the sphere is left out of the object's mask over bands (as whole: the test above)."""
    res = process(rti_capture, outputs=["ptm"])
    assert res.mask.sum() > res.object_mask.sum() > 0


def test_the_budget_of_the_relighting_files_alone(tmp_path, diligent):
    o = ProcessOptions()
    got = _relight_only.relight_only_budget(diligent, o, stages_needed(["rti", "ptm"]), free=64 * 10 ** 9)
    assert got is not None
    opts, notes = got
    assert opts.memory_bytes == 4 * 10 ** 9 and len(notes) == 1 and "read band by band in 4.0 GB" in notes[0]
    opts, notes = _relight_only.relight_only_budget(diligent, o, stages_needed(["rti"]), free=3 * 10 ** 9)
    assert opts.memory_bytes == 10 ** 9                 # the default budget's, when it is smaller
    assert _relight_only.relight_only_budget(diligent, ProcessOptions(memory="2GB"), stages_needed(["ptm"])) \
        == (ProcessOptions(memory="2GB"), [])          # --memory as given
    for outputs in (["rti", "normals"], ["relight"], []):      # the normals needed (or nothing asked)
        assert _relight_only.relight_only_budget(diligent, o, stages_needed(outputs)) is None
    assert _relight_only.relight_only_budget(tmp_path / "nothing.png", o, stages_needed(["rti"])) is None


def test_band_rows_hold_the_budget():
    w, h, m = 4000, 3000, 16
    rows = _relight_only.relight_band_rows(2 * 10 ** 9, w, h, m, 7)
    assert rows % 2 == 0 and 2 <= rows < h
    assert _relight_only.relight_band_rows(10 ** 8, w, h, m, 7) == 2        # never under two rows
    assert _relight_only.relight_band_rows(4 * 10 ** 9, w, h, m, 7) > rows


def test_a_scheduler_given_is_said_unused(diligent):
    res = process(diligent, outputs=["rti"], memory="1GB", scheduler="tcp://127.0.0.1:9")
    assert any(n.startswith("--scheduler tcp://127.0.0.1:9: not used") for n in res.notes)
    assert res.hsh is not None and res.ps is None
