"""`facette bench uncertainty`'s before/after split: taking the curl term out of the written band gives
the local fit's band alone."""
import numpy as np

from facette.bench.uncertainty import before_after, score
from facette.recon import _uncertainty as unc
from facette.recon import normal_uncertainty
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def test_before_is_the_local_fits_band(monkeypatch):
    L = thesis_light_directions()
    sc = sphere_on_plane(24, 24)
    im = render(sc, L, "satin", noise=0.01, rng=np.random.default_rng(1)).astype(np.float32)
    after = normal_uncertainty(im, L, sc.normals, sc.mask)
    monkeypatch.setattr(unc, "K_CURL", 0.0)
    alone = normal_uncertainty(im, L, sc.normals, sc.mask)
    monkeypatch.undo()
    before, same = before_after(after, sc.normals)
    assert same is after and np.allclose(before, alone, atol=1e-3)
    rho, cov, _, _ = score(np.array([1.0, 2.0, 3.0]), np.array([0.5, 2.5, 2.9]))
    assert rho == 1.0 and np.isclose(cov, 2 / 3)
