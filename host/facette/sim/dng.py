"""Minimal real DNG writer (uncompressed CFA, one IFD) for the simulated camera.

The files are plain TIFF with the DNG tags LibRaw needs; rawpy decodes them
bit-exactly (tested). ExposureTime and ISO are written in the EXIF-style tags of
IFD0 (rawpy does not expose them: `facette.camera.raw` reads them with tifffile).
"""
import json
import os
from fractions import Fraction
from pathlib import Path

import numpy as np
import tifffile

__all__ = ["write_dng", "CFA_PATTERNS", "MIN_SIDE"]

# LibRaw's identify() rejects any image with a side under 22 pixels.
MIN_SIDE = 22

# CFA pattern codes (0 = R, 1 = G, 2 = B) of the 2×2 repeat, row major.
CFA_PATTERNS = {"RGGB": (0, 1, 1, 2), "BGGR": (2, 1, 1, 0), "GRBG": (1, 0, 2, 1),
                "GBRG": (1, 2, 0, 1)}


def _exposure_rational(exposure_time_s):
    # Microsecond resolution is what the rig controls; keep both terms within uint32.
    frac = Fraction(float(exposure_time_s)).limit_denominator(1_000_000)
    num, den = frac.numerator, frac.denominator
    while num > 0xFFFFFFFF or den > 0xFFFFFFFF:
        num, den = max(num // 2, 1), max(den // 2, 1)
    return num, den


def write_dng(path, mosaic_uint16, black_level, white_level, exposure_time_s, iso, cfa="RGGB",
              make="facette", model="sim", extra=None):
    """Write a Bayer mosaic as an uncompressed DNG, atomically.

    Parameters
    ----------
    path : str or Path
        Destination (``.dng``). Written to a temporary name in the same folder and
        renamed, so a folder watcher never sees half a file.
    mosaic_uint16 : ndarray (H, W), uint16, H and W even and >= MIN_SIDE (22)
        Raw CFA values in DN, black level included.
    black_level, white_level : int
        DN; written as BlackLevel / WhiteLevel.
    exposure_time_s : float, > 0
        Exposure time, seconds (ExposureTime rational, µs resolution).
    iso : int
        ISO speed (ISOSpeedRatings).
    cfa : str
        2×2 pattern, one of ``CFA_PATTERNS`` (default ``"RGGB"``).
    make, model : str
        Make / Model tags.
    extra : dict or None
        JSON-serialisable metadata stored in ImageDescription (e.g. light, exposure
        and frame indices, current in mA).

    Returns
    -------
    Path of the written file.
    """
    raw = np.asarray(mosaic_uint16)
    if raw.ndim != 2 or raw.shape[0] % 2 or raw.shape[1] % 2 or raw.size == 0:
        raise ValueError(f"a Bayer mosaic must be 2-D with even, non-zero sides; got {raw.shape}")
    if min(raw.shape) < MIN_SIDE:
        raise ValueError(f"mosaic {raw.shape} is too small: LibRaw (rawpy) refuses images with a side "
                         f"under {MIN_SIDE} photosites; simulate at least {MIN_SIDE}×{MIN_SIDE}")
    if raw.dtype != np.uint16:
        if np.issubdtype(raw.dtype, np.integer) and raw.min() >= 0 and raw.max() <= 0xFFFF:
            raw = raw.astype(np.uint16)
        else:
            raise ValueError(f"mosaic must hold uint16 DN values, got dtype {raw.dtype}")
    if cfa not in CFA_PATTERNS:
        raise ValueError(f"unknown CFA pattern {cfa!r}; choose from {sorted(CFA_PATTERNS)}")
    black, white = int(black_level), int(white_level)
    if not 0 <= black < white <= 0xFFFF:
        raise ValueError(f"need 0 <= black_level ({black}) < white_level ({white}) <= 65535")
    if not exposure_time_s > 0:
        raise ValueError(f"exposure_time_s must be > 0 seconds, got {exposure_time_s}")
    description = json.dumps(extra or {}, sort_keys=True)
    extratags = [
        (50706, "B", 4, (1, 4, 0, 0), True),             # DNGVersion
        (50707, "B", 4, (1, 1, 0, 0), True),             # DNGBackwardVersion
        (50708, "s", 0, f"{make} {model}", True),        # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),                   # CFARepeatPatternDim
        (33422, 1, 4, CFA_PATTERNS[cfa], True),          # CFAPattern
        (50710, "B", 3, (0, 1, 2), True),                # CFAPlaneColor
        (50711, "H", 1, 1, True),                        # CFALayout: rectangular
        (50714, "H", 1, black, True),                    # BlackLevel
        (50717, "H", 1, white, True),                    # WhiteLevel
        # ColorMatrix1 = identity (SRATIONAL pairs): the sim camera is "raw RGB".
        (50721, 10, 9, (1, 1, 0, 1, 0, 1, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1, 1, 1), True),
        (50778, "H", 1, 21, True),                       # CalibrationIlluminant1 = D65
        (50728, 5, 3, (1, 1, 1, 1, 1, 1), True),         # AsShotNeutral
        (33434, 5, 1, _exposure_rational(exposure_time_s), True),  # ExposureTime
        (34855, "H", 1, int(iso), True),                 # ISOSpeedRatings
        (271, "s", 0, str(make), True),                  # Make
        (272, "s", 0, str(model), True),                 # Model
        (270, "s", 0, description, True),                # ImageDescription
    ]
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        tifffile.imwrite(tmp, raw, photometric=32803, compression=None, subfiletype=0,
                         metadata=None, extratags=extratags)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path
