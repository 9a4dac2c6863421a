"""Small inputs made in code for the documentation's examples and pictures: an RTI capture (JPEG
photographs and an .lp file, RTIBuilder's layout) and a DiLiGenT-style folder, both of a glossy
sphere on a plane rendered by `facette.recon.synthetic`. A few seconds, a few hundred kB."""
import argparse
from pathlib import Path

import cv2
import numpy as np

from facette.calib.lp import write_lp
from facette.io.diligent import write_diligent
from facette.recon.synthetic import render, sphere_on_plane


def dome_lights(count=16):
    """`count` directions, 10-60 degrees from the view and all around, as a small dome has."""
    az = np.radians(np.arange(count) * 360.0 / count)
    el = np.radians(np.resize([15.0, 30.0, 45.0, 60.0], count))
    return np.c_[np.sin(el) * np.cos(az), np.sin(el) * np.sin(az), np.cos(el)]


def _images(height, width, lights):
    scene = sphere_on_plane(height, width, radius=min(height, width) * 0.36)
    imgs = render(scene, lights, "satin", albedo=(0.7, 0.55, 0.4), cast_shadows=False)
    return scene, np.clip(imgs / np.percentile(imgs, 99.5) * 0.9, 0, 1)


def _srgb(v):
    v = np.clip(v, 0, 1)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def rti_capture(folder, height=96, width=128, count=16):
    """A folder of JPEGs (8-bit sRGB, as a camera writes them) and `capture.lp`; returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lights = dome_lights(count)
    _, imgs = _images(height, width, lights)
    names = []
    for i, im in enumerate(imgs):
        names.append(f"IMG_{i:04d}.jpg")
        cv2.imwrite(str(folder / names[-1]), np.round(_srgb(im)[..., ::-1] * 255).astype(np.uint8),
                    [cv2.IMWRITE_JPEG_QUALITY, 95])
    write_lp(folder / "capture.lp", names, lights)
    return folder


def diligent_folder(folder, height=96, width=128, count=16):
    """A DiLiGenT-style folder (16-bit PNGs, light_directions.txt, mask.png); returns the folder."""
    lights = dome_lights(count)
    scene, imgs = _images(height, width, lights)
    write_diligent(folder, np.round(imgs * 65535).astype(np.uint16), lights, mask=scene.mask)
    return Path(folder)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("kind", choices=("rti", "diligent"))
    p.add_argument("folder")
    args = p.parse_args(argv)
    (rti_capture if args.kind == "rti" else diligent_folder)(args.folder)
    print(args.folder)


if __name__ == "__main__":
    main()
