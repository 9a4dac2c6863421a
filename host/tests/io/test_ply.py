"""facette.io.ply: ASCII and binary PLY round trips."""
import numpy as np
import pytest

from facette.io.ply import read_ply, write_ply


@pytest.mark.parametrize("binary", [True, False])
def test_ply_roundtrip(tmp_path, binary):
    v = np.array([[0, 0, 0], [1, 0, 0.5], [0, 1, 0.25], [1, 1, 1]], np.float32)
    f = np.array([[0, 2, 1], [1, 2, 3]], np.int32)
    write_ply(tmp_path / "m.ply", v, f, binary=binary)
    v2, f2 = read_ply(tmp_path / "m.ply")
    np.testing.assert_allclose(v2, v)
    assert np.array_equal(f2, f)
    with pytest.raises(ValueError, match="face indices"):
        write_ply(tmp_path / "bad.ply", v, f + 3)
