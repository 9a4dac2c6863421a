"""facette.io.lights: the checks every capture's lights pass, whoever read them."""
import numpy as np
import pytest

from facette.errors import BadInputError
from facette.io.lights import check_lights, photograph_paths


def _ring(m=8, el_deg=40.0):
    az = np.radians(np.arange(m) * 360.0 / m)
    el = np.radians(el_deg)
    return np.c_[np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), np.full(m, np.cos(el))]


def test_lights_below_the_horizon_are_left_out_and_named():
    dirs = _ring()
    dirs[[2, 5], 2] *= -1
    keep, notes = check_lights(dirs, "x.lp", [f"p{k}.jpg" for k in range(8)])
    assert keep.tolist() == [0, 1, 3, 4, 6, 7]
    assert notes == ["x.lp: 2 light(s) below the horizon (z < 0; p2.jpg, p5.jpg) left out: they cannot light "
                     "a surface the camera sees"]
    with pytest.raises(BadInputError, match="every light has z < 0") as err:
        check_lights(-_ring(), "x.lp")
    assert "flip the sign of z" in err.value.hint


def test_shared_directions_are_kept_and_said_degenerate_ones_refused():
    dirs = np.vstack([_ring(), _ring()[:2]])           # two photographs repeated under their lights
    keep, notes = check_lights(dirs, "light_directions.txt")
    assert len(keep) == 10
    assert notes == ["light_directions.txt: 2 light(s) share a direction with another (within 0.5°: line 1 = line 9, "
                     "line 2 = line 10): kept, as repeated photographs"]
    with pytest.raises(BadInputError, match="the 6 lights all share one direction"):
        check_lights(np.tile([0.1, 0.2, 0.97], (6, 1)), "a.lp")
    with pytest.raises(BadInputError, match="the 6 lights give 2 distinct direction"):
        check_lights(np.vstack([np.tile([0.1, 0.2, 0.97], (3, 1)), np.tile([-0.3, 0.0, 0.95], (3, 1))]), "a.lp")
    column = np.c_[np.zeros(6), np.linspace(-0.5, 0.5, 6), np.ones(6)]
    with pytest.raises(BadInputError, match="the 6 lights lie in one plane through the object"):
        check_lights(column, "a.lp")
    with pytest.raises(BadInputError, match="no direction"):
        check_lights(np.vstack([_ring(), [np.nan, 0, 1]]), "a.lp")


def test_notes_hold_no_nan():
    dirs = _ring(12)
    dirs[0, 2] = -1e-9
    for note in check_lights(dirs, "x.lp")[1]:
        assert "nan" not in note.lower()


def test_photographs_listed_twice_or_outside_the_folder(tmp_path):
    cap, other = tmp_path / "cap", tmp_path / "other"
    for d in (cap, other):
        d.mkdir()
        for k in range(3):
            (d / f"p{k}.jpg").write_bytes(b"x")
    (other / "only_there.jpg").write_bytes(b"x")
    paths, notes = photograph_paths(cap, ["p0.jpg", "p1.jpg", "p2.jpg"], "c.lp")
    assert paths == [cap / "p0.jpg", cap / "p1.jpg", cap / "p2.jpg"] and notes == []
    with pytest.raises(BadInputError, match=r"c.lp: p1.jpg is listed 2 times \(lines 3, 4\)"):
        photograph_paths(cap, ["p0.jpg", "p1.jpg", "p1.jpg"], "c.lp")
    # absolute paths (RTIBuilder's, or another capture's on this machine): this folder's files, said
    paths, notes = photograph_paths(cap, [str(other / f"p{k}.jpg") for k in range(3)], "c.lp")
    assert paths == [cap / "p0.jpg", cap / "p1.jpg", cap / "p2.jpg"]
    assert notes == [f"c.lp names 3 photograph(s) outside the capture's folder (as {other / 'p0.jpg'}): read "
                     f"from {cap}, by their file names"]
    paths, _ = photograph_paths(cap, ["C:\\captures\\x\\p0.jpg", "../other/p1.jpg", "p2.jpg"], "c.lp")
    assert paths == [cap / "p0.jpg", cap / "p1.jpg", cap / "p2.jpg"]
    with pytest.raises(BadInputError, match="only_there.jpg is not in") as err:     # never another folder's file
        photograph_paths(cap, ["p0.jpg", "p1.jpg", str(other / "only_there.jpg")], "c.lp")
    assert "reads a capture's own folder only" in str(err.value)
    with pytest.raises(BadInputError, match="line 1: nothere.jpg"):
        photograph_paths(cap, ["nothere.jpg"], "filenames.txt", first_line=1)
