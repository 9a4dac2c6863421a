"""Photometric stereo over tiles: forced small tiles give the untiled result, for every
per-pixel method; whole-image methods refuse; the tile height follows the memory budget."""
import shutil

import numpy as np
import pytest

from facette.io.diligent import read_diligent, write_diligent
from facette.methods import photometric_stereo
from facette.pipeline import TILED_METHODS, WHOLE_IMAGE_METHODS, parse_memory, ps_tiled, rows_per_tile
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()


def _angle_deg(a, b):
    a, b = a.astype(np.float64), b.astype(np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A glossy sphere on a plane (highlights, attached and cast shadows, noise, a few clipped
    values), 36x44 px, written as 16-bit PNGs with a mask that leaves out a border and a row."""
    scene = sphere_on_plane(36, 44, border=2)
    images = render(scene, L, material="glossy", noise=0.002, rng=np.random.default_rng(3))
    raw = np.clip(np.rint(images * 3.0 * 65535), 0, 65535).astype(np.uint16)
    assert (raw == 65535).any()                         # saturated values: NaN on reading
    mask = scene.mask.copy()
    mask[20] = False                                    # a row out of the mask
    mask[:7] = False                                    # whole bands out of the mask
    path = tmp_path_factory.mktemp("tiles")
    write_diligent(path, raw, L, np.full((len(L), 3), 3.0), mask)
    return path


@pytest.mark.parametrize("method", TILED_METHODS)
def test_small_tiles_give_the_untiled_result(folder, method):
    d = read_diligent(folder)
    whole = photometric_stereo(d.images, d.light_dirs, method=method, mask=d.mask)
    tiled = ps_tiled(folder, method=method, rows=5)
    assert tiled.info["tiles"] == 8 and tiled.info["rows_per_tile"] == 5
    assert whole.valid.sum() > 500
    np.testing.assert_array_equal(tiled.valid, whole.valid)
    assert _angle_deg(tiled.normal, whole.normal)[whole.valid].max() < 0.01
    np.testing.assert_allclose(tiled.albedo, whole.albedo, atol=1e-5)
    np.testing.assert_allclose(tiled.residual, whole.residual, atol=1e-5)
    assert tiled.info["pixels"] == whole.info["pixels"]


def test_on_band_sees_every_masked_row_and_nothing_is_kept(folder):
    seen = []
    res = ps_tiled(folder, method="woodham1980", rows=7, keep=(),
                   on_band=lambda r0, r1, part: seen.append((r0, r1, part.normal.shape)))
    assert res.normal.shape == (0, 0, 3) and res.valid.shape == (0, 0)
    # rows 0..6 and the 2-px border's rows 34..35 are out of the mask: those bands are skipped
    assert [s[:2] for s in seen] == [(7, 14), (14, 21), (21, 28), (28, 35)]
    assert all(shape == (r1 - r0, 44, 3) for r0, r1, shape in seen)


@pytest.mark.parametrize("method", sorted(WHOLE_IMAGE_METHODS))
def test_whole_image_methods_refuse_tiles(folder, method):
    with pytest.raises(ValueError, match="cannot run over tiles"):
        ps_tiled(folder, method=method, rows=5)


def test_memory_sizes_are_parsed():
    assert parse_memory("2GB") == 2_000_000_000
    assert parse_memory("1.5 gb") == 1_500_000_000
    assert parse_memory("512MB") == 512_000_000
    assert parse_memory("3GiB") == 3 * 2 ** 30
    assert parse_memory(1000) == 1000
    for bad in ("two GB", "2 XB", "0", "-1GB", ""):
        with pytest.raises(ValueError, match="memory must be"):
            parse_memory(bad)


def test_rows_per_tile_follow_the_budget():
    w, h = 4288, 2848
    rows = [rows_per_tile(w, h, 12, mem) for mem in ("1GB", "2GB", "3GB")]
    assert rows[0] < rows[1] < rows[2] <= h
    assert rows_per_tile(64, 48, 12, "2GB") == 48                # a small image is one tile
    assert rows_per_tile(w, h, 12, "1GB", keep=()) > rows[0]      # fewer outputs kept: taller tiles
    with pytest.raises(ValueError, match="give at least"):
        rows_per_tile(11648, 8736, 12, "2GB")                     # 100 MP outputs do not fit in 2 GB
    assert rows_per_tile(11648, 8736, 12, "2GB", keep=()) >= 1


def test_what_the_process_holds_besides_comes_out_of_the_bands():
    w, h = 4288, 2848
    alone = rows_per_tile(w, h, 12, "2GB", keep=())
    held = 450e6 + 9 * w * h                                      # libraries and a scan's maps
    besides = rows_per_tile(w, h, 12, "2GB", keep=(), held=held)
    per_row = w * 12 * 48                                         # rank_trimmed's band bytes per row
    assert besides < alone and abs((alone - besides) * per_row - held) < 2 * per_row
    with pytest.raises(ValueError, match="held besides"):
        rows_per_tile(w, h, 12, "2GB", keep=(), held=1.9e9)


def test_a_budget_too_small_or_a_bad_request_is_said_before_any_work(folder):
    with pytest.raises(ValueError, match="give at least"):
        ps_tiled(folder, method="woodham1980", memory=1000)
    with pytest.raises(ValueError, match="keep names outputs"):
        ps_tiled(folder, method="woodham1980", rows=5, keep=("normals",))
    with pytest.raises(ValueError, match="rows must be >= 1"):
        ps_tiled(folder, method="woodham1980", rows=0)


def test_a_budget_chooses_the_tiles(folder):
    res = ps_tiled(folder, method="woodham1980", memory="2GB")
    assert res.info["tiles"] == 1 and res.info["rows_per_tile"] == 36


def test_lights_below_the_horizon_are_left_out_as_read_diligent_does(folder, tmp_path):
    shutil.copytree(folder, tmp_path / "f")
    dirs = np.loadtxt(tmp_path / "f" / "light_directions.txt")
    dirs[4] = [0.3, 0.2, -0.9]                                   # below the horizon
    np.savetxt(tmp_path / "f" / "light_directions.txt", dirs, fmt="%.8f")
    d = read_diligent(tmp_path / "f")
    assert len(d.light_dirs) == 11
    whole = photometric_stereo(d.images, d.light_dirs, method="woodham1980", mask=d.mask)
    tiled = ps_tiled(tmp_path / "f", method="woodham1980", rows=9)
    assert _angle_deg(tiled.normal, whole.normal)[whole.valid].max() < 0.01
    assert any("below the horizon" in note for note in tiled.info["notes"])
