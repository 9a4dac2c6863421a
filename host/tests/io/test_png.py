"""facette.io.png (OpenCV): 8- and 16-bit PNG read/write, masks and errors."""
import struct
import zlib

import numpy as np
import pytest

from facette.io.png import PngBandWriter, png_size, read_mask, read_png, write_mask, write_png


def _encode_filtered(img):
    """A 16-bit RGB PNG whose rows cycle through the five filter types (as encoders do)."""
    h, w, _ = img.shape
    bpp = 6
    rows = img.astype(">u2").reshape(h, -1).view(np.uint8).astype(np.int16)
    out, prev = [], np.zeros(w * bpp, np.int16)
    for r in range(h):
        f, cur = r % 5, rows[r]
        left = np.r_[np.zeros(bpp, np.int16), cur[:-bpp]]
        ul = np.r_[np.zeros(bpp, np.int16), prev[:-bpp]]
        p = left + prev - ul
        pa, pb, pc = abs(p - left), abs(p - prev), abs(p - ul)
        paeth = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, ul))
        pred = [0 * cur, left, prev, (left + prev) // 2, paeth][f]
        out.append(bytes([f]) + ((cur - pred) & 255).astype(np.uint8).tobytes())
        prev = cur

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"".join(out))) + chunk(b"IEND", b""))


def test_png_16bit_roundtrip_and_all_filter_types(tmp_path):
    img = (np.random.default_rng(0).random((23, 31, 3)) * 65535).astype(np.uint16)
    write_png(tmp_path / "a.png", img)
    back = read_png(tmp_path / "a.png")
    assert back.dtype == np.uint16 and np.array_equal(back, img)
    (tmp_path / "f.png").write_bytes(_encode_filtered(img))
    assert np.array_equal(read_png(tmp_path / "f.png"), img)


def test_png_8bit_grey_mask_and_errors(tmp_path):
    m = np.zeros((5, 7), bool)
    m[1:3, 2:6] = True
    write_mask(tmp_path / "m.png", m)
    assert np.array_equal(read_mask(tmp_path / "m.png"), m)
    with pytest.raises(ValueError, match="uint8 or uint16"):
        write_png(tmp_path / "x.png", np.zeros((2, 2), np.float32))
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="not a PNG"):
        read_png(tmp_path / "bad.png")
    with pytest.raises(FileNotFoundError):
        read_png(tmp_path / "missing.png")


def test_png_channels_stay_in_rgb_order_at_8_and_16_bits(tmp_path):
    """OpenCV stores BGR(A): read_png and write_png give and take RGB(A). Pillow, an
    independent encoder, writes the 8-bit reference files."""
    from PIL import Image
    rng = np.random.default_rng(1)
    rgb8 = rng.integers(0, 256, (9, 13, 3), dtype=np.uint8)
    rgba8 = rng.integers(0, 256, (9, 13, 4), dtype=np.uint8)
    Image.fromarray(rgb8).save(tmp_path / "rgb.png")
    Image.fromarray(rgba8).save(tmp_path / "rgba.png")
    assert np.array_equal(read_png(tmp_path / "rgb.png"), rgb8)
    assert np.array_equal(read_png(tmp_path / "rgba.png"), rgba8)
    write_png(tmp_path / "w.png", rgba8)
    assert np.array_equal(np.asarray(Image.open(tmp_path / "w.png")), rgba8)
    grey16 = rng.integers(0, 65536, (9, 13), dtype=np.uint16)
    rgba16 = rng.integers(0, 65536, (9, 13, 4), dtype=np.uint16)
    for img in (grey16, rgba16, grey16[:, :, None]):
        write_png(tmp_path / "x.png", img)
        back = read_png(tmp_path / "x.png")
        assert back.dtype == np.uint16 and np.array_equal(back, img.reshape(back.shape))


def test_png_truncated_file_and_unsupported_shapes_are_refused(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((40, 40, 3), np.uint16) + 1000)
    data = (tmp_path / "a.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[:len(data) // 2])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        read_png(tmp_path / "cut.png")
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        write_png(tmp_path / "b.png", np.zeros((4, 4, 2), np.uint8))
    assert not (tmp_path / "b.png").exists()


# ----------------------------------------------------------------------------- PngBandWriter

def test_band_writer_gives_the_image_to_opencv(tmp_path):
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 65536, (23, 31, 3)).astype(np.uint16)
    with PngBandWriter(tmp_path / "rgb.png", 31, 23) as w:
        for r0 in range(0, 23, 4):
            w.write(rgb[r0:r0 + 4])
    np.testing.assert_array_equal(read_png(tmp_path / "rgb.png"), rgb)
    grey = rng.integers(0, 256, (5, 9)).astype(np.uint8)
    with PngBandWriter(tmp_path / "grey.png", 9, 5, channels=1, dtype=np.uint8) as w:
        w.write(grey)
    np.testing.assert_array_equal(read_png(tmp_path / "grey.png"), grey)


def test_band_writer_refuses_wrong_bands_and_keeps_no_partial_file(tmp_path):
    path = tmp_path / "x.png"
    with pytest.raises(ValueError, match="a band must be"):
        with PngBandWriter(path, 8, 4) as w:
            w.write(np.zeros((2, 8, 3), np.uint8))                 # wrong dtype
    with pytest.raises(ValueError, match="the image has 4"):
        with PngBandWriter(path, 8, 4) as w:
            w.write(np.zeros((5, 8, 3), np.uint16))
    w = PngBandWriter(path, 8, 4)
    w.write(np.zeros((3, 8, 3), np.uint16))
    with pytest.raises(ValueError, match="3 rows written of 4"):
        w.close()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="grey or RGB"):
        PngBandWriter(path, 8, 4, channels=4)


def test_png_size_reads_the_header_only(tmp_path):
    write_png(tmp_path / "a.png", np.zeros((7, 11, 3), np.uint16))
    assert png_size(tmp_path / "a.png") == (11, 7)
    (tmp_path / "b.png").write_bytes(b"not a png at all, no header here")
    with pytest.raises(ValueError, match="not a PNG"):
        png_size(tmp_path / "b.png")
