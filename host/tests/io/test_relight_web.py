"""Relight's web format (io.relight_web): what the writer puts in info.json and the planes, read back as
openlime's loader and shader read them (its basis, term order, dequantisation, clamp), in both
layouts; the deep-zoom pyramid written band by band is the pyramid of the whole picture."""
import json

import numpy as np
import pytest
from PIL import Image

from facette.errors import BadInputError
from facette.io import relight_web as web
from facette.io.ptm import ptm_weights
from facette.io.relight_web import openlime_weights, read_relight_web, write_relight_web
from facette.io.rti import hsh_weights


def _image(path):
    with Image.open(path) as im:
        return np.asarray(im, float)


def _smooth_coeffs(h, w, terms, seed=0):
    """(H, W, 3, T) coefficients that vary smoothly across the picture (as a real fit's do)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    base = rng.normal(size=(4, 3, terms)) * 0.3
    c = base[0] + base[1] * xx[..., None, None] + base[2] * yy[..., None, None] \
        + base[3] * np.sin(6 * xx)[..., None, None]
    c[..., 0] += 1.0                                  # a positive constant term: lit
    return c


def _within_jpeg(got, want, span):
    """Dequantised coefficients within what 8 bits and JPEG 95 (4:4:4) keep: half a byte on average,
    a few bytes at most (in each term's own range)."""
    err = np.abs(got - want) / (span / 255.0)
    assert err.mean() < 0.8 and err.max() < 8.0, (err.mean(), err.max())


def _write(tmp_path, coeffs, kind="hsh", layout="image", name="web"):
    h, w, _, t = coeffs.shape
    flat = coeffs.reshape(-1, t)
    lights = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 0.866]])
    info = write_relight_web(tmp_path / name, w, h, kind, lambda r0, r1: coeffs[r0:r1],
                             (flat.min(0), flat.max(0)), lights, layout=layout)
    return info, tmp_path / name


def test_info_json_is_what_openlime_reads(tmp_path):
    coeffs = _smooth_coeffs(40, 60, 9)
    info, folder = _write(tmp_path, coeffs)
    on_disk = json.loads((folder / "info.json").read_text())
    assert on_disk == info
    assert (on_disk["width"], on_disk["height"], on_disk["type"], on_disk["colorspace"]) == (60, 40, "hsh", "rgb")
    assert on_disk["format"] == "jpg" and on_disk["nplanes"] == 27 and len(on_disk["lights"]) == 6
    mat = on_disk["materials"][0]
    assert len(mat["scale"]) == len(mat["bias"]) == 27
    assert sorted(p.name for p in folder.iterdir()) == ["info.json"] + [f"plane_{j}.jpg" for j in range(9)]
    # plane p = 3 t + c: byte 0 stands for the smallest coefficient of term t, 255 for the largest
    lo, hi = coeffs.reshape(-1, 9).min(0), coeffs.reshape(-1, 9).max(0)
    for t in (0, 4):
        for c in range(3):
            p = 3 * t + c
            assert (0 - mat["bias"][p]) * mat["scale"][p] == pytest.approx(lo[t], rel=1e-4, abs=1e-5)
            assert (1 - mat["bias"][p]) * mat["scale"][p] == pytest.approx(hi[t], rel=1e-4, abs=1e-5)


def test_read_back_as_openlime_relights_it(tmp_path):
    coeffs = _smooth_coeffs(40, 60, 9)
    _, folder = _write(tmp_path, coeffs)
    got = read_relight_web(folder)
    assert (got.kind, got.terms, got.width, got.height) == ("hsh", 9, 60, 40)
    span = coeffs.reshape(-1, 9).max(0) - coeffs.reshape(-1, 9).min(0)
    _within_jpeg(got.coeffs, coeffs, span)
    light = np.array([0.3, -0.4, np.sqrt(1 - 0.25)])
    want = np.clip(coeffs @ openlime_weights("hsh", light), 0, 1)
    assert np.abs(got.relight(light) - want).max() < 0.03


def test_openlime_basis_is_rtiviewers_above_its_clamp_and_the_ptm_order():
    el = np.radians(np.array([10.0, 30.0, 60.0, 89.0]))
    az = np.radians(np.array([0.0, 100.0, 200.0, 300.0]))
    d = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    np.testing.assert_allclose(openlime_weights("hsh", d), hsh_weights(d, 9), atol=2e-4)   # its π = 3.1415
    low = np.array([np.cos(0.05), 0.0, np.sin(0.05)])       # 0.05 rad above the horizon: taken at 0.15
    at = np.array([np.cos(0.15), 0.0, np.sin(0.15)])
    np.testing.assert_allclose(openlime_weights("hsh", low), hsh_weights(at, 9), atol=2e-4)
    # PTM: [1, x, y, x², xy, y²], the .ptm file's [x², y², xy, x, y, 1] reordered
    np.testing.assert_allclose(openlime_weights("ptm", d), ptm_weights(d)[:, list(web.PTM_TO_WEB)])


def test_ptm_planes_relight_as_the_polynomial(tmp_path):
    file_order = _smooth_coeffs(20, 30, 6, seed=3)[..., ::-1]      # the constant term last
    info, folder = _write(tmp_path, file_order[..., list(web.PTM_TO_WEB)], kind="ptm")
    assert info["type"] == "ptm" and info["nplanes"] == 18
    got = read_relight_web(folder)
    light = np.array([0.2, 0.3, np.sqrt(1 - 0.13)])
    want = np.clip(file_order @ ptm_weights(light), 0, 1)
    assert np.abs(got.relight(light) - want).mean() < 0.01


@pytest.mark.parametrize("rows", [256, 7])
def test_deep_zoom_pyramid_band_by_band(tmp_path, monkeypatch, rows):
    """600 x 300: levels 0 (150 x 75, one tile), 1 (300 x 150), 2 (600 x 300: 3 x 2 tiles, the edge
    ones cut); fed 7 rows at a time, the same tiles as 256 at a time."""
    monkeypatch.setattr(web, "ROWS", rows)
    coeffs = _smooth_coeffs(300, 600, 4, seed=1)
    info, folder = _write(tmp_path, coeffs, layout="deepzoom")
    dzi = (folder / "plane_0.dzi").read_text()
    assert 'TileSize="256"' in dzi and 'Overlap="0"' in dzi and 'Width="600"' in dzi and 'Height="300"' in dzi
    files = folder / "plane_3_files"
    assert sorted(p.name for p in files.iterdir()) == ["0", "1", "2"]
    sizes = {p.name: _image(p).shape[1::-1] for p in (files / "2").iterdir()}
    assert sizes == {"0_0.jpg": (256, 256), "1_0.jpg": (256, 256), "2_0.jpg": (88, 256),
                     "0_1.jpg": (256, 44), "1_1.jpg": (256, 44), "2_1.jpg": (88, 44)}
    assert _image(files / "0" / "0_0.jpg").shape == (75, 150, 3)
    assert sorted(p.name for p in (files / "1").iterdir()) == ["0_0.jpg", "1_0.jpg"]
    # each level the 2 x 2 means of the one below it
    full, top = _image(files / "1" / "0_0.jpg"), _image(files / "0" / "0_0.jpg")
    halved = (full[0::2, 0::2] + full[1::2, 0::2] + full[0::2, 1::2] + full[1::2, 1::2]) / 4
    assert np.abs(top[:, :128] - halved).mean() < 2.0
    got = read_relight_web(folder)
    _within_jpeg(got.coeffs, coeffs, coeffs.reshape(-1, 4).max(0) - coeffs.reshape(-1, 4).min(0))


def test_a_rewrite_replaces_the_folder_and_bad_input_is_refused(tmp_path):
    coeffs = _smooth_coeffs(20, 20, 9)
    _, folder = _write(tmp_path, coeffs, layout="deepzoom")
    _write(tmp_path, coeffs, layout="image")
    assert not (folder / "plane_0.dzi").exists() and (folder / "plane_0.jpg").is_file()
    assert not (tmp_path / "web.part").exists()
    with pytest.raises(ValueError, match="not written"):
        write_relight_web(tmp_path / "x", 20, 20, "hsh", lambda a, b: coeffs[a:b, ..., :6],
                          (np.zeros(6), np.ones(6)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="finite"):
        write_relight_web(tmp_path / "x", 20, 20, "hsh", lambda a, b: coeffs[a:b],
                          (np.full(9, np.nan), np.ones(9)), np.zeros((1, 3)))
    (tmp_path / "empty").mkdir()
    with pytest.raises(BadInputError, match="info.json"):
        read_relight_web(tmp_path / "empty")
    (folder / "plane_4.jpg").unlink()
    with pytest.raises(BadInputError, match="plane_4"):
        read_relight_web(folder)


def test_reading_bad_folders_says_what_is_wrong_with_a_hint(tmp_path):
    """A missing tile, a JPEG cut short, an info.json without its materials: BadInputError with a hint,
    never PIL's or json's own exception."""
    coeffs = _smooth_coeffs(300, 280, 4, seed=2)
    _, folder = _write(tmp_path, coeffs, layout="deepzoom")
    tile = folder / "plane_2_files" / "1" / "1_0.jpg"
    data = tile.read_bytes()
    tile.write_bytes(data[:len(data) // 3])
    with pytest.raises(BadInputError, match="plane 2's tile 1_0 is not a readable JPEG") as err:
        read_relight_web(folder)
    assert "cut short" in err.value.hint
    tile.unlink()
    with pytest.raises(BadInputError, match="tile 1_0 is missing") as err:
        read_relight_web(folder)
    assert "relight-web" in err.value.hint
    _, flat = _write(tmp_path, coeffs[:20, :20], name="flat")
    (flat / "plane_1.jpg").write_bytes((flat / "plane_1.jpg").read_bytes()[:200])
    with pytest.raises(BadInputError, match="plane 1 is not a readable JPEG"):
        read_relight_web(flat)
    info = json.loads((flat / "info.json").read_text())
    del info["materials"]
    (flat / "info.json").write_text(json.dumps(info))
    with pytest.raises(BadInputError, match="materials"):
        read_relight_web(flat)
    with pytest.raises(BadInputError, match="not a folder"):
        read_relight_web(flat / "info.json")


def test_relit_band_by_band_is_the_coefficients_relit_whole(tmp_path, monkeypatch):
    """The reader holds the planes' bytes (one per coefficient) and relights a band of rows at a time:
    the same picture as the dequantised coefficients times openlime's weights, clipped."""
    monkeypatch.setattr(web, "BAND_ROWS", 7)
    coeffs = _smooth_coeffs(30, 26, 9, seed=3)
    _, folder = _write(tmp_path, coeffs)
    got = read_relight_web(folder)
    assert got.planes.dtype == np.uint8 and got.planes.shape == (9, 30, 26, 3)
    light = np.array([0.4, -0.3, np.sqrt(1 - 0.25)])
    whole = np.clip(got.coeffs @ openlime_weights("hsh", light), 0, 1)
    np.testing.assert_allclose(got.relight(light), whole, atol=1e-5)     # float32, as the shader
