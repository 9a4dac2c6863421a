"""DNG writer: rawpy decodes what we write, bit for bit, with its metadata."""
import numpy as np
import pytest
import rawpy
import tifffile

from facette.sim.dng import write_dng
from facette.camera.sensor import SensorModel


@pytest.mark.parametrize("t_s", [1 / 30, 15.0, 0.000125])
def test_round_trip_bit_exact(tmp_path, t_s):
    s = SensorModel()
    rng = np.random.default_rng(7)
    mosaic = s.expose(rng.uniform(0, 2e4, (24, 40, 3)), 0.5, rng)
    path = write_dng(tmp_path / "f.dng", mosaic, s.black_level_dn, s.white_level_dn, t_s, 400,
                     extra={"light": 2, "exposure": 5})
    with rawpy.imread(str(path)) as raw:
        assert np.array_equal(raw.raw_image, mosaic)
        assert list(raw.black_level_per_channel) == [s.black_level_dn] * 4
        assert raw.white_level == s.white_level_dn
        assert raw.color_desc == b"RGBG"
        assert raw.raw_pattern.tolist() == [[0, 1], [3, 2]]  # RGGB, second green = 3
    with tifffile.TiffFile(path) as tf:
        tags = tf.pages[0].tags
        num, den = tags[33434].value
        assert num / den == pytest.approx(t_s, rel=1e-6)
        assert tags[34855].value == 400
        assert '"light": 2' in tags[270].value
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]


def test_rejects_bad_mosaics(tmp_path):
    with pytest.raises(ValueError, match="even"):
        write_dng(tmp_path / "a.dng", np.zeros((23, 24), np.uint16), 0, 16383, 1.0, 400)
    with pytest.raises(ValueError, match="too small"):
        write_dng(tmp_path / "a.dng", np.zeros((20, 40), np.uint16), 0, 16383, 1.0, 400)
    with pytest.raises(ValueError, match="uint16"):
        write_dng(tmp_path / "a.dng", np.full((24, 24), -1.0), 0, 16383, 1.0, 400)
    with pytest.raises(ValueError, match="CFA"):
        write_dng(tmp_path / "a.dng", np.zeros((24, 24), np.uint16), 0, 16383, 1.0, 400, cfa="XYZW")
    with pytest.raises(ValueError, match="exposure"):
        write_dng(tmp_path / "a.dng", np.zeros((24, 24), np.uint16), 0, 16383, 0.0, 400)
    assert not list(tmp_path.iterdir())
