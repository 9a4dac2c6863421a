"""An RTI capture's bad input (issues 48, 51): its lights checked as a DiLiGenT folder's, its
encoding read per photograph, an .lp that disagrees with itself or its folder refused with a hint."""
import cv2
import numpy as np
import pytest
import tifffile

from facette.calib.lp import write_lp
from facette.capture import load_input
from facette.capture.rti import srgb_to_linear
from facette.errors import BadInputError
from facette.pipeline import process

H, W = 24, 32


def _lights(m=8):
    az = np.radians(np.arange(m) * 360.0 / m)
    el = np.radians(np.tile([20.0, 45.0], m // 2))
    return np.c_[np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), np.cos(el)]


def _jpegs(folder, m=8, size=(H, W), first=0):
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(first)
    names = []
    for k in range(first, first + m):
        names.append(f"IMG_{k:03d}.jpg")
        cv2.imwrite(str(folder / names[-1]), rng.integers(40, 200, size + (3,)).astype(np.uint8))
    return names


def test_lights_below_the_horizon_and_photographs_listed_twice(tmp_path):
    names = _jpegs(tmp_path / "a")
    dirs = _lights()
    dirs[3, 2] *= -1
    write_lp(tmp_path / "a" / "a.lp", names, dirs)
    inp = load_input(tmp_path / "a")
    assert len(inp.light_dirs) == 7 and inp.images.shape[0] == 7
    assert any("1 light(s) below the horizon (z < 0; IMG_003.jpg) left out" in n for n in inp.notes)
    write_lp(tmp_path / "a" / "a.lp", names, -_lights())               # every z negated: another frame
    with pytest.raises(BadInputError, match="every light has z < 0"):
        load_input(tmp_path / "a")
    write_lp(tmp_path / "a" / "a.lp", names[:7] + names[:1], _lights())
    with pytest.raises(BadInputError, match="IMG_000.jpg is listed 2 times"):
        load_input(tmp_path / "a")
    write_lp(tmp_path / "a" / "a.lp", names, np.tile([0.0, 0.0, 1.0], (8, 1)))
    with pytest.raises(BadInputError, match="all share one direction"):
        load_input(tmp_path / "a")


def test_absolute_paths_read_this_captures_photographs_never_anothers(tmp_path):
    ours, theirs = _jpegs(tmp_path / "ours"), _jpegs(tmp_path / "theirs", first=100)
    for k, n in enumerate(theirs):                  # the other capture holds files of our names too
        (tmp_path / "theirs" / ours[k]).write_bytes((tmp_path / "theirs" / n).read_bytes())
    write_lp(tmp_path / "ours" / "c.lp", [str(tmp_path / "theirs" / n) for n in ours], _lights())
    inp = load_input(tmp_path / "ours")
    ref = cv2.imread(str(tmp_path / "ours" / ours[0]))[..., ::-1]
    theirs0 = cv2.imread(str(tmp_path / "theirs" / ours[0]))[..., ::-1]
    assert not np.array_equal(ref, theirs0)
    lut = srgb_to_linear(np.arange(256) / 255.0)
    np.testing.assert_array_equal(inp.images[0], lut[ref])            # our photograph, not theirs
    assert any(f"read from {tmp_path / 'ours'}" in n for n in inp.notes)


def test_mixed_bit_depths_are_refused_with_the_list(tmp_path):
    names = _jpegs(tmp_path / "m")
    tif = "IMG_003.tif"
    (tmp_path / "m" / names[3]).unlink()
    tifffile.imwrite(tmp_path / "m" / tif, np.full((H, W, 3), 30000, np.uint16), photometric="rgb")
    names[3] = tif
    write_lp(tmp_path / "m" / "m.lp", names, _lights())
    with pytest.raises(BadInputError, match=r"mix bit depths \(8-bit: IMG_000.jpg.*\(7\); 16-bit: IMG_003.tif \(1\)\)") as err:
        load_input(tmp_path / "m")
    assert "export every photograph" in err.value.hint


def test_an_lp_that_disagrees_with_itself_or_its_folder(tmp_path):
    names = _jpegs(tmp_path / "c")
    lp = tmp_path / "c" / "c.lp"
    write_lp(lp, names, _lights())
    lines = lp.read_text().splitlines()
    lp.write_text("\n".join(["9"] + lines[1:]) + "\n")                  # count and rows disagree
    with pytest.raises(BadInputError, match="announces 9 lights but lists 8") as err:
        load_input(tmp_path / "c")
    assert "the count" in err.value.hint
    write_lp(lp, names[:7] + ["IMG_999.jpg"], _lights())                # a listed photograph missing
    with pytest.raises(BadInputError, match="line 9: IMG_999.jpg is not in") as err:
        load_input(tmp_path / "c")
    assert err.value.hint
    _jpegs(tmp_path / "c", m=1, size=(H + 2, W), first=7)               # photographs of two sizes
    write_lp(lp, names, _lights())
    with pytest.raises(BadInputError, match="IMG_007.jpg is 32x26 px, IMG_000.jpg is 32x24") as err:
        process(tmp_path / "c", outputs=["normals"], method="woodham1980")
    assert "same size" in err.value.hint


def test_a_diligent_folder_listing_a_photograph_twice(tmp_path):
    from facette.io.diligent import write_diligent
    write_diligent(tmp_path / "d", np.full((8, H, W, 3), 20000, np.uint16), _lights())
    names = (tmp_path / "d" / "filenames.txt").read_text().split()
    (tmp_path / "d" / "filenames.txt").write_text("\n".join(names[:7] + names[:1]) + "\n")
    with pytest.raises(BadInputError, match="is listed 2 times"):
        load_input(tmp_path / "d")
