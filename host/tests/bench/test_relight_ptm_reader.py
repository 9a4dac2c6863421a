"""bench._relight_ptm_reader: RTIViewer's loader rules on files made byte by byte here (not by
facette's writer): channel planes, bottom row first, truncated coefficients, the LRGB's colour."""
import numpy as np
import pytest

from facette.bench._relight_ptm_reader import read_ptm_as_rtiviewer

HEAD = "PTM_1.2\n{fmt}\n2\n2\n0.5 0.5 0.5 0.5 0.5 2\n0 0 0 0 0 10\n"


def _pixel(a3, a5):          # a0..a5 bytes of one texel: lu term a3, constant a5
    return [0, 0, 0, a3, 0, a5]


def test_rgb_planes_bottom_row_first_and_truncated(tmp_path):
    # texels in file order (bottom row first): (x0, y1) (x1, y1) (x0, y0) (x1, y0); a = (byte - bias) * scale
    red = _pixel(9, 60) + _pixel(0, 70) + _pixel(0, 80) + _pixel(0, 90)
    green, blue = _pixel(0, 20) * 4, _pixel(0, 110) * 4
    path = tmp_path / "rgb.ptm"
    path.write_bytes(HEAD.format(fmt="PTM_FORMAT_RGB").encode() + bytes(red + green + blue))
    relight, fmt = read_ptm_as_rtiviewer(path)
    assert fmt == "PTM_FORMAT_RGB"
    top = relight(0.0, 0.0)
    # a5 = (byte - 10) * 2; the file's last row is the picture's top
    np.testing.assert_array_equal(top[..., 0], [[140, 160], [100, 120]])
    assert (top[..., 1] == 20).all() and (top[..., 2] == 200).all()
    # a3 = int(9 * 0.5) = 4 (truncated), on the bottom-left texel only
    assert relight(1.0, 0.0)[1, 0, 0] == 104 and relight(1.0, 0.0)[1, 1, 0] == 120


def test_lrgb_is_luminance_times_colour(tmp_path):
    lum = _pixel(0, 137) * 4                        # L = (137 - 10) * 2 = 254
    colour = [255, 128, 0] * 4
    path = tmp_path / "lrgb.ptm"
    path.write_bytes(HEAD.format(fmt="PTM_FORMAT_LRGB").encode() + bytes(lum + colour))
    relight, fmt = read_ptm_as_rtiviewer(path)
    assert fmt == "PTM_FORMAT_LRGB"
    np.testing.assert_allclose(relight(0.0, 0.0)[0, 0], [254.0, 128 * 254 / 255, 0.0])


def test_other_formats_are_refused(tmp_path):
    path = tmp_path / "lum.ptm"
    path.write_bytes(HEAD.format(fmt="PTM_FORMAT_LUM").encode())
    with pytest.raises(ValueError, match="not read"):
        read_ptm_as_rtiviewer(path)


def test_a_body_that_is_not_the_headers_size_is_refused(tmp_path):
    path = tmp_path / "short.ptm"
    path.write_bytes(HEAD.format(fmt="PTM_FORMAT_RGB").encode() + bytes(_pixel(0, 20) * 11))    # 12 texels wanted
    with pytest.raises(ValueError, match="66 data bytes for 2x2 texels"):
        read_ptm_as_rtiviewer(path)
