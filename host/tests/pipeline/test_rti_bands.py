"""`process --memory` with ptm and rti (pipeline._rti_bands): relight.ptm and relight.rti fitted
over bands of two rows are the untiled files byte for byte, for a scan directory (near lights,
HDR with variances, values unknown) and a DiLiGenT-style folder, in both encodings, without the
whole images ever loaded; the reference-format readers read them (the HDR exposure over bands:
test_rti_exposure)."""
import sys
from pathlib import Path

import numpy as np
import pytest

from facette.pipeline import process
from facette.pipeline import _process, _rti_bands
from facette.recon import _rti as rti_fit
from test_exports import _diligent
from test_process_memory import M, WHOLE_CHANNELS, _never_whole, diligent, scan, small_bands  # noqa: F401

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "io"))
from rti_spec_readers import hsh_colour, ptm_colour, ptm_rgb_colour, read_hsh, read_ptm, read_ptm_rgb  # noqa: E402

OUTPUTS = ["normals", "mask", "ptm", "rti", "relight-web"]


def _both(request, tmp_path, monkeypatch, source, encoding, rows, block):
    """(untiled result, --memory result) with fit bands of `rows` rows and the fits' blocks of
    `block` pixels (None: as shipped)."""
    if block is not None:
        monkeypatch.setattr(rti_fit, "_BLOCK", block)
    src = request.getfixturevalue(source)
    whole = process(src, channels=WHOLE_CHANNELS, outputs=OUTPUTS, out_dir=tmp_path / "whole", method=M,
                    rti_encoding=encoding)
    _never_whole(monkeypatch)
    monkeypatch.setattr(_rti_bands, "relight_rows", lambda *a: rows)
    tiled = process(src, outputs=OUTPUTS, out_dir=tmp_path / "tiled", method=M, memory="1GB", rti_encoding=encoding)
    assert tiled.ps.info["tiles"] > 1 and not any("loaded whole" in n for n in tiled.notes)
    return whole, tiled


# bands of 8 rows on blocks of 16 pixels: a band starts on a block (44 and 46 pixels wide); the
# scan's near lights solve each pixel on its own (no shared product): bands of 2 rows off the blocks too
@pytest.mark.parametrize("source,encoding,rows,block", [("scan", "srgb", 2, None), ("scan", "linear", 8, 16),
                                                        ("diligent", "srgb", 8, 16), ("diligent", "linear", 8, 16)])
def test_relight_files_over_bands_are_the_untiled_bytes(request, tmp_path, small_bands, monkeypatch, source,
                                                         encoding, rows, block):
    whole, tiled = _both(request, tmp_path, monkeypatch, source, encoding, rows, block)
    for name in ("relight.ptm", "relight.rti"):
        a, b = (tmp_path / "whole" / name).read_bytes(), (tmp_path / "tiled" / name).read_bytes()
        assert len(a) == len(b) and a == b, name
    web = sorted(p.relative_to(tmp_path / "whole") for p in (tmp_path / "whole" / "relight_web").rglob("*"))
    assert len(web) == 10                 # info.json and 9 plane JPEGs: the same bytes from the spill
    for p in web:
        assert (tmp_path / "whole" / p).read_bytes() == (tmp_path / "tiled" / p).read_bytes(), p
    assert tiled.fit_errors == whole.fit_errors and set(whole.fit_errors) == {"ptm_relative_rms",
                                                                              "hsh_relative_rms"}
    assert tiled.ptm.white == whole.ptm.white and tiled.hsh.white == whole.hsh.white
    np.testing.assert_array_equal(tiled.ptm.coeffs, whole.ptm.coeffs)          # stride 1 at this size
    np.testing.assert_array_equal(tiled.hsh.coeffs, whole.hsh.coeffs)
    notes = [n for n in tiled.notes if "relight" in n and "do not start on the fit's blocks" not in n]
    assert notes == [n for n in whole.notes if "relight" in n]
    assert not list(Path(tmp_path / "tiled").glob(".*partial"))


def test_bands_off_the_fits_blocks_say_so_and_differ_by_a_step_at_most(request, tmp_path, small_bands,
                                                                       monkeypatch):
    whole, tiled = _both(request, tmp_path, monkeypatch, "diligent", "srgb", 2, None)
    assert any("do not start on the fit's blocks of 8192 pixels" in n for n in tiled.notes)
    for name in ("relight.ptm", "relight.rti"):
        a, b = (tmp_path / "whole" / name).read_bytes(), (tmp_path / "tiled" / name).read_bytes()
        assert len(a) == len(b)
    pw, pt = read_ptm(tmp_path / "whole" / "relight.ptm"), read_ptm(tmp_path / "tiled" / "relight.ptm")
    hw, ht = read_hsh(tmp_path / "whole" / "relight.rti"), read_hsh(tmp_path / "tiled" / "relight.rti")
    np.testing.assert_allclose(pt["scale"], pw["scale"], rtol=1e-5)
    np.testing.assert_allclose(ht["scale"], hw["scale"], rtol=1e-5)
    # one quantisation step (scale, scale / 255) and the range's float32 wobble at most
    assert np.all(np.abs(pt["coeffs"] - pw["coeffs"]) <= 1.01 * pw["scale"])
    assert np.all(np.abs(ht["coeffs"] - hw["coeffs"]) <= 1.01 * hw["scale"] / 255)
    assert tiled.fit_errors == pytest.approx(whole.fit_errors, rel=1e-5)


@pytest.mark.parametrize("lights,saturate", [(12, (slice(10, 14), slice(14, 18), range(7))), (6, None)])
def test_unfitted_pixels_and_a_lower_hsh_order_over_bands_as_untiled(tmp_path, small_bands, monkeypatch, lights,
                                                                    saturate):
    """7 of 12 lights clipped on a patch (fitted as photographed, at full brightness); 6 lights: HSH order 2."""
    folder = _diligent(tmp_path / "dil", lights, saturate)
    monkeypatch.setattr(rti_fit, "_BLOCK", 16)
    whole = process(folder, channels=WHOLE_CHANNELS, outputs=OUTPUTS, out_dir=tmp_path / "whole", method=M)
    monkeypatch.setattr(_rti_bands, "relight_rows", lambda *a: 8)      # 32 pixels wide: on the blocks
    tiled = process(folder, outputs=OUTPUTS, out_dir=tmp_path / "tiled", method=M, memory="1GB")
    said = [n for n in whole.notes if n.startswith("relight.")]
    assert said and said == [n for n in tiled.notes if n.startswith("relight.")]
    if saturate:          # clipped values are known as photographed (full brightness): nothing left out
        assert not any("usable lights" in n for n in said)
    else:
        assert any("HSH order 2" in n for n in said)
    for name in ("relight.ptm", "relight.rti"):
        assert (tmp_path / "whole" / name).read_bytes() == (tmp_path / "tiled" / name).read_bytes(), name


def test_the_reference_readers_read_the_banded_files(scan, tmp_path, small_bands):
    res = process(scan, outputs=OUTPUTS, out_dir=tmp_path, method=M, memory="1GB", rti_encoding="linear")
    ptm, rti = read_ptm(tmp_path / "relight.ptm"), read_hsh(tmp_path / "relight.rti")
    h, w = res.mask.shape
    assert (ptm["height"], ptm["width"]) == (h, w) and (rti["height"], rti["width"]) == (h, w)
    sel = res.object_mask
    light = np.array([0.3, 0.2, 0.93])
    light /= np.linalg.norm(light)
    for shown in (ptm_colour(ptm, light), hsh_colour(rti, light)):
        assert shown.shape == (h, w, 3) and np.isfinite(shown).all()
        assert shown[sel].mean() > 0.02            # the object is lit, not a blank file


def test_the_web_folder_alone_over_bands_is_the_untiled_folder(tmp_path, small_bands, monkeypatch, diligent):
    """--memory with `--outputs relight-web` alone (no .rti asked for): the HSH is fitted over the bands all
    the same (before: no fit, and a TypeError in the hsh stage), the folder the untiled one byte for byte."""
    with monkeypatch.context() as whole_only:       # read whole (the relighting files alone go over bands)
        whole_only.setattr(_process, "relighting_budget", lambda *a, **k: None)
        whole_only.setattr(_process, "with_default_budget", lambda s, o, out: (o, []))
        process(diligent, channels=WHOLE_CHANNELS, outputs=["relight-web"], out_dir=tmp_path / "whole", method=M)
    _never_whole(monkeypatch)
    monkeypatch.setattr(_rti_bands, "relight_rows", lambda *a: 8)
    monkeypatch.setattr(rti_fit, "_BLOCK", 16)
    process(diligent, outputs=["relight-web"], out_dir=tmp_path / "tiled", method=M, memory="1GB")
    assert not (tmp_path / "tiled" / "relight.rti").exists()
    web = sorted(p.relative_to(tmp_path / "whole") for p in (tmp_path / "whole" / "relight_web").rglob("*"))
    assert len(web) == 10
    for p in web:
        assert (tmp_path / "whole" / p).read_bytes() == (tmp_path / "tiled" / p).read_bytes(), p


def _satin_capture(folder, m=24):
    """A JPEG + .lp capture of a red satin sphere on a grey plane: white highlights on a red body,
    a colour that changes with the light (what a luminance x colour PTM cannot follow)."""
    import cv2

    from facette.calib.lp import write_lp
    from facette.recon.synthetic import render, sphere_on_plane
    az = np.radians(np.arange(m) * 360.0 / m)
    el = np.radians(np.tile([25.0, 40.0, 55.0, 70.0], m // 4))
    dirs = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    imgs = render(sphere_on_plane(36, 44, radius=14), dirs, "satin", albedo=(0.7, 0.08, 0.05), cast_shadows=False,
                  ks=3.0)
    imgs = np.clip(imgs / np.percentile(imgs, 99.5), 0, 1)
    folder.mkdir()
    names = [f"p{k:02d}.jpg" for k in range(m)]
    for name, im in zip(names, imgs):
        v = np.where(im <= 0.0031308, 12.92 * im, 1.055 * im ** (1 / 2.4) - 0.055)
        cv2.imwrite(str(folder / name), np.round(v[..., ::-1] * 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 95])
    write_lp(folder / "c.lp", names, dirs)
    return dirs


def test_ptm_format_auto_takes_a_polynomial_per_channel_where_the_colour_moves(tmp_path):
    """Highlights whiter than the body: `auto` writes PTM_FORMAT_RGB (said, with both errors), which
    RTIViewer's rules (a reader written from its RGBPtm loader) show closer to the photographs than
    the LRGB file, at the captured lights."""
    import cv2
    dirs = _satin_capture(tmp_path / "c")
    shown = {}
    for fmt in ("auto", "lrgb"):
        res = process(tmp_path / "c", outputs=["ptm"], out_dir=tmp_path / fmt, ptm_format=fmt)
        shown[fmt] = res
    said = [n for n in shown["auto"].notes if n.startswith("relight.ptm: PTM_FORMAT_")]
    assert len(said) == 1 and "PTM_FORMAT_RGB" in said[0] and "grey levels" in said[0]
    rgb, lrgb = read_ptm_rgb(tmp_path / "auto" / "relight.ptm"), read_ptm(tmp_path / "lrgb" / "relight.ptm")
    photos = np.stack([cv2.imread(str(tmp_path / "c" / f"p{k:02d}.jpg"))[..., ::-1] for k in range(len(dirs))]) / 255
    err = {name: np.mean([np.abs(colour(f, d) - p).mean() for d, p in zip(dirs, photos)])
           for name, colour, f in (("rgb", ptm_rgb_colour, rgb), ("lrgb", ptm_colour, lrgb))}
    assert err["rgb"] < 0.8 * err["lrgb"] and err["rgb"] < 0.045, err
    assert shown["auto"].fit_errors["ptm_relative_rms"] < shown["lrgb"].fit_errors["ptm_relative_rms"]


@pytest.mark.parametrize("material,albedo,chosen", [("satin", (0.7, 0.08, 0.05), "RGB"), ("matte", (0.5, 0.5, 0.5), "LRGB")])
def test_whole_images_choose_the_ptm_format_first_and_write_the_bytes_of_both_fits(tmp_path, material, albedo, chosen):
    """From whole images (`whole`) relight.ptm's format is chosen on the relighting error's rows
    before the fits and only that format is fitted, held in memory (or on disk above IN_MEMORY_BYTES);
    the files, the note (both errors) and the errors are those of fitting both formats everywhere and
    spilling them to disk (the bands' way), each of the 13 row bands taking the untiled fit's rows."""
    from facette.pipeline._options import ProcessOptions
    from facette.pipeline._rti_exposure import Exposure
    from facette.recon.synthetic import render, sphere_on_plane
    m = 24
    az = np.radians(np.arange(m) * 360.0 / m)
    el = np.radians(np.tile([25.0, 40.0, 55.0, 70.0], m // 4))
    dirs = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]
    imgs = render(sphere_on_plane(50, 44, radius=18), dirs, material, albedo=albedo, cast_shadows=False, ks=3.0)
    imgs = np.asarray(imgs / np.percentile(imgs, 99.5), np.float32)
    mask = np.ones(imgs.shape[1:3], bool)
    exposure = Exposure(1.0, "srgb", None, "hdr", 0.5)
    runs = {}
    for name, whole, cap in (("memory", True, None), ("chosen first, on disk", True, 0), ("bands", False, None)):
        with pytest.MonkeyPatch.context() as mp:
            if cap is not None:
                mp.setattr(_rti_bands, "IN_MEMORY_BYTES", cap)
            fits = _rti_bands.relight_bands(lambda r0, r1: (imgs[:, r0:r1], dirs), mask, ["ptm", "rti"],
                                            ProcessOptions(), None, m, None, exposure=exposure, rows=4, whole=whole)
        fits.write_ptm(tmp_path / f"{name}.ptm")
        fits.write_rti(tmp_path / f"{name}.rti", ["c"])
        runs[name] = fits
        assert isinstance(fits.spills["ptm"].data, np.memmap) is (name != "memory"), name
    for name in ("chosen first, on disk", "bands"):
        for ext in ("ptm", "rti"):
            assert (tmp_path / f"memory.{ext}").read_bytes() == (tmp_path / f"{name}.{ext}").read_bytes(), (name, ext)
        assert runs[name].ptm_format == runs["memory"].ptm_format == chosen.lower()
        assert runs[name].notes == runs["memory"].notes and f"PTM_FORMAT_{chosen} (" in runs[name].notes["ptm"][0]
        assert runs[name].fit_errors == runs["memory"].fit_errors
        assert runs[name].loo == runs["memory"].loo and len(runs[name].loo) > 1
