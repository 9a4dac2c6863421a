"""Large test captures: a relief slab with known normals and heights at any size, written band
by band as a DiLiGenT-style folder (memory bounded by the band, not the image).

The slab's height is a sum of sinusoids and round bosses scaled with the image, so its slopes
(median 25 deg, 99 % under 45, at most 50) and so its normals' statistics are the same at every size. It is lit by the
rig's 12 directions (`recon.synthetic.thesis_light_directions`) and rendered Lambert plus a
weak Blinn-Phong highlight, with attached shadows (no cast shadows), as 16-bit RGB PNGs.

Folder: 001.png ... 012.png, filenames.txt, light_directions.txt, light_intensities.txt,
mask.png (the whole frame), and the truth beside them: normal_gt.npy (H, W, 3) float32 unit
vectors and height_gt.npy (H, W) float32 in pixels.
"""
from pathlib import Path

import numpy as np

from facette.io.png import PngBandWriter
from facette.recon.synthetic import thesis_light_directions

__all__ = ["write_relief_capture", "relief_surface", "npy_band_writer", "slab_to_scan", "BAND_PIXELS"]

BAND_PIXELS = 1 << 20          # pixels rendered at once (~0.4 GB of float64 temporaries)
GAIN = 2.5                     # PNG value = GAIN x radiance x 65535; light_intensities say GAIN
KS, SHININESS = 0.04, 40.0     # the highlight: weak, so that every method sees a Lambertian slab
_WAVES = ((0.012, 6.0, 4.0, 0.0), (0.010, 3.0, -5.0, 1.0), (0.0025, 17.0, 11.0, 2.0))
_BOSSES = ((0.3, 0.35, 0.12, 0.05), (0.7, 0.6, 0.18, 0.07), (0.45, 0.8, 0.08, 0.03))


def relief_surface(rows, cols, scale):
    """Height (pixels) and unit normals of the slab at pixel rows `rows` (R,) and columns
    `cols` (W,), for an image whose smaller side is `scale` px. Camera frame: x right, y up
    (rows go down), z towards the camera. Returns height (R, W), normals (R, W, 3) float64."""
    u = (cols[None, :] + 0.5) / scale
    v = (rows[:, None] + 0.5) / scale
    z = np.zeros((rows.size, cols.size))
    zu = np.zeros_like(z)
    zv = np.zeros_like(z)
    for a, fu, fv, ph in _WAVES:
        arg = 2 * np.pi * (fu * u + fv * v) + ph
        z += a * np.sin(arg)
        zu += a * 2 * np.pi * fu * np.cos(arg)
        zv += a * 2 * np.pi * fv * np.cos(arg)
    for cu, cv, r, a in _BOSSES:                  # Gaussian bosses at fixed places of the slab
        g = a * np.exp(-((u - cu) ** 2 + (v - cv) ** 2) / (2 * r * r))
        z += g
        zu += g * -(u - cu) / (r * r)
        zv += g * -(v - cv) / (r * r)
    # dz/dx = zu (x with columns); dz/dy = -zv (y up, rows down); heights in pixels
    n = np.stack([-zu, zv, np.ones_like(z)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return z * scale, n


def _albedo(rows, cols, scale):
    u = (cols[None, :] + 0.5) / scale
    v = (rows[:, None] + 0.5) / scale
    t = 0.5 + 0.5 * np.sin(2 * np.pi * (2.0 * u + 1.5 * v))
    base = np.array([0.62, 0.52, 0.42])
    return base * (0.75 + 0.25 * t)[..., None]


def npy_band_writer(path, shape):
    """An open file with a .npy header for a float32 array of `shape`: write its rows' bytes
    (little-endian float32, C order) band by band, then close it."""
    f = open(path, "wb")
    np.lib.format.write_array_header_1_0(f, {"descr": "<f4", "fortran_order": False, "shape": shape})
    return f


def write_relief_capture(folder, width, height, band_pixels=BAND_PIXELS, compression=1):
    """Write the slab at width x height px into `folder` (created) band by band.
    Returns the folder (a Path)."""
    width, height = int(width), int(height)
    if width < 8 or height < 8:
        raise ValueError(f"a relief capture needs at least 8x8 px, got {width}x{height}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lights = thesis_light_directions()
    m = len(lights)
    names = [f"{i + 1:03d}.png" for i in range(m)]
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    np.savetxt(folder / "light_directions.txt", lights, fmt="%.8f")
    np.savetxt(folder / "light_intensities.txt", np.full((m, 3), GAIN), fmt="%.8f")
    scale = min(width, height)
    rows_per_band = max(1, band_pixels // width)
    cols = np.arange(width)
    view = np.array([0.0, 0.0, 1.0])
    halves = lights + view
    halves /= np.linalg.norm(halves, axis=1, keepdims=True)
    writers = [PngBandWriter(folder / name, width, height, 3, np.uint16, compression) for name in names]
    mask_writer = PngBandWriter(folder / "mask.png", width, height, 1, np.uint8, compression)
    f_n = npy_band_writer(folder / "normal_gt.npy", (height, width, 3))
    f_h = npy_band_writer(folder / "height_gt.npy", (height, width))
    try:
        for r0 in range(0, height, rows_per_band):
            rows = np.arange(r0, min(height, r0 + rows_per_band))
            z, n = relief_surface(rows, cols, scale)
            rho = _albedo(rows, cols, scale)
            f_n.write(n.astype("<f4").tobytes())
            f_h.write(z.astype("<f4").tobytes())
            mask_writer.write(np.full((rows.size, width), 255, np.uint8))
            for writer, l, hv in zip(writers, lights, halves):
                nl = np.maximum(n @ l, 0.0)
                spec = KS * np.maximum(n @ hv, 0.0) ** SHININESS * (nl > 0)
                e = rho / np.pi * nl[..., None] + spec[..., None]
                writer.write(np.clip(np.rint(e * GAIN * 65535), 0, 65535).astype(np.uint16))
        for writer in writers + [mask_writer]:
            writer.close()
    finally:
        f_n.close()
        f_h.close()
    return folder


def slab_to_scan(folder, scan_dir):
    """The slab's DiLiGenT folder as a scan directory, one light at a time: radiance = PNG / 65535
    (NaN where clipped), variance 1e-6 x radiance + 1e-9 (every sample above the noise)."""
    from facette.io.diligent import read_diligent_lights
    from facette.io.exr import write_exr
    from facette.io.png import read_png
    from facette.scan import ScanDirectory
    folder, scan_dir = Path(folder), Path(scan_dir)
    names, dirs, inten, _ = read_diligent_lights(folder)
    (scan_dir / "hdr").mkdir(parents=True)
    for i, name in enumerate(names):
        raw = read_png(folder / name)
        e = raw.astype(np.float32) / np.float32(65535)
        e[raw >= 65535] = np.nan
        del raw
        write_exr(scan_dir / "hdr" / f"light_{i:02d}.exr", e, compression="none")
        write_exr(scan_dir / "hdr" / f"light_{i:02d}_var.exr", np.nan_to_num(e, nan=np.inf) * 1e-6 + 1e-9,
                  compression="none")
        del e
    lights = [{"index": i, "direction": dirs[i].tolist(), "position_mm": None, "intensity": inten[i].tolist()}
              for i in range(len(names))]
    sd = ScanDirectory(scan_dir)
    sd.create(rig={"id": "synthetic"}, profile=None, pixel_pitch_mm=0.05, lights=lights, exposures=[], plan=None)
    sd.save()
    return scan_dir
