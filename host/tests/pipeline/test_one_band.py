"""One processing path (issue 49 item 2): a capture read whole is the band loop's one band
(`pipeline._whole`), and a capture whose one band fits the --memory budget is read so too: `process`
with or without --memory writes the same files."""
from types import SimpleNamespace

import numpy as np
import pytest

from facette.io.diligent import write_diligent
from facette.pipeline import ProcessOptions, process
from facette.pipeline import _tiled_process
from facette.pipeline import _streamed
from facette.pipeline._budget import whole_bytes
from facette.pipeline._streamed import read_in_bands
from facette.pipeline._whole import HeldBands
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()
FILES = ("normal.exr", "albedo.exr", "mask.png", "height.exr")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A glossy sphere on a plane, 36x44 px, 16-bit PNGs, its lights 4 % off their given intensities."""
    scene = sphere_on_plane(36, 44, border=2)
    images = render(scene, L, material="glossy", noise=0.002, rng=np.random.default_rng(11))
    gain = 1 + 0.04 * np.sin(np.arange(len(L)))
    raw = np.clip(np.rint(images * gain[:, None, None, None] * 3.0 * 65535), 0, 65535).astype(np.uint16)
    path = tmp_path_factory.mktemp("one") / "dil"
    write_diligent(path, raw, L, np.full((len(L), 3), 3.0), scene.mask)
    return path


def test_held_bands_prepare_the_one_band_once_and_serve_it_without_a_copy():
    rng = np.random.default_rng(3)
    images = rng.uniform(0.1, 1.0, (4, 3, 5, 3)).astype(np.float32)
    raw = images.copy()
    mask = np.ones((3, 5), bool)
    bands = HeldBands(images, images[..., 1] > 0)
    weights = np.array([0.25, 0.5, 0.25], np.float32)
    bands.prepare(SimpleNamespace(mask=mask), None, {"light_dirs": L[:4], "saturation": None}, weights,
                  "li_alternating")
    first, solve, dirs, solved = bands.solve_read(0, 3)          # the gains' pass: before the division
    assert np.shares_memory(first, images) and solve.shape == (4, 3, 5, 4) and solved.all()
    gains = np.array([1.0, 2.0, 4.0, 0.5], np.float32)
    again, solve_g, _, _ = bands.solve_read(0, 3, gains)          # divided in place, once
    assert np.shares_memory(again, images) and np.shares_memory(solve_g, solve)
    np.testing.assert_allclose(images, raw / gains[:, None, None, None], rtol=1e-6)
    band = bands.solve_inputs(0, 3, gains)                        # the solve's: the same arrays
    assert band[0] is images and np.shares_memory(band[1], solve) and band[1].shape[-1] == 4
    np.testing.assert_allclose(images, raw / gains[:, None, None, None], rtol=1e-6)    # not divided twice
    with pytest.raises(RuntimeError):
        bands.solve_read(0, 3)


def test_read_in_bands_only_when_the_whole_reading_does_not_fit(folder, force_bands):
    outputs = ["normals"]
    assert not read_in_bands(folder, ProcessOptions(), outputs)                      # no budget: whole
    assert not read_in_bands(folder, ProcessOptions(memory="2GB"), outputs)          # one band fits
    assert read_in_bands(folder, ProcessOptions(memory="2GB", scheduler="tcp://127.0.0.1:9"), outputs)
    force_bands(5)
    assert read_in_bands(folder, ProcessOptions(memory="2GB"), outputs)


def test_the_budget_s_note_figure_decides_whether_a_capture_is_read_whole(folder, monkeypatch):
    """Not the bands' own model (124 bytes per pixel-light for li_alternating): it split a 12 MP x 12
    capture under --memory 12GB while the note said the capture needs ~10.1 GB whole."""
    monkeypatch.setattr(_streamed, "capture_size", lambda source: (12, 3000, 4000))
    need = whole_bytes(12, 3000, 4000)
    assert 9.5e9 < need < 10.5e9
    for memory, bands in (("12GB", False), (str(need), False), (str(need - 1), True), ("2GB", True)):
        assert read_in_bands(folder, ProcessOptions(memory=memory), ["normals"]) == bands, memory


def test_memory_that_holds_one_band_writes_the_files_of_a_run_without_it(folder, tmp_path):
    outputs = ["normals", "albedo", "mask", "height"]
    kw = {"ps_options": {"coarse_pixels": 400}}          # li_alternating's model made for the bands
    whole = process(folder, outputs=outputs, out_dir=tmp_path / "whole", **kw)
    flag = process(folder, outputs=outputs, out_dir=tmp_path / "flag", memory="2GB", **kw)
    for res in (whole, flag):
        assert res.ps.method == "li_alternating" and res.ps.info["tiles"] == 1
        assert res.light_gains is not None and res.ps.shadow.shape[-1] == len(L)     # the flags kept
    assert any("fits one band" in n for n in flag.notes)
    assert not any("--memory reads the images by bands" in n for n in flag.notes)  # inter-reflections decided
    assert (whole.interreflections is None) == (flag.interreflections is None)
    differ = [name for name in FILES if (tmp_path / "whole" / name).read_bytes() != (tmp_path / "flag" / name).read_bytes()]
    assert not differ, differ


def test_the_prepared_band_gives_the_normals_of_a_band_read_again_by_each_pass(folder, tmp_path, monkeypatch):
    """The one band prepared once (the solve's channel appended once, no copy of the photographs)
    writes the bytes of the loop that reads and prepares the band again in each pass."""
    made = []
    stack = _tiled_process.with_solve_channel
    monkeypatch.setattr(_tiled_process, "with_solve_channel", lambda *a, **k: made.append(1) or stack(*a, **k))
    outputs = ["normals", "albedo", "mask"]
    shared = process(folder, outputs=outputs, out_dir=tmp_path / "shared")
    once, made[:] = len(made), []
    monkeypatch.setattr(HeldBands, "prepare", lambda self, *a: None)      # each pass reads a copy of its own
    again = process(folder, outputs=outputs, out_dir=tmp_path / "again")
    assert once == 1 and len(made) >= 3              # the gains', the shadows' (and the decision's) and the solve's
    assert shared.light_gains is not None and shared.quality["shadows"] is not None
    for name in ("normal.exr", "albedo.exr", "mask.png"):
        assert (tmp_path / "shared" / name).read_bytes() == (tmp_path / "again" / name).read_bytes(), name


def test_the_hidden_values_are_taken_out_once_for_the_model_and_the_solve(tmp_path):
    """li_alternating's model and the solve read the one band without its hidden lights: one copy made
    for the model and taken by the solve, the normals of a copy made for each."""
    from shadow_scenes import groove_scene
    from facette.pipeline import _whole
    d = groove_scene("groove", fill=0.4)
    top = 60000.0 / float(d["images"].max())
    folder = tmp_path / "groove"
    write_diligent(folder, np.round(d["images"] * top).astype(np.uint16), d["light_dirs"],
                   np.full((len(d["images"]), 3), top / 65535.0), d["mask"])
    copies = []
    plain = _whole.without_hidden

    def counted(images, found, *a):
        copies.append(found is not None)
        return plain(images, found, *a)

    options = dict(outputs=["normals", "albedo"], interreflections=False, shadows="on",
                   ps_options={"coarse_pixels": 400})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_whole, "without_hidden", counted)
        once = process(folder, **options)
        made, copies[:] = sum(copies), []
        mp.setattr(HeldBands, "without_hidden", lambda self, solve, found, mask, r0, name, keep=False:
                   counted(solve, found, mask, r0, name))          # a copy for each reader
        each = process(folder, **options)
    assert once.quality["shadows"]["applied"] and once.ps.info.get("coarse") is not None
    assert made == 1 and sum(copies) == 2
    np.testing.assert_array_equal(once.normals, each.normals)
    np.testing.assert_array_equal(once.albedo, each.albedo)
    np.testing.assert_array_equal(once.ps.shadow, each.ps.shadow)
