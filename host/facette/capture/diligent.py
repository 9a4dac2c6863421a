"""A DiLiGenT-style folder (filenames.txt, light_directions.txt, optional light_intensities.txt
and mask.png, PNG photographs) read a band of rows at a time: the photographs staged once to raw
files (PNG decodes whole images only), each band one contiguous read per light."""
from pathlib import Path

import numpy as np

from facette.capture.base import Bands
from facette.capture.usable import usable_from_levels
from facette.io.diligent import png_radiance, size_mismatch
from facette.io.png import read_png

__all__ = ["DiligentBands"]


class _Staged:
    """The photographs of a folder as raw uint16/uint8 (H, W, 3) files, one per light, so that a
    band of rows is one contiguous read per light."""

    def __init__(self, folder, names, work):
        self.paths, self.shape, self.dtype = [], None, None
        for i, name in enumerate(names):
            arr = read_png(folder / name)
            if arr.ndim == 2:
                arr = np.repeat(arr[..., None], 3, axis=2)
            arr = np.ascontiguousarray(arr[..., :3])
            if self.shape is None:
                self.shape, self.dtype = arr.shape, arr.dtype
            elif arr.shape != self.shape:
                raise ValueError(size_mismatch(name, arr.shape, names[0], self.shape))
            path = Path(work) / f"{i:04d}.raw"
            arr.astype(self.dtype, copy=False).tofile(path)
            self.paths.append(path)
            del arr

    def band(self, r0, r1, intensities):
        """(m, r1 - r0, W, 3) float32 radiance of rows r0..r1 (as `read_diligent`)."""
        h, w, c = self.shape
        item = np.dtype(self.dtype).itemsize
        out = np.empty((len(self.paths), r1 - r0, w, 3), np.float32)
        for i, path in enumerate(self.paths):
            raw = np.fromfile(path, self.dtype, count=(r1 - r0) * w * c, offset=r0 * w * c * item)
            png_radiance(raw.reshape(r1 - r0, w, c), intensities[i], out[i])
        return out


class DiligentBands(Bands):
    """A DiLiGenT-style folder's photographs staged to raw files (`_tiles._Staged`), read a band
    at a time as `read_diligent` and `load_input` make them (usable: `usable_from_levels`)."""

    def __init__(self, folder, names, inten, work):
        self._init(_Staged(folder, names, work), inten)

    def _init(self, staged, inten):
        self.staged, self.inten = staged, np.asarray(inten)
        self.h, self.w = self.staged.shape[:2]
        bits = 16 if self.staged.dtype == np.uint16 else 8
        self.levels = (self.inten[:, 1] * (2.0 ** bits - 1))[:, None, None]

    def spec(self):
        st = self.staged
        return ("diligent", [str(p) for p in st.paths], tuple(st.shape), np.dtype(st.dtype).str, self.inten.tolist())

    def read(self, r0, r1, flat=None):
        images = self.staged.band(r0, r1, self.inten)
        with np.errstate(invalid="ignore"):
            levels = images[..., 1] * self.levels
        return images, usable_from_levels(levels)

    def close(self):
        pass
