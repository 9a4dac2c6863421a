"""facette.io.diligent: DiLiGenT-style folders."""
import numpy as np
import pytest

from facette.io.diligent import is_diligent_dir, read_diligent, write_diligent
from facette.io.png import write_png


def test_diligent_folder_roundtrip_divides_by_intensities(tmp_path):
    rng = np.random.default_rng(3)
    imgs = (rng.random((5, 6, 8, 3)) * 60000).astype(np.uint16)
    imgs[2, 3, 4, 1] = 65535                       # a saturated value
    dirs = rng.normal(size=(5, 3))
    dirs[:, 2] = np.abs(dirs[:, 2]) + 1
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    inten = rng.random((5, 3)) + 0.5
    mask = rng.random((6, 8)) > 0.3
    write_diligent(tmp_path, imgs, dirs, inten, mask)
    assert is_diligent_dir(tmp_path)
    d = read_diligent(tmp_path)
    expected = imgs / 65535.0 / inten[:, None, None, :]
    expected[2, 3, 4, 1] = np.nan
    np.testing.assert_allclose(d.images, expected, rtol=1e-6)
    np.testing.assert_allclose(d.light_dirs, dirs, atol=1e-7)
    assert np.array_equal(d.mask, mask)
    (tmp_path / "light_intensities.txt").write_text("1 1 1\n")
    with pytest.raises(ValueError, match="light_intensities.txt holds 1 lines of 3 numbers; filenames.txt lists 5"):
        read_diligent(tmp_path)


def test_read_diligent_selects_images_and_reports_bit_depth(tmp_path):
    rng = np.random.default_rng(4)
    dirs = rng.normal(size=(4, 3))
    dirs[:, 2] = np.abs(dirs[:, 2]) + 1
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    imgs = (rng.random((4, 3, 5, 3)) * 200).astype(np.uint16)
    write_diligent(tmp_path / "a", imgs, dirs)
    d = read_diligent(tmp_path / "a", select=[3, 1])
    assert d.images.shape == (2, 3, 5, 3) and d.bit_depth == 16 and d.names == ["004.png", "002.png"]
    np.testing.assert_allclose(d.light_dirs, dirs[[3, 1]], atol=1e-7)
    np.testing.assert_allclose(d.images[0], imgs[3] / 65535.0, rtol=1e-6)
    write_diligent(tmp_path / "b", imgs.astype(np.uint8), dirs)
    assert read_diligent(tmp_path / "b").bit_depth == 8
    with pytest.raises(ValueError, match="select"):
        read_diligent(tmp_path / "a", select=[4])


def _folder_with_lights(folder, dirs):
    from facette.recon.synthetic import render, sphere_on_plane
    sc = sphere_on_plane(16, 16)
    imgs = render(sc, np.abs(np.asarray(dirs)) / np.linalg.norm(dirs, axis=1)[:, None], "matte")
    write_diligent(folder, np.round(imgs / imgs.max() * 50000).astype(np.uint16), dirs)
    return folder


def test_lights_below_the_horizon_are_left_out_and_said(tmp_path):
    from facette.recon.synthetic import thesis_light_directions
    dirs = thesis_light_directions()[:8].copy()
    dirs[[2, 5], 2] *= -1                                  # two lights under the table
    d = read_diligent(_folder_with_lights(tmp_path / "f", dirs))
    assert len(d.light_dirs) == 6 and (d.light_dirs[:, 2] >= 0).all() and len(d.images) == 6
    assert d.names == ["001.png", "002.png", "004.png", "005.png", "007.png", "008.png"]
    assert d.notes == ["light_directions.txt: 2 light(s) below the horizon (z < 0; lines 3, 6) left out: "
                       "they cannot light a surface the camera sees"]


def test_lights_all_below_or_from_one_direction_are_refused(tmp_path):
    from facette.errors import BadInputError
    from facette.recon.synthetic import thesis_light_directions
    dirs = thesis_light_directions()[:6].copy()
    flipped = dirs * [1, 1, -1]
    with pytest.raises(BadInputError, match="every light has z < 0") as exc:
        read_diligent(_folder_with_lights(tmp_path / "a", flipped))
    assert "flip the sign of z" in exc.value.hint
    same = np.tile(dirs[:1], (6, 1))
    with pytest.raises(BadInputError, match="the 6 lights all share one direction"):
        read_diligent(_folder_with_lights(tmp_path / "b", same))
    # a column of lights in one plane through the object (as DiLiGenT's first 8): normals undetermined
    t = np.radians(np.linspace(10, 50, 6))
    column = np.stack([np.zeros(6), np.sin(t), np.cos(t)], axis=1)
    with pytest.raises(BadInputError, match="the 6 lights lie in one plane through the object"):
        read_diligent(_folder_with_lights(tmp_path / "c", column))


def test_an_image_of_another_size_is_refused_by_name(tmp_path):
    """The images are decoded on two threads: the size check still stops the read and names the file."""
    imgs = np.full((6, 4, 5, 3), 1000, np.uint16)
    dirs = np.tile([0.0, 0.0, 1.0], (6, 1)) + np.eye(6, 3) * 0.3
    write_diligent(tmp_path, imgs, dirs / np.linalg.norm(dirs, axis=1, keepdims=True))
    names = (tmp_path / "filenames.txt").read_text().split()
    write_png(tmp_path / names[4], np.zeros((3, 5, 3), np.uint16))
    with pytest.raises(ValueError, match=f"{names[4]} is 5x3, {names[0]} is 5x4: every photograph .* one size"):
        read_diligent(tmp_path)
