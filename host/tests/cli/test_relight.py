"""cli relight: a .ptm or .rti file rendered under a light, as the viewers show it."""
import numpy as np
import pytest

from facette.cli.main import main
from facette.io.png import read_png
from facette.io.ptm import write_ptm_lrgb
from facette.io.rti import write_hsh_rti


def test_relight_writes_the_picture_of_a_ptm_and_an_rti(tmp_path, capsys, unchanged):
    h, w = 6, 10
    coeffs = np.zeros((h, w, 6))
    coeffs[..., 3] = 0.5                         # brighter towards +x (lu)
    coeffs[..., 5] = 0.5
    write_ptm_lrgb(tmp_path / "a.ptm", coeffs, np.ones((h, w, 3)))
    assert main(["relight", str(tmp_path / "a.ptm"), "--light", "0,30", "-o", str(tmp_path / "a.png")]) == 0
    right = read_png(tmp_path / "a.png")
    main(["relight", str(tmp_path / "a.ptm"), "--light", "180,30", "-o", str(tmp_path / "b.png")])
    left = read_png(tmp_path / "b.png")
    assert right.shape == (h, w, 3) and right.mean() > left.mean() + 50     # 0.5 ± 0.43 of 255
    hsh = np.zeros((h, w, 3, 4))
    hsh[..., 0] = 0.5 * np.sqrt(2 * np.pi)       # the constant term: 0.5 everywhere
    write_hsh_rti(tmp_path / "c.rti", hsh, ["encoding: srgb"])
    assert main(["relight", str(tmp_path / "c.rti"), "-o", str(tmp_path / "c.png")]) == 0
    assert abs(int(read_png(tmp_path / "c.png").mean()) - 128) <= 1
    assert "HSH 4 terms" in capsys.readouterr().out


def test_relight_refuses_what_it_cannot_read(tmp_path, capsys, unchanged):
    (tmp_path / "x.rti").write_bytes(b"hello")
    with unchanged(tmp_path):
        assert _run(capsys, "relight", tmp_path / "none.ptm")[0] == 2
        assert _run(capsys, "relight", tmp_path / "x.rti", "--light", "up")[0] == 2
        code, said = _run(capsys, "relight", tmp_path / "x.rti")
    assert code == 2 and "neither a PTM nor an HSH" in said


def _ptm(tmp_path):
    coeffs = np.zeros((4, 5, 6))
    coeffs[..., 5] = 0.5
    write_ptm_lrgb(tmp_path / "a.ptm", coeffs, np.ones((4, 5, 3)))
    return tmp_path / "a.ptm"


def _run(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:             # argparse refuses before anything runs
        code = exc.code
    out, err = capsys.readouterr()
    return code, out + err


def test_relight_never_writes_its_input_nor_a_file_it_did_not_make(tmp_path, capsys, unchanged):
    ptm = _ptm(tmp_path)
    user = tmp_path / "mine.png"
    user.write_bytes(b"\x89PNG\r\n\x1a\n a user's picture")
    with unchanged(ptm, user):
        code, said = _run(capsys, "relight", ptm, "-o", ptm)
        assert code == 2 and "is the input" in said and "never writes its inputs" in said
        code, said = _run(capsys, "relight", ptm, "-o", ptm, "--overwrite")      # not even with --overwrite
        assert code == 2
        code, said = _run(capsys, "relight", ptm, "-o", user)
        assert code == 2 and "facette did not make it" in said and "--overwrite" in said
    with unchanged(ptm):                   # the hint followed: --overwrite replaces the user's picture
        assert _run(capsys, "relight", ptm, "-o", user, "--overwrite")[0] == 0
        assert read_png(user).shape == (4, 5, 3)
        assert _run(capsys, "relight", ptm)[0] == 0                        # a.png, made here
        assert _run(capsys, "relight", ptm, "--light", "90,20")[0] == 0     # its own picture: replaced
        assert _run(capsys, "relight", ptm, "-o", tmp_path)[0] == 2         # a folder


def test_the_input_as_output_hint_names_a_file_that_works(tmp_path, capsys, unchanged):
    ptm = _ptm(tmp_path)
    with unchanged(ptm):
        code, said = _run(capsys, "relight", ptm, "-o", ptm)
        hinted = said.split("e.g. ")[1].split()[0]
        assert _run(capsys, "relight", ptm, "-o", hinted)[0] == 0
    assert read_png(hinted).shape == (4, 5, 3)


@pytest.mark.parametrize("light, words", [("0,-10", "outside [0, 90]"), ("0,100", "outside [0, 90]"),
                                          ("nan,20", "finite"), ("0,inf", "finite"), ("10", "not AZ,EL"),
                                          ("a,b", "not AZ,EL")])
def test_a_light_that_cannot_be_is_refused_before_any_work(tmp_path, capsys, unchanged, light, words):
    ptm = _ptm(tmp_path)
    with unchanged(tmp_path):
        code, said = _run(capsys, "relight", ptm, "--light", light)
    assert code == 2 and words in said


def test_the_hinted_elevation_renders(tmp_path, capsys, unchanged):
    ptm = _ptm(tmp_path)
    said = _run(capsys, "relight", ptm, "--light", "30,-10")[1]
    hinted = said.split("e.g. ")[1].split()[0]
    assert hinted == "30,10"
    assert _run(capsys, "relight", ptm, "--light", hinted)[0] == 0


@pytest.mark.parametrize("name", ["x.jpg", "x.tif", "x"])
def test_an_output_that_is_not_a_png_is_refused_with_the_png_to_give(tmp_path, capsys, unchanged, name):
    ptm = _ptm(tmp_path)
    with unchanged(tmp_path):
        code, said = _run(capsys, "relight", ptm, "-o", tmp_path / name)
    assert code == 2 and "writes PNG pictures" in said
    hinted = said.split("-o ")[-1].split()[0]
    assert _run(capsys, "relight", ptm, "-o", hinted)[0] == 0 and hinted.endswith(".png")


@pytest.mark.parametrize("header, words", [
    (b"#HSH1.2\n3\n10 x 3\n2 0 1\n", "line 3"), (b"#HSH1.2\n#c\n3\n10 10\n4 0 1\n", "line 4"),
    (b"#HSH1.2\n3\n10 10 3\n", "ends early"), (b"#HSH1.2\n3\n2 2 3\n4 0 1\n\x00\x00", "ends in the scale")])
def test_a_bad_rti_header_names_the_file_and_line(tmp_path, capsys, unchanged, header, words):
    (tmp_path / "x.rti").write_bytes(header)
    with unchanged(tmp_path):
        code, said = _run(capsys, "relight", tmp_path / "x.rti")
    assert code == 2 and words in said and "x.rti" in said, said
