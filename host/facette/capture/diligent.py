"""A DiLiGenT-style folder (filenames.txt, light_directions.txt, optional light_intensities.txt
and mask.png, PNG photographs) read a band of rows at a time: the photographs staged once to raw
files (PNG decodes whole images only), each band one contiguous read per light."""
from pathlib import Path

import numpy as np

from facette._threads import run_blocks
from facette.capture.base import Bands
from facette.capture.usable import MIN_LEVELS
from facette.io.diligent import size_mismatch
from facette.io.png import read_png

__all__ = ["DiligentBands"]


class _Staged:
    """The photographs of a folder as raw uint16/uint8 (H, W, 3) files, one per light, so that a
    band of rows is one contiguous read per light. Staged on `WORKERS` threads (OpenCV's PNG decoder
    and the file writes give the GIL up): two decoded photographs held at once."""

    def __init__(self, folder, names, work):
        work = Path(work)
        self.paths = [work / f"{i:04d}.raw" for i in range(len(names))]
        first = self._stage(folder, names[0], self.paths[0])
        self.shape, self.dtype = first

        def stage(i):
            shape, dtype = self._stage(folder, names[i], self.paths[i])
            if shape != self.shape:
                raise ValueError(size_mismatch(names[i], shape, names[0], self.shape))
        run_blocks(stage, range(1, len(names)))

    @staticmethod
    def _stage(folder, name, path):
        arr = read_png(folder / name)
        if arr.ndim == 2:
            arr = np.repeat(arr[..., None], 3, axis=2)
        arr = np.ascontiguousarray(arr[..., :3])
        arr.tofile(path)
        return arr.shape, arr.dtype

    def _raw(self, i, r0, r1):
        h, w, c = self.shape
        item = np.dtype(self.dtype).itemsize
        raw = np.fromfile(self.paths[i], self.dtype, count=(r1 - r0) * w * c, offset=r0 * w * c * item)
        return raw.reshape(r1 - r0, w, c)

    def band(self, r0, r1, intensities):
        """(m, r1 - r0, W, 3) float32 radiance of rows r0..r1 (as `read_diligent`: `band_usable`'s)."""
        bits = 16 if self.dtype == np.uint16 else 8
        return self.band_usable(r0, r1, intensities, np.asarray(intensities)[:, 1] * (2.0 ** bits - 1))[0]

    def band_usable(self, r0, r1, intensities, levels):
        """(`band`'s radiance, usable (m, r1 - r0, W): `usable_from_levels` of its green channel times
        `levels` (m,), each photograph's grey levels per unit): the same values, each photograph's looked
        up by value (`radiance_and_usable`; its table made once per light: 0.8 MB at 16 bits), the
        photographs shared between `WORKERS` threads."""
        from facette.capture._pixels_jit import radiance_and_usable, radiance_tables
        h, w, c = self.shape
        m = len(self.paths)
        out, usable = np.empty((m, r1 - r0, w, 3), np.float32), np.empty((m, r1 - r0, w), bool)
        tables = getattr(self, "_tables", None)
        if tables is None or not (np.array_equal(tables[0], intensities) and np.array_equal(tables[1], levels)):
            self._tables = tables = (np.array(intensities), np.array(levels), [None] * m)

        def convert(i):
            if tables[2][i] is None:
                tables[2][i] = radiance_tables(self.dtype, intensities[i], levels[i], MIN_LEVELS)
            radiance_and_usable(self._raw(i, r0, r1), tables[2][i], out[i], usable[i])
        run_blocks(convert, range(m))
        return out, usable


class DiligentBands(Bands):
    """A DiLiGenT-style folder's photographs staged to raw files (`_tiles._Staged`), read a band
    at a time as `read_diligent` and `load_input` make them (usable: `usable_from_levels`)."""

    def __init__(self, folder, names, inten, work):
        self._init(_Staged(folder, names, work), inten)

    def _init(self, staged, inten):
        self.staged, self.inten = staged, np.asarray(inten)
        self.h, self.w = self.staged.shape[:2]
        bits = 16 if self.staged.dtype == np.uint16 else 8
        self.levels = self.inten[:, 1] * (2.0 ** bits - 1)

    def spec(self):
        st = self.staged
        return ("diligent", [str(p) for p in st.paths], tuple(st.shape), np.dtype(st.dtype).str, self.inten.tolist())

    def read(self, r0, r1, flat=None):
        return self.staged.band_usable(r0, r1, self.inten, self.levels)

    def close(self):
        pass
