import numpy as np
import pytest

from facette.calib import Lights, Profile, nominal_light_directions
from facette.calib.lp import lights_from_lp, read_lp, write_lp, write_profile_lp


def test_round_trip(tmp_path):
    d = nominal_light_directions()
    names = [f"raw/L{i:02d}_E00.dng" for i in range(12)]
    p = write_lp(tmp_path / "lights.lp", names, d)
    lines = p.read_text().splitlines()
    assert lines[0] == "12" and lines[1].startswith("raw/L00_E00.dng ")
    n2, d2 = read_lp(p)
    assert n2 == names
    np.testing.assert_allclose(d2, d, atol=1e-9)


def test_reads_rtibuilder_style_files_with_spaces_and_positions(tmp_path):
    p = tmp_path / "dome.lp"
    p.write_text("3\nimg 01.jpg 0 0 2\r\nimg02.jpg\t-0.5 0.5 0.7071\n\nimg03.jpg 1e-1 0 0.99\n")
    names, v = read_lp(p)
    assert names == ["img 01.jpg", "img02.jpg", "img03.jpg"]
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1)
    np.testing.assert_allclose(v[0], [0, 0, 1])
    _, raw = read_lp(p, normalize=False)
    assert raw[0, 2] == 2.0


@pytest.mark.parametrize("text, match", [
    ("", "empty"),
    ("two\na 0 0 1\n", "number of lights"),
    ("2\na 0 0 1\n", "announces 2 lights but lists 1"),
    ("1\na 0 x 1\n", "line 2"),
    ("1\na 0 0 0\n", "non-zero"),
    ("1\na 0 nan 1\n", "finite"),
])
def test_malformed_files_name_the_problem(tmp_path, text, match):
    p = tmp_path / "bad.lp"
    p.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_lp(p)


def test_write_refuses_mismatched_lengths(tmp_path):
    with pytest.raises(ValueError, match="one \\(x, y, z\\) per file name"):
        write_lp(tmp_path / "x.lp", ["a", "b"], np.zeros((3, 3)))


def test_profile_directions_round_trip_through_lp(tmp_path):
    p = Profile(rig="x", lights=Lights(nominal_light_directions(), np.ones((12, 3))))
    path = write_profile_lp(p, tmp_path / "lights.lp")
    lights, names = lights_from_lp(path)
    assert names[3] == "hdr/light_03.exr"
    np.testing.assert_allclose(lights.directions, p.lights.directions, atol=1e-9)
