"""facette.capture.rti.RTIBands: an RTI capture read a band of rows at a time gives the whole
reading's values, and `process --memory` on it never holds the photographs whole."""
import cv2
import numpy as np
import pytest
import tifffile

from facette.calib.lp import write_lp
from facette.capture import load_input, open_bands
from facette.capture.rti import RTIBands, rti_files
from facette.pipeline import _whole as process_module   # where the whole reading loads the capture
from facette.pipeline import process
from facette.recon.synthetic import render, sphere_on_plane

H, W, ROWS = 40, 52, 7


def _lights():
    az = np.radians(np.arange(12) * 30.0)
    el = np.radians(np.tile([20.0, 40.0, 55.0], 4))
    return np.c_[np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), np.cos(el)]


def _capture(folder, kind):
    sc = sphere_on_plane(H, W, radius=14)
    imgs = render(sc, _lights(), "matte", albedo=(0.7, 0.6, 0.5), cast_shadows=False)
    imgs = np.clip(imgs / imgs.max() * 1.05, 0, 1)             # a few clipped values
    folder.mkdir(parents=True)
    names = []
    for i, im in enumerate(imgs):
        if kind == "tif16":
            names.append(f"p{i:02d}.tif")
            tifffile.imwrite(folder / names[-1], np.round(im * 65535).astype(np.uint16), photometric="rgb")
        else:
            names.append(f"p{i:02d}.jpg")
            v = np.where(im <= 0.0031308, 12.92 * im, 1.055 * im ** (1 / 2.4) - 0.055)
            cv2.imwrite(str(folder / names[-1]), np.round(v[..., ::-1] * 255).astype(np.uint8),
                        [cv2.IMWRITE_JPEG_QUALITY, 95])
    write_lp(folder / "c.lp", names, _lights())
    np.savetxt(folder / "light_intensities.txt", np.linspace(0.8, 1.2, 36).reshape(12, 3))
    return folder


@pytest.mark.parametrize("kind", ["jpg", "tif16"])
def test_bands_read_the_whole_readings_values(tmp_path, kind):
    folder = _capture(tmp_path / "c", kind)
    whole = load_input(folder, capture={"reference": (0, 0, 6, 6)})
    paths, _, _, inten, notes = rti_files(folder)
    work = tmp_path / "work"
    work.mkdir()
    bands = RTIBands(paths, inten, None, work)
    bands.set_reference((0, 0, 6, 6), notes)
    again = open_bands(bands.spec())                         # as a task on another worker opens it
    for r0 in range(0, H, ROWS):
        r1 = min(H, r0 + ROWS)
        for reader in (bands, again):
            images, usable = reader.read(r0, r1)
            np.testing.assert_array_equal(images, whole.images[:, r0:r1])
            np.testing.assert_array_equal(usable, whole.usable[:, r0:r1])
    assert np.isnan(whole.images).any()                       # the clipped values are unknown in both


def test_process_with_memory_reads_an_rti_capture_band_by_band(tmp_path, monkeypatch, force_bands):
    folder = _capture(tmp_path / "c", "jpg")
    kw = dict(outputs=["normals", "albedo", "mask", "height"], method="rank_trimmed", channels="green",
              light_gains=False, shadows="off")
    whole = process(folder, **kw)

    def refuse(*a, **k):
        raise AssertionError("the whole photographs were loaded")
    monkeypatch.setattr(process_module, "load_input", refuse)
    force_bands(ROWS)
    tiled = process(folder, memory="1GB", **kw)
    assert tiled.ps.info["tiles"] == 6
    assert np.array_equal(whole.mask, tiled.mask) and np.array_equal(whole.object_mask, tiled.object_mask)
    np.testing.assert_array_equal(tiled.normals, whole.normals)
    np.testing.assert_array_equal(tiled.albedo, whole.albedo)
    assert any("read band by band" in n for n in tiled.notes)


def _old_reading(paths, inten, enc):
    """The reading before each photograph was converted as decoded (the whole photograph at
    once, as `RTIBands.read(0, H)` did it): the values the new one must give, bit for bit."""
    from facette.capture.rti import _read_image, srgb_to_linear
    images, usable = [], []
    for k, p in enumerate(paths):
        stored, top, bits = _read_image(p)
        raw = stored.astype(np.float32)
        usable.append(np.isfinite(raw[..., 1]) & (raw[..., 1] >= 2))
        scale = top
        if enc == "linear":
            img = (raw / (scale * (1.0 if inten is None else inten[k]))).astype(np.float32)
        else:
            lut = srgb_to_linear(np.arange(256) / 255.0)
            img = lut[raw.astype(np.uint8)] if bits == 8 else srgb_to_linear(raw / scale)
            if inten is not None:
                img /= inten[k].astype(np.float32)
        img[raw >= top] = np.nan
        images.append(img)
    return np.stack(images), np.stack(usable)


@pytest.mark.parametrize("kind,enc", [("jpg", None), ("tif16", None), ("tif16", "srgb"), ("jpg", "linear")])
def test_whole_reading_converts_each_photograph_as_decoded(tmp_path, monkeypatch, kind, enc):
    import weakref

    from facette.capture import rti
    folder = _capture(tmp_path / "c", kind)
    paths, _, _, inten, _ = rti_files(folder)
    expected = _old_reading(paths, inten, enc or ("srgb" if kind == "jpg" else "linear"))
    decoded, read = [], rti._read_image

    def spy(path):              # each photograph decoded must be gone before the next is
        assert all(r() is None for r in decoded), "a decoded photograph is still held"
        out = read(path)
        decoded.append(weakref.ref(out[0]))
        return out
    monkeypatch.setattr(rti, "_read_image", spy)
    monkeypatch.setattr(rti, "CONVERT_ROWS", 3)              # bands of rows within a photograph
    inp = load_input(folder, capture={"encoding": enc} if enc else None)
    assert len(decoded) == 12
    np.testing.assert_array_equal(inp.images, expected[0])  # NaN where clipped, in both
    np.testing.assert_array_equal(inp.usable, expected[1])
    assert np.isnan(inp.images).any() and inp.images.dtype == np.float32
