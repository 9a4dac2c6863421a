"""`bench lights --capture`'s input: the banded relief written once as a DiLiGenT folder."""
import numpy as np

from facette.bench._dome_capture import GAIN, write_dome_capture
from facette.bench._render_jit import cast_hidden
from facette.bench.lights import band_rows, dome_lights, relief_heights, render_band
from facette.io.diligent import read_diligent


def test_the_folder_holds_the_banded_photographs(tmp_path, capsys):
    w, h, m = 40, 30, 6
    folder = tmp_path / "dome"
    write_dome_capture(folder, w, h, m, "satin")
    printed = capsys.readouterr().out
    assert '"render_cpu_s"' in printed and '"hidden_of_lit"' in printed
    d = read_diligent(folder)
    assert d.images.shape == (m, h, w, 3) and d.mask.all()
    np.testing.assert_allclose(d.light_dirs, dome_lights(m), atol=1e-7)
    hidden = cast_hidden(relief_heights(h, w), 0, h, dome_lights(m))
    assert hidden.any()                       # its cast shadows: 0 in the photographs
    want, normals = render_band(0, h, w, min(h, w), dome_lights(m), "satin", hidden=hidden)   # the same rows whatever the band
    assert band_rows(w, m) >= 1
    # the PNGs hold the photographs to 16 bits: within half a step of the range over the gain
    np.testing.assert_allclose(d.images, want, atol=0.5 / 65535 / GAIN + 1e-7)
    np.testing.assert_array_equal(np.load(folder / "normal_gt.npy"), normals.astype(np.float32))
