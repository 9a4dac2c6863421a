"""relight.ptm, relight.rti and relight_web as photographed (pipeline._rti_exposure): relit at a captured
light, as RTIViewer and openlime read them, they give that photograph (its scale, encoding and
clipping), with no photometric stereo run; an HDR scan's files at the exposure that clips <= 0.1 %
of the object, said in the header and process.json; the exposure over bands is the untiled one."""
import json

import cv2
import numpy as np
import pytest

from facette.calib.lp import write_lp
from facette.cli.main import main
from facette.io.ptm import read_ptm
from facette.io.relight_web import read_relight_web
from facette.io.rti import read_hsh_rti
from facette.pipeline import process
from facette.pipeline._rti_exposure import CLIP_PERCENT, HDRWhite, exposure_of
from test_process import L, _write_scan
from test_rti_capture import _lights, _scene_images, _write
from facette.recon.synthetic import render, sphere_on_plane


def _jpeg_capture(folder, gain=1.3, intensities=None):
    """A JPEG + .lp capture of a matte sphere on a plane, `gain` times brighter than the renders' 0.9
    peak (so some photographs clip); the photographs (m, H, W, 3) uint8 RGB as they are on disk."""
    _, imgs = _scene_images()
    imgs = np.clip(imgs * gain * (1.0 if intensities is None else intensities[:, None, None, :]), 0, 1)
    names = _write(folder, imgs, "jpg")
    write_lp(folder / "capture.lp", names, _lights())
    if intensities is not None:
        np.savetxt(folder / "light_intensities.txt", intensities)
    return np.stack([cv2.imread(str(folder / n))[..., ::-1] for n in names])


def _bytes(picture):
    return np.round(np.clip(picture, 0, 1) * 255)


def test_a_jpeg_capture_relit_at_its_lights_gives_its_photographs(tmp_path):
    photos = _jpeg_capture(tmp_path / "cap")
    assert (photos == 255).any(axis=-1).mean() > 0.001                  # some of it clips
    res = process(tmp_path / "cap", outputs=["ptm", "rti", "relight-web"], out_dir=tmp_path / "o")
    assert res.ps is None and "ps" not in res.timings                   # no photometric stereo for these
    e = res.rti_exposure
    assert (e.white, e.encoding, e.source, e.gains) == (1.0, "srgb", "photographs", None)
    rec = json.loads((tmp_path / "o" / "process.json").read_text())
    assert rec["quality"]["rti_exposure"] == {"white": 1.0, "encoding": "srgb", "scale": "photographs"}
    rti, ptm = read_hsh_rti(tmp_path / "o" / "relight.rti"), read_ptm(tmp_path / "o" / "relight.ptm")
    web = read_relight_web(tmp_path / "o" / "relight_web")
    assert any("as photographed" in c for c in rti.comments)
    lights = _lights()
    for reader, most in ((rti.relight, 6.0), (lambda d: ptm.relight(d, rtiviewer=True), 7.0), (web.relight, 7.0)):
        err = [np.abs(_bytes(reader(d)) - photos[k]).mean() for k, d in enumerate(lights)]
        # the same brightness (before: about twice), a few grey levels off (16 lights, 6 or 9 terms)
        ratio = np.mean([_bytes(reader(d)).mean() / photos[k].mean() for k, d in enumerate(lights)])
        assert np.mean(err) < most and abs(ratio - 1) < 0.03, (np.mean(err), ratio)
    clipped = photos == 255
    shown = np.stack([_bytes(rti.relight(d)) for d in lights])
    assert shown[clipped].mean() > 235                                # white where the photographs clip


def test_relight_command_at_a_captured_light_reproduces_it(tmp_path):
    photos = _jpeg_capture(tmp_path / "cap")
    assert main(["process", str(tmp_path / "cap"), "-o", str(tmp_path / "o"), "--outputs", "rti"]) == 0
    d = _lights()[5]
    az, el = np.degrees(np.arctan2(d[1], d[0])), np.degrees(np.arcsin(d[2]))
    out = tmp_path / "lit.png"
    assert main(["relight", str(tmp_path / "o" / "relight.rti"), "--light", f"{az},{el}", "-o", str(out)]) == 0
    got = cv2.imread(str(out))[..., ::-1].astype(float)
    assert np.abs(got - photos[5]).mean() < 6.0


def test_intensities_divided_out_are_multiplied_back(tmp_path):
    """A flash brighter near the axis (0.8 at 60° from it, 1.19 at 10°): the files show each photograph
    as it was taken (a smooth basis can follow a light's intensity only where it is smooth)."""
    inten = np.repeat((0.4 + 0.8 * _lights()[:, 2])[:, None], 3, axis=1)
    photos = _jpeg_capture(tmp_path / "cap", gain=1.0, intensities=inten)
    res = process(tmp_path / "cap", outputs=["rti"], out_dir=tmp_path / "o")
    np.testing.assert_allclose(res.rti_exposure.gains, inten, rtol=1e-6)
    rti = read_hsh_rti(tmp_path / "o" / "relight.rti")
    for k in range(len(inten)):      # as photographed, not evened out (that would be 1 / intensity off)
        ratio = _bytes(rti.relight(_lights()[k])).mean() / photos[k].mean()
        assert abs(ratio - 1) < 0.04, (k, ratio)


def test_a_16_bit_capture_keeps_its_linear_encoding(tmp_path):
    _, imgs = _scene_images()
    names = _write(tmp_path / "cap", imgs, "png16")
    write_lp(tmp_path / "cap" / "capture.lp", names, _lights())
    res = process(tmp_path / "cap", outputs=["rti"], out_dir=tmp_path / "o")
    assert res.rti_exposure.encoding == "linear"
    rti = read_hsh_rti(tmp_path / "o" / "relight.rti")
    assert rti.encoding == "linear"
    assert abs(rti.relight(_lights()[3]).mean() / imgs[3].mean() - 1) < 0.03
    res = process(tmp_path / "cap", outputs=["rti"], out_dir=tmp_path / "s", rti_encoding="srgb", overwrite=True)
    assert res.rti_exposure.encoding == "srgb"


def test_an_hdr_scan_clips_at_most_a_tenth_of_a_percent_of_the_object(tmp_path):
    sc = sphere_on_plane(24, 32)
    _write_scan(tmp_path / "scan", sc, render(sc, L, "glossy"), pitch=0.1)
    res = process(tmp_path / "scan", outputs=["rti", "ptm"], out_dir=tmp_path / "o")
    e = res.rti_exposure
    assert e.source == "hdr" and e.encoding == "srgb" and 0 <= e.clipped_percent <= CLIP_PERCENT
    rec = json.loads((tmp_path / "o" / "process.json").read_text())["quality"]["rti_exposure"]
    assert rec["white"] == e.white and rec["clipped_percent"] == e.clipped_percent
    rti = read_hsh_rti(tmp_path / "o" / "relight.rti")
    assert any(f"1.0 = {e.white:.6g}" in c and "HDR exposure" in c for c in rti.comments)
    assert any("at the exposure" in n for n in res.notes)


def test_hdr_white_over_bands_is_the_whole_images_and_counts_the_saturated():
    rng = np.random.default_rng(0)
    images = rng.gamma(2.0, size=(7, 30, 20, 3)).astype(np.float32)
    images[2, 3, 4:6] = np.nan                                       # saturated: clipped (2 of ~2900)
    mask = rng.random((30, 20)) > 0.3
    whole = exposure_of(type("I", (), {"kind": "scan", "light_dirs": np.zeros((7, 3))})(), "auto",
                        images=images, mask=mask)
    top = HDRWhite(7 * int(mask.sum()))
    for r0 in range(0, 30, 4):
        top.add(images[:, r0:r0 + 4], mask[r0:r0 + 4])
    white, clipped = top.value()
    assert (white, clipped) == (whole.white, whole.clipped_percent)
    brightest = np.max(images[:, mask], axis=-1)
    above = np.isnan(brightest) | (brightest > white)
    assert 100 * above.mean() == pytest.approx(clipped) and clipped <= CLIP_PERCENT
    assert 100 * (np.isnan(brightest) | (brightest >= white)).mean() > CLIP_PERCENT - 100 / brightest.size
