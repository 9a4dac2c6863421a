"""facette.sim.bands: the scene and the LEDs rendered a band of rows at a time to disk give the
numbers (and the frames) of the whole rendered at once."""
import numpy as np
import pytest

from facette.camera.raw import read_raw_mosaic
from facette.sim.bands import RadianceOnDisk, band_rows_for, render_to_disk
from facette.sim.lights import thesis_leds
from facette.sim.render import radiance_per_led
from facette.sim.rig import SimCamera
from facette.sim.scene import make_scene, scene_spec


@pytest.mark.parametrize("near", [False, True])
def test_radiance_rendered_in_bands_equals_the_whole(tmp_path, near):
    spec = scene_spec("plaque_sphere", (48, 64))
    leds = thesis_leds(near=near)
    whole = radiance_per_led(make_scene("plaque_sphere", (48, 64)), leds)
    disk = render_to_disk(tmp_path, spec, leds, band_rows=7)      # 7 bands, the last one short
    assert disk.shape == whole.shape
    for i in range(len(leds)):
        assert np.array_equal(disk.rows(i, 0, 48), whole[i])
    assert np.array_equal(disk.rows(3, 10, 17), whole[3, 10:17])
    truth = make_scene("plaque_sphere", (48, 64))
    assert np.array_equal(np.load(tmp_path / "truth_normals.npy"), truth.normals.astype(np.float32))
    assert np.array_equal(np.load(tmp_path / "truth_mask.npy"), truth.mask)


def test_scene_rows_equal_the_same_rows_of_the_whole():
    spec = scene_spec("plaque_sphere", (40, 56), supersample=3)
    whole = make_scene("plaque_sphere", (40, 56), supersample=3)
    band = spec.rows(13, 29)
    for name in ("height_mm", "normals", "mask", "albedo"):
        assert np.array_equal(getattr(band, name), getattr(whole, name)[13:29])
    with pytest.raises(ValueError, match="not inside"):
        spec.rows(30, 41)


def test_a_frame_exposed_in_bands_is_the_frame_exposed_whole(tmp_path):
    leds = thesis_leds()
    whole = radiance_per_led(make_scene("plaque_sphere", (48, 64)), leds)
    disk = render_to_disk(tmp_path / "rad", scene_spec("plaque_sphere", (48, 64)), leds, band_rows=5)
    charge = np.zeros(len(leds))
    charge[4] = 2.5e5                        # one LED lit, as in every frame of a scan
    a = SimCamera(tmp_path / "a", whole, seed=3).expose(charge, 0.25)
    b = SimCamera(tmp_path / "b", disk, seed=3).expose(charge, 0.25)
    assert np.array_equal(read_raw_mosaic(a)[0], read_raw_mosaic(b)[0])
    dark = SimCamera(tmp_path / "c", disk, seed=3).expose(np.zeros(len(leds)), 0.25)
    assert read_raw_mosaic(dark)[0].max() < 1000          # no light: black level and noise


def test_radiance_on_disk_reads_only_the_lit_leds(tmp_path):
    disk = RadianceOnDisk(tmp_path, 3, (4, 5))
    for i in range(3):
        with open(disk.path(i), "wb") as fh:
            np.save(fh, np.full((4, 5, 3), float(i + 1)))
    disk.path(0).unlink()                     # never read: LED 0 gave no charge
    e = disk.electrons([0.0, 2.0, 0.5], 1, 3)
    assert e.shape == (2, 5, 3) and np.all(e == 2.0 * 2 + 0.5 * 3)


def test_band_rows_for_a_100_mp_raw_keeps_a_band_small():
    rows = band_rows_for(5824)
    assert rows % 2 == 0 and 200 <= rows <= 300
    assert band_rows_for(1_000_000) == 8


def test_a_folder_that_holds_the_same_render_is_used_as_it_is(tmp_path):
    spec, leds = scene_spec("plaque_sphere", (24, 32)), thesis_leds()
    first = render_to_disk(tmp_path, spec, leds, band_rows=8).rows(2, 0, 24)
    stamp = (tmp_path / "led_00.npy").stat().st_mtime_ns
    again = render_to_disk(tmp_path, spec, leds, band_rows=6)
    assert (tmp_path / "led_00.npy").stat().st_mtime_ns == stamp             # not rendered again
    assert np.array_equal(again.rows(2, 0, 24), first)
    render_to_disk(tmp_path, spec, leds, electrons_per_mA_s=40.0, band_rows=8)   # another render
    np.testing.assert_allclose(RadianceOnDisk(tmp_path, 12, (24, 32)).rows(2, 0, 24), 2 * first, rtol=1e-12)
