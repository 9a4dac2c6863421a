import numpy as np
import pytest

from facette.io.exr import read_exr, write_exr


def test_round_trip_keeps_values_and_channel_order(tmp_path):
    rng = np.random.default_rng(1)
    img = rng.normal(size=(7, 5, 3)).astype(np.float32)
    img[0, 0, 0] = np.inf
    img[1, 1, 1] = 1e-30
    write_exr(tmp_path / "n.exr", img, channels=("X", "Y", "Z"), header={"units": "unit vectors"})
    back, names = read_exr(tmp_path / "n.exr")
    assert names == ("X", "Y", "Z")
    np.testing.assert_array_equal(back, img)


def test_single_channel_and_selection(tmp_path):
    h = np.arange(12, dtype=np.float64).reshape(3, 4)
    write_exr(tmp_path / "h.exr", h, channels=("Z",))
    back, names = read_exr(tmp_path / "h.exr", channels=("Z",))
    assert back.shape == (3, 4, 1) and names == ("Z",)
    np.testing.assert_array_equal(back[:, :, 0], h.astype(np.float32))


def test_errors_say_what_is_wrong(tmp_path):
    with pytest.raises(ValueError, match="shape"):
        write_exr(tmp_path / "x.exr", np.zeros(3))
    with pytest.raises(ValueError, match="channel names"):
        write_exr(tmp_path / "x.exr", np.zeros((2, 2, 3)), channels=("A",))
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr at all")
    with pytest.raises(ValueError, match="not a readable EXR"):
        read_exr(bad)
    write_exr(tmp_path / "c.exr", np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="no channel"):
        read_exr(tmp_path / "c.exr", channels=("Q",))
