"""The simulated rig at any size: the scene and each LED's radiance made a band of rows at a
time and kept on disk, never all LEDs × the whole image in memory.

At 11648×8736 RAW (5824×4368 px at half size) the scene alone is 1.5 GB of float64 and the
12 LEDs' radiance 7.3 GB: `render_to_disk` writes each LED's radiance (float64, as
`radiance_per_led` gives it, the same numbers) and the truth (float32 .npy, as truth.npz
holds it) into a folder band by band, holding the whole height field (the cast shadows read
along the rays) and one band. `RadianceOnDisk` gives the simulated camera the electrons of
any rows of a frame from those files (`SimCamera` exposes a frame band by band).
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np

from facette.sim.render import led_reach, radiance_rows

__all__ = ["RadianceOnDisk", "render_to_disk", "TRUTH_ARRAYS", "band_rows_for"]

TRUTH_ARRAYS = {"normals": (np.float32, 3), "height_mm": (np.float32, 0), "mask": (np.bool_, 0),
                "albedo": (np.float32, 3)}
"""The per-pixel arrays of truth.npz written beside the radiance: dtype and channels (0: none)."""


BAND_PIXELS = 1_500_000
"""Half-size pixels in a band: the renderer holds about 0.4 GB per band of these (the BRDF's
temporaries) and its cast shadows read a halo of rows beyond it (~1000 rows at 11648x8736
RAW under the thesis LEDs), so a thinner band recomputes more halo for less memory."""


def band_rows_for(width, pixels=BAND_PIXELS):
    """Rows per band of about `pixels` half-size pixels for an image `width` wide: at least
    8 rows, even."""
    rows = int(pixels // max(int(width), 1))
    return max(8, rows // 2 * 2)


def _header(fh, dtype, shape):
    np.lib.format.write_array_header_1_0(
        fh, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)), "fortran_order": False,
             "shape": tuple(shape)})


class RadianceOnDisk:
    """Per-LED radiance files (m, H, W, 3) float64, e- per mA·µs (`radiance_per_led`'s), in
    `folder` as led_XX.npy; read a band of rows at a time (plain reads: the file's pages stay
    in the page cache, not in this process)."""

    def __init__(self, folder, n_leds, shape):
        self.folder = folder
        self.shape = (int(n_leds), int(shape[0]), int(shape[1]), 3)

    def path(self, i):
        return self.folder / f"led_{int(i):02d}.npy"

    def rows(self, i, r0, r1):
        """LED i's radiance on rows r0..r1: (r1 - r0, W, 3) float64."""
        _, _, ww, _ = self.shape
        row_bytes = ww * 3 * 8
        out = np.empty((r1 - r0, ww, 3))
        with open(self.path(i), "rb") as fh:
            np.lib.format.read_magic(fh)
            np.lib.format.read_array_header_1_0(fh)
            fh.seek(r0 * row_bytes, 1)
            if fh.readinto(memoryview(out).cast("B")) != out.nbytes:
                raise OSError(f"{self.path(i)} ends before row {r1}: the simulator's radiance file "
                              "was cut short")
        return out

    def electrons(self, charges, r0, r1):
        """Σ_i charges[i] · radiance[i] on rows r0..r1 (the LEDs that gave no charge are not
        read): (r1 - r0, W, 3) float64 e-."""
        q = np.asarray(charges, float)
        lit = np.flatnonzero(q)
        if lit.size == 0:
            return np.zeros((r1 - r0, self.shape[2], 3))
        return np.tensordot(q[lit], np.stack([self.rows(i, r0, r1) for i in lit]), axes=(0, 0))


def _stamp(spec, leds, electrons_per_mA_s, shadows):
    """What a render depends on, as JSON: the same stamp, the same files."""
    return json.dumps({"format": 1, "scene": dataclasses.asdict(spec), "leds": leds.truth_dict(),
                       "distance_mm": leds.distance_mm, "electrons_per_mA_s": float(electrons_per_mA_s),
                       "shadows": bool(shadows)}, sort_keys=True)


def _rendered(folder, disk, stamp):
    """True when `folder` holds a finished render of `stamp` (render.json written last)."""
    try:
        if (folder / RENDER_STAMP).read_text() != stamp:
            return False
    except OSError:
        return False
    size = disk.shape[1] * disk.shape[2] * 3 * 8
    return all(disk.path(i).is_file() and disk.path(i).stat().st_size >= size for i in range(disk.shape[0])) \
        and all((folder / f"truth_{name}.npy").is_file() for name in TRUTH_ARRAYS)


RENDER_STAMP = "render.json"


def render_to_disk(folder, spec, leds, electrons_per_mA_s=20.0, shadows=True, band_rows=None):
    """Render every LED of `leds` on the scene of `spec` (a `facette.sim.scene.SceneSpec`) into
    `folder`, `band_rows` rows at a time (None: `band_rows_for` the width): led_XX.npy
    (`RadianceOnDisk`) and truth_<name>.npy (`TRUTH_ARRAYS`), then render.json, what the render
    depends on. Returns the `RadianceOnDisk`. A folder that already holds the same render (its
    render.json) is used as it is: at 11648x8736 the render takes half an hour on two cores."""
    folder.mkdir(parents=True, exist_ok=True)
    hh, ww = spec.shape
    stamp = _stamp(spec, leds, electrons_per_mA_s, shadows)
    if _rendered(folder, RadianceOnDisk(folder, len(leds), (hh, ww)), stamp):
        return RadianceOnDisk(folder, len(leds), (hh, ww))
    (folder / RENDER_STAMP).unlink(missing_ok=True)
    step = int(band_rows) if band_rows else band_rows_for(ww)
    height = np.empty((hh, ww))
    for r0 in range(0, hh, step):    # the whole height field: the shadows' rays read it
        height[r0:r0 + step] = spec.rows(r0, min(r0 + step, hh)).height_mm
    reaches = [led_reach(height, spec.pixel_pitch_mm, leds, i, band_rows=step) if shadows else None
               for i in range(len(leds))]
    disk = RadianceOnDisk(folder, len(leds), (hh, ww))
    files = [open(disk.path(i), "wb") for i in range(len(leds))]
    truth = {name: open(folder / f"truth_{name}.npy", "wb") for name in TRUTH_ARRAYS}
    try:
        for fh in files:
            _header(fh, np.float64, (hh, ww, 3))
        for name, (dtype, ch) in TRUTH_ARRAYS.items():
            _header(truth[name], dtype, (hh, ww, ch) if ch else (hh, ww))
        for r0 in range(0, hh, step):
            band = spec.rows(r0, min(r0 + step, hh))
            for name, (dtype, _) in TRUTH_ARRAYS.items():
                truth[name].write(np.ascontiguousarray(getattr(band, name), dtype).tobytes())
            for i, fh in enumerate(files):
                fh.write(radiance_rows(band, leds, i, r0, height, reaches[i], electrons_per_mA_s).tobytes())
    finally:
        for fh in [*files, *truth.values()]:
            fh.close()
    (folder / RENDER_STAMP).write_text(stamp)
    return disk
