"""Row bands of a capture's images, read without the whole images (`process --memory`,
pipeline._tiled_process): `ScanBands` (a scan's hdr/ EXR, a window of scanlines at a time),
`DiligentBands` (a DiLiGenT folder's PNGs staged once to raw files); `spec()` describes a reader
so that a task on another worker opens the same one (`open_bands`)."""
from pathlib import Path

import numpy as np

from facette.pipeline._quality import usable_from_green, usable_from_levels
from facette.pipeline._tiles import _Staged

__all__ = ["ScanBands", "DiligentBands", "open_bands"]


class ScanBands:
    """A scan's HDR images (hdr/light_XX.exr and _var.exr), read a band of scanlines at a time,
    as `_scan_input._read_hdr_fast` then `load_scan` make them: NaN where the variance is not
    finite, `usable` from the green channel before the light's intensity is divided out, then
    divided by the intensity and the flat field."""

    def __init__(self, scan_dir, ids, inten, flat=None):
        import Imath
        import OpenEXR
        self.scan_dir, self.ids = Path(scan_dir), list(ids)
        self.paths = [(self.scan_dir / "hdr" / f"light_{i:02d}.exr", self.scan_dir / "hdr" / f"light_{i:02d}_var.exr")
                      for i in self.ids]
        self.inten = np.asarray(inten, np.float64)
        self.flat = flat
        self.float = Imath.PixelType(Imath.PixelType.FLOAT)
        self.files, self.windows = [], []
        try:
            for img, var in self.paths:
                pair = []
                for path in (img, var):
                    if path is var and not var.is_file():
                        pair.append(None)      # radiance without its variance (made elsewhere): no noise
                        continue
                    f = OpenEXR.InputFile(str(path))
                    box = f.header()["dataWindow"]
                    pair.append(f)
                    self.windows.append((box.min.x, box.min.y, box.max.x - box.min.x + 1, box.max.y - box.min.y + 1))
                self.files.append(pair)
        except Exception as exc:
            self.close()
            raise ValueError(f"{path}: cannot read this HDR image ({exc}); delete {path.parent} to merge it "
                             "again from raw/, or rescan that light") from exc
        if len(set(self.windows)) != 1:
            self.close()
            raise ValueError(f"the HDR images of {self.scan_dir / 'hdr'} differ in size: merge them again")
        self.x0, self.y0, self.w, self.h = self.windows[0]

    def spec(self):
        """What a task needs to open the same reader (`open_bands`), flat field apart."""
        return ("scan", str(self.scan_dir), self.ids, self.inten.tolist())

    def close(self):
        for pair in self.files:
            for f in pair:
                if f is not None:
                    f.close()
        self.files = []

    def _channels(self, f, r0, r1):
        y = self.y0
        raw = f.channels(["R", "G", "B"], self.float, y + r0, y + r1 - 1)
        return [np.frombuffer(b, np.float32).reshape(r1 - r0, self.w) for b in raw]

    def read(self, r0, r1, flat=None):
        """(images (m, r1 - r0, W, 3) float32, usable (m, r1 - r0, W) bool) of rows r0..r1;
        flat: the flat field's rows r0..r1 (default this reader's own, if any)."""
        if flat is None and self.flat is not None:
            flat = self.flat[r0:r1]
        m, b, w = len(self.paths), r1 - r0, self.w
        images = np.empty((m, b, w, 3), np.float32)
        usable = np.empty((m, b, w), bool)
        for k, (f_img, f_var) in enumerate(self.files):
            for c, ch in enumerate(self._channels(f_img, r0, r1)):
                images[k, :, :, c] = ch
            if f_var is None:
                images[k][~np.isfinite(images[k]).all(axis=-1)] = np.nan
                usable[k] = np.isfinite(images[k][..., 1]) & (images[k][..., 1] > 0)
            else:
                v = self._channels(f_var, r0, r1)
                bad = ~(np.isfinite(v[0]) & np.isfinite(v[1]) & np.isfinite(v[2]))
                fin = np.isfinite(images[k])
                wild = ~(fin[..., 0] | fin[..., 1] | fin[..., 2]) & ~bad
                if wild.any():
                    raise ValueError(f"{self.paths[k][0]} has {int(wild.sum())} non-finite values (Inf or NaN) "
                                     f"where its variance is finite: the file is damaged; delete it: processing "
                                     "merges it again from raw/")
                images[k][bad] = np.nan
                usable[k] = usable_from_green(images[k][..., 1], np.ascontiguousarray(v[1]))
            images[k] /= self.inten[k].astype(np.float32)
            if flat is not None:
                np.divide(images[k], flat, out=images[k])
        return images, usable


class DiligentBands:
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


def open_bands(spec):
    """The band reader a `spec()` describes (in a task, on whichever worker runs it)."""
    if spec[0] == "scan":
        return ScanBands(Path(spec[1]), spec[2], spec[3])
    staged = _Staged.__new__(_Staged)
    staged.paths, staged.shape, staged.dtype = [Path(p) for p in spec[1]], tuple(spec[2]), np.dtype(spec[3])
    reader = DiligentBands.__new__(DiligentBands)
    reader._init(staged, spec[4])
    return reader
