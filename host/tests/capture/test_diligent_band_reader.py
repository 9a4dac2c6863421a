"""The DiLiGenT folder's band reader (`capture.diligent.DiligentBands`): its values looked up by stored
value on two threads are those of the whole reading (`io.diligent.png_radiance`, `usable_from_levels`)."""
import numpy as np
import pytest

from facette.capture.diligent import DiligentBands
from facette.capture.usable import usable_from_levels
from facette.io.diligent import png_radiance
from facette.io.png import write_png


@pytest.mark.parametrize("dtype", [np.uint16, np.uint8])
@pytest.mark.parametrize("inten_dtype", [np.float64, np.float32])
def test_band_values_are_the_whole_readings(tmp_path, dtype, inten_dtype):
    rng = np.random.default_rng(3)
    top = np.iinfo(dtype).max
    names = [f"{i:03d}.png" for i in range(5)]
    images = []
    for name in names:
        im = rng.integers(0, top + 1, (29, 17, 3)).astype(dtype)
        im[0, :4] = top                   # clipped: unknown
        im[1, :4] = np.arange(4)[:, None]  # dark: below MIN_LEVELS once divided
        images.append(im)
        write_png(tmp_path / name, im)
    inten = rng.uniform(0.5, 2.0, (5, 3)).astype(inten_dtype)
    work = tmp_path / "work"
    work.mkdir()
    bands = DiligentBands(tmp_path, names, inten, work)
    bits = 16 if dtype == np.uint16 else 8
    for r0, r1 in [(0, 29), (3, 11), (28, 29)]:
        got, usable = bands.read(r0, r1)
        want = np.stack([png_radiance(im[r0:r1], inten[i], np.empty((r1 - r0, 17, 3), np.float32))
                         for i, im in enumerate(images)])
        with np.errstate(invalid="ignore"):
            want_usable = usable_from_levels(want[..., 1] * (inten[:, 1] * (2.0 ** bits - 1))[:, None, None])
        assert np.array_equal(got, want, equal_nan=True)
        assert np.array_equal(usable, want_usable)
        if r0 == 0:          # the clipped values unknown, the darkest not usable
            assert np.isnan(got[:, 0, :4]).all() and not usable[:, 1, :2].any() and usable[:, 1, 3].all()
        assert np.array_equal(bands.staged.band(r0, r1, inten), want, equal_nan=True)
