"""facette.capture.rti: RTI capture folders (photographs + .lp, or a mirror sphere in
view) as the input of `process`, built here from rendered scenes."""
import os

import cv2
import numpy as np
import pytest
import tifffile

from facette.calib import nominal_light_directions
from facette.calib.lp import read_lp, write_lp
from facette.calib.targets import render_mirror_sphere
from facette.cli.main import main
from facette.errors import BadInputError
from facette.io.diligent import write_diligent
from facette.pipeline import load_input, process
from facette.capture.rti import srgb_to_linear
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane

H, W = 72, 96


def _lights():
    """16 lights, 10–60° from the axis, all around."""
    az = np.radians(np.arange(16) * 22.5)
    el = np.radians(np.tile([10.0, 25.0, 45.0, 60.0], 4))
    return np.c_[np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), np.cos(el)]


def _scene_images(lights=None):
    sc = sphere_on_plane(H, W, radius=26)
    imgs = render(sc, _lights() if lights is None else lights, "matte", albedo=(0.7, 0.6, 0.5),
                  cast_shadows=False)
    return sc, np.clip(imgs / imgs.max() * 0.9, 0, 1)


def _linear_to_srgb(v):
    v = np.clip(v, 0, 1)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def _write(folder, imgs, kind):
    """Write photographs as 16-bit PNG (linear), 16-bit TIFF (linear) or JPEG (8-bit sRGB);
    returns the file names."""
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for i, im in enumerate(imgs):
        if kind == "png16":
            name = f"img_{i:03d}.png"
            cv2.imwrite(str(folder / name), np.round(im[..., ::-1] * 65535).astype(np.uint16))
        elif kind == "tif16":
            name = f"img_{i:03d}.tif"
            tifffile.imwrite(folder / name, np.round(im * 65535).astype(np.uint16), photometric="rgb")
        else:
            name = f"IMG_{i:03d}.jpg"
            cv2.imwrite(str(folder / name), np.round(_linear_to_srgb(im)[..., ::-1] * 255).astype(np.uint8),
                        [cv2.IMWRITE_JPEG_QUALITY, 97])
        names.append(name)
    return names


def _capture(folder, kind, lp=True):
    sc, imgs = _scene_images()
    names = _write(folder, imgs, kind)
    if lp:
        write_lp(folder / "capture.lp", names, _lights())
    return sc


def _err(res, sc):
    """Angles to the truth where every light reaches the surface (least squares ignores no shadow)."""
    m = res.mask & sc.sphere & np.all(sc.normals @ _lights().T > 0.05, axis=-1)
    return angular_error_deg(res.normals, sc.normals, m)


def test_png_capture_gives_the_normals_of_the_same_photographs_as_a_diligent_folder(tmp_path):
    sc = _capture(tmp_path / "rti", "png16")
    _, imgs = _scene_images()
    write_diligent(tmp_path / "dil", np.round(imgs * 65535).astype(np.uint16), _lights())
    a = process(tmp_path / "rti", outputs=["normals"], method="woodham1980")
    b = process(tmp_path / "dil", outputs=["normals"], method="woodham1980")
    assert a.inputs.kind == "rti"
    m = a.mask & b.mask & sc.sphere
    assert np.degrees(np.arccos(np.clip(np.sum(a.normals[m] * b.normals[m], -1), -1, 1))).max() < 0.1
    assert np.mean(_err(a, sc)) < 0.5
    assert any("16-bit photographs read as linear" in n for n in a.notes)


def test_tiff_and_jpeg_captures_agree_with_the_png_one(tmp_path):
    sc = _capture(tmp_path / "png", "png16")
    _capture(tmp_path / "tif", "tif16")
    _capture(tmp_path / "jpg", "jpg")
    png = process(tmp_path / "png", outputs=["normals"], method="woodham1980")
    tif = process(tmp_path / "tif", outputs=["normals"], method="woodham1980")
    jpg = process(tmp_path / "jpg", outputs=["normals"], method="woodham1980")
    wrong = process(tmp_path / "jpg", outputs=["normals"], method="woodham1980", capture={"encoding": "linear"})
    m = png.mask & tif.mask & jpg.mask & sc.sphere
    assert angular_error_deg(tif.normals, png.normals, m).max() < 0.1
    # 8-bit sRGB JPEG, decoded as sRGB (the default for 8 bits): within a degree on average
    assert angular_error_deg(jpg.normals, png.normals, m).mean() < 1.0
    assert any("8-bit photographs read as srgb" in n for n in jpg.notes)
    # read as linear, the same files give shading that is too flat: the normals bend
    assert angular_error_deg(wrong.normals, png.normals, m).mean() > 3 * angular_error_deg(jpg.normals, png.normals, m).mean()


def test_srgb_decoding_matches_the_standard():
    v = np.array([0.0, 0.04045, 0.5, 1.0])
    np.testing.assert_allclose(srgb_to_linear(v), [0.0, 0.04045 / 12.92, 0.21404, 1.0], rtol=1e-4)


def test_clipped_values_are_unknown_and_intensities_beside_the_lp_divide(tmp_path):
    _, imgs = _scene_images()
    imgs[0, :4, :4] = 1.0                     # clipped corner in the first photograph
    names = _write(tmp_path, imgs, "png16")
    write_lp(tmp_path / "c.lp", names, _lights())
    inten = np.linspace(0.5, 2.0, len(names))[:, None] * np.ones(3)
    np.savetxt(tmp_path / "light_intensities.txt", inten)
    inp = load_input(tmp_path)
    assert np.isnan(inp.images[0, 0, 0]).all()
    k = len(names) - 1
    np.testing.assert_allclose(inp.images[k, 40, 40], np.round(imgs[k, 40, 40] * 65535) / 65535 / 2.0, rtol=1e-5)


def _sphere_capture(folder, lights, kind="jpg"):
    """An object (the hemisphere) with a chrome ball on a dark background in the top-left corner."""
    h, w = 120, 180
    sc = sphere_on_plane(h, w, radius=30)             # the object: x from 60 px
    obj = render(sc, lights, "matte", albedo=(0.6, 0.6, 0.6), cast_shadows=False)
    rows, cols = np.mgrid[0:h, 0:w]
    cloth = (rows < 52) & (cols < 52)                 # a square of black velvet under the ball
    o = (np.arange(4) + 0.5) / 4 - 0.5
    cover = np.mean([np.hypot(cols + dx - 26.0, rows + dy - 26.0) < 20.0 for dy in o for dx in o], axis=0)
    imgs = []
    for k, d in enumerate(lights):
        sphere = render_mirror_sphere((h, w), (26.0, 26.0), 20.0, 0.2, direction=d, source_radius_deg=1.5,
                                      psf_px=1.0, supersample=4, backdrop_albedo=0.0)
        # the ball mirrors a dim room (4 % grey) besides the lamp; the velvet is near black
        img = np.where(cloth[..., None], 0.004 + 0.04 * cover[..., None] + sphere, obj[k] * 0.8)
        imgs.append(np.clip(img, 0, 1))
    names = _write(folder, np.array(imgs), kind)
    return sc, names


def _relight_reads(lp_path, folder):
    """What Relight's loader (relight/src/imageset.cpp parseLP and initFromFolder) asks of an .lp
    in a folder of JPEGs: the first line an integer 1..1000 alone, then exactly that many lines of
    4 whitespace-separated fields, a non-zero vector; the .jpg files of the folder, in name
    order with case ignored, as many as the lights. Returns the unit directions it would use."""
    lines = lp_path.read_text().split("\n")
    n = int(lines[0])                         # QString::toInt on the whole line
    assert 0 < n <= 1000
    dirs = []
    for line in lines[1:n + 1]:
        tokens = line.split()
        assert len(tokens) == 4, line
        v = np.array([float(t) for t in tokens[1:]])
        assert np.linalg.norm(v) >= 1e-4
        dirs.append(v / np.linalg.norm(v))
    jpgs = sorted((p.name for p in folder.iterdir() if p.suffix in (".jpg", ".JPG")), key=str.lower)
    assert len(jpgs) == n
    return jpgs, np.array(dirs)


def test_capture_without_lp_takes_its_lights_from_the_sphere_and_writes_the_lp_beside_the_results(tmp_path):
    lights = nominal_light_directions()
    sc, names = _sphere_capture(tmp_path / "cap", lights)
    before = sorted((p.name, p.stat().st_mtime_ns) for p in (tmp_path / "cap").iterdir())
    out = tmp_path / "out"
    res = process(tmp_path / "cap", outputs=["normals", "mask"], out_dir=out, method="woodham1980")
    assert angular_error_deg(res.inputs.light_dirs, lights).max() < 1.0
    assert any("mirror sphere (found" in n for n in res.notes)
    # the input folder is read only; the .lp is among the results
    assert sorted((p.name, p.stat().st_mtime_ns) for p in (tmp_path / "cap").iterdir()) == before
    lp = out / "lights.lp"
    assert lp.is_file() and "lp" in res.files
    lp_names, lp_dirs = read_lp(lp)
    assert lp_names == names
    # Relight loads it beside the photographs: their order and its lights agree
    (tmp_path / "cap2").mkdir()
    for n in names:
        os.symlink(tmp_path / "cap" / n, tmp_path / "cap2" / n)
    (tmp_path / "cap2" / "lights.lp").write_bytes(lp.read_bytes())
    jpgs, rel_dirs = _relight_reads(tmp_path / "cap2" / "lights.lp", tmp_path / "cap2")
    assert jpgs == names
    np.testing.assert_allclose(rel_dirs, lp_dirs, atol=1e-6)
    # the sphere is not the object; the object's normals are right
    assert not res.mask[26, 26]
    m = res.mask & sc.sphere & np.all(sc.normals @ lights.T > 0.05, axis=-1)
    assert angular_error_deg(res.normals, sc.normals, m).mean() < 1.0


def test_sphere_given_as_a_circle_on_the_command_line(tmp_path):
    lights = nominal_light_directions()
    _sphere_capture(tmp_path / "cap", lights)
    out = tmp_path / "out"
    assert main(["process", str(tmp_path / "cap"), "-o", str(out), "--outputs", "normals",
                 "--sphere", "26,26,20", "--encoding", "srgb"]) == 0
    _, dirs = read_lp(out / "lights.lp")
    assert angular_error_deg(dirs, lights).max() < 1.0
    assert main(["process", str(tmp_path / "cap"), "-o", str(tmp_path / "o2"), "--sphere", "26,26"]) == 2


def test_bad_captures_are_refused_with_the_file_named(tmp_path):
    _capture(tmp_path / "a", "png16")
    write_lp(tmp_path / "a" / "second.lp", ["img_000.png"], [[0, 0, 1]])
    with pytest.raises(BadInputError, match="2 .lp files"):
        load_input(tmp_path / "a")
    _capture(tmp_path / "b", "png16", lp=False)
    write_lp(tmp_path / "b" / "c.lp", ["img_000.png", "nothere.png", "img_002.png"], np.eye(3))
    with pytest.raises(BadInputError, match="line 3: nothere.png"):
        load_input(tmp_path / "b")
    _capture(tmp_path / "c", "png16", lp=False)        # no .lp and no sphere in view
    with pytest.raises(BadInputError, match="no .lp file"):
        load_input(tmp_path / "c")


def test_lp_positions_and_rtibuilder_absolute_paths(tmp_path):
    sc, imgs = _scene_images()
    names = _write(tmp_path, imgs, "png16")
    # RTIBuilder writes the path of the machine it ran on; a dome writes positions
    write_lp(tmp_path / "dome.lp", [f"C:\\captures\\x\\{n}" for n in names], 300.0 * _lights())
    res = process(tmp_path, outputs=["normals"], method="woodham1980")
    assert any("positions" in n for n in res.notes)
    assert np.mean(_err(res, sc)) < 0.5


def test_write_lp_refuses_what_relight_cannot_read(tmp_path):
    with pytest.raises(ValueError, match="no spaces"):
        write_lp(tmp_path / "x.lp", ["a b.jpg"], [[0, 0, 1]])
