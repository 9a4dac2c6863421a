"""cli relight: a .ptm or .rti file rendered under a light, as the viewers show it."""
import numpy as np
import pytest

from facette.cli.main import main
from facette.io.png import read_png
from facette.io.ptm import write_ptm_lrgb
from facette.io.rti import write_hsh_rti

from . import run_cli_joined as _run


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


def _web_folder(tmp_path, layout):
    from facette.io.relight_web import write_relight_web
    h, w = 300, 270                              # deep zoom: 2 x 2 tiles at full size, 2 levels
    yy, xx = np.mgrid[0:h, 0:w] / 300.0
    coeffs = np.zeros((h, w, 3, 9))
    coeffs[..., 0] = 0.6 + 0.2 * np.sin(5 * xx)[..., None]
    coeffs[..., 3] = 0.3 * yy[..., None]         # an HSH term that follows the light's x
    flat = coeffs.reshape(-1, 9)
    write_relight_web(tmp_path / "web", w, h, "hsh", lambda a, b: coeffs[a:b], (flat.min(0), flat.max(0)),
                      np.array([[0.0, 0.0, 1.0]]), layout=layout)
    return tmp_path / "web"


@pytest.mark.parametrize("layout", ["deepzoom", "image"])
def test_relight_opens_a_web_folder_as_openlime_shows_it(tmp_path, capsys, unchanged, layout):
    from facette.io.relight_web import read_relight_web
    folder = _web_folder(tmp_path, layout)
    with unchanged(folder):
        assert main(["relight", str(folder), "--light", "30,40"]) == 0
    got = read_png(tmp_path / "web.png")                   # beside the folder, never inside it
    d = np.array([np.cos(np.radians(40)) * np.cos(np.radians(30)), np.cos(np.radians(40)) * np.sin(np.radians(30)),
                  np.sin(np.radians(40))])
    np.testing.assert_array_equal(got, np.round(read_relight_web(folder).relight(d) * 255))
    assert got.shape == (300, 270, 3) and got.std() > 5
    assert ("deep zoom" if layout == "deepzoom" else "one JPEG per plane") in capsys.readouterr().out


def test_relight_refuses_broken_web_folders_with_a_hint(tmp_path, capsys, unchanged):
    folder = _web_folder(tmp_path, "deepzoom")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "relight_web").symlink_to(folder)
    with unchanged(tmp_path):
        code, said = _run(capsys, "relight", tmp_path / "out")       # process's folder, not the web one
        assert code == 2 and "without info.json" in said and str(tmp_path / "out" / "relight_web") in said
        code, said = _run(capsys, "relight", folder, "-o", folder / "x.png")
        assert code == 2 and "inside the folder" in said
    tile = folder / "plane_5_files" / "1" / "0_1.jpg"
    tile.write_bytes(tile.read_bytes()[:300])
    with unchanged(tmp_path):
        code, said = _run(capsys, "relight", folder)
    assert code == 2 and "plane 5's tile 0_1 is not a readable JPEG" in said and "cut short" in said
    tile.unlink()
    code, said = _run(capsys, "relight", folder)
    assert code == 2 and "tile 0_1 is missing" in said
    assert not (tmp_path / "web.png").exists()


def test_relight_at_a_captured_light_of_what_process_wrote(tmp_path, capsys):
    """`process --outputs relight-web,relight` on a JPEG capture: the web folder and relight_model.npz,
    relit at a captured light, are the readers' own pictures, and that photograph within a few levels."""
    import sys
    from pathlib import Path

    from facette.io.relight_web import read_relight_web
    from facette.recon import load_relight_model
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "pipeline"))
    from test_rti_exposure import _jpeg_capture
    from test_rti_capture import _lights

    photos = _jpeg_capture(tmp_path / "cap")
    out = tmp_path / "o"
    assert main(["process", str(tmp_path / "cap"), "-o", str(out), "--outputs", "relight-web,relight",
                 "--method", "woodham1980", "--shadows", "off"]) == 0
    web, model = read_relight_web(out / "relight_web"), load_relight_model(out / "relight_model.npz")
    for k in (2, 5, 11):
        d = _lights()[k]
        light = f"{np.degrees(np.arctan2(d[1], d[0]))},{np.degrees(np.arcsin(d[2]))}"
        for src, reader, most in ((out / "relight_web", web.relight, 7.0), (out / "relight_model.npz", model.display,
                                                                               6.0)):
            assert main(["relight", str(src), f"--light={light}", "-o", str(tmp_path / "lit.png")]) == 0
            got = read_png(tmp_path / "lit.png")
            np.testing.assert_array_equal(got, np.round(reader(d) * 255))
            err = np.abs(got.astype(float) - photos[k])[model.mask].mean()
            assert err < most, (src.name, k, err)
    assert "relighting model" in capsys.readouterr().out
