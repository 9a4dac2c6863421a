"""The rendered satin sphere lying on a plane that two pipeline tests share: local shading and cast shadows
only (no inter-reflections), relative intensities, a DiLiGenT-style folder."""
import numpy as np

from facette.io.diligent import write_diligent
from facette.recon.synthetic import render, sphere_on_plane


def satin_sphere_on_a_plane(folder, m=24):
    """The folder (40 x 48 px, m lights drawn above the plane, 16-bit PNGs); returns it."""
    rng = np.random.default_rng(5)
    d = rng.normal(size=(m, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sc = sphere_on_plane(40, 48, radius=14)
    imgs = render(sc, d, "satin", albedo=(0.7, 0.6, 0.5))
    write_diligent(folder, np.round(imgs / imgs.max() * 60000).astype(np.uint16), d, mask=sc.mask)
    return folder
