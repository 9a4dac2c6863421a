"""One processing path (issue 49 item 2): a capture read whole is the band loop's one band
(`pipeline._whole`), and a capture whose one band fits the --memory budget is read so too: `process`
with or without --memory writes the same files."""
import numpy as np
import pytest

from facette.io.diligent import write_diligent
from facette.pipeline import ProcessOptions, process
from facette.pipeline import _tiled_process
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


def test_held_bands_give_copies_until_the_last_read():
    images = np.arange(2 * 3 * 4 * 3, dtype=np.float32).reshape(2, 3, 4, 3)
    usable = images[..., 1] > 5
    bands = HeldBands(images, usable)
    band, use = bands.read(1, 3)
    band /= 2                                    # the loop's passes divide their band in place
    np.testing.assert_array_equal(images[:, 1:3], np.arange(2 * 3 * 4 * 3).reshape(2, 3, 4, 3)[:, 1:3])
    np.testing.assert_array_equal(use, usable[:, 1:3])
    bands.last = True
    whole, _ = bands.read(0, 3)
    assert np.shares_memory(whole, images) and not bands.last      # the solve's read: no second stack
    assert not np.shares_memory(bands.read(0, 3)[0], images)        # once only


def test_read_in_bands_only_when_the_band_is_shorter_than_the_image(folder, monkeypatch):
    outputs = ["normals"]
    assert not read_in_bands(folder, ProcessOptions(), outputs)                      # no budget: whole
    assert not read_in_bands(folder, ProcessOptions(memory="2GB"), outputs)          # one band fits
    assert read_in_bands(folder, ProcessOptions(memory="2GB", scheduler="tcp://127.0.0.1:9"), outputs)
    monkeypatch.setattr(_tiled_process, "rows_per_tile", lambda *a, **k: 5)
    assert read_in_bands(folder, ProcessOptions(memory="2GB"), outputs)


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
