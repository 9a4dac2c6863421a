"""The measures tried for the uncertainty band and not taken (bench._uncertainty_candidates): the
jackknife's rank-one downdates equal solving again without each light, the shared-table residual sees
a pixel in cast shadow, and every measure comes out finite over a render."""
import numpy as np

from facette.bench._uncertainty_candidates import (CANDIDATES, GLOBAL_CANDIDATES, PHYSICS_CANDIDATES,
                                                  candidate_spearman,
                                                  jackknife_lambertian, table_residual)
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def test_jackknife_equals_solving_again_without_each_light():
    rng = np.random.default_rng(0)
    L = thesis_light_directions()
    n = np.array([0.2, -0.3, 0.93])
    e = np.maximum(L @ n, 0)[None] * 0.8 + 0.02 * rng.normal(size=(1, len(L)))
    w = (L @ n > 0).astype(float)[None]
    jack, rel, smallest, unit = jackknife_lambertian(e, w, L)
    kept = np.flatnonzero(w[0])
    full = np.linalg.lstsq(L[kept], e[0, kept], rcond=None)[0]
    angles = []
    for i in kept:
        rest = kept[kept != i]
        b = np.linalg.lstsq(L[rest], e[0, rest], rcond=None)[0]
        across = b - (b @ full / (full @ full)) * full
        angles.append(np.linalg.norm(across) / np.linalg.norm(full))
    k = len(kept)
    assert np.allclose(unit[0], full / np.linalg.norm(full))
    assert np.isclose(jack[0], np.sqrt((k - 1) / k * np.sum(np.square(angles))), rtol=1e-6)
    assert 0 < rel[0] < 0.1 and smallest[0] > 0


def test_table_residual_sees_a_pixel_in_cast_shadow():
    L = thesis_light_directions()
    sc = sphere_on_plane(24, 24)
    sel = sc.mask & (sc.normals[..., 2] > 0.3) & (sc.normals[..., 2] < 0.999)      # the sphere, not the plane
    e = render(sc, L, "matte", noise=0.0).astype(np.float64).mean(-1)[:, sel].T
    odd = np.arange(0, len(e), 7)                  # one pixel in seven: its two brightest lights hidden
    top = np.argsort(-e[odd], axis=1)[:, :2]
    e[odd[:, None], top] = 0.0
    r = table_residual(e, np.ones_like(e, bool), sc.normals[sel], L)
    rest = np.setdiff1d(np.arange(len(e)), odd)
    assert np.median(r[odd]) > 3 * np.median(r[rest])


def test_every_candidate_is_scored_on_a_render():
    L = thesis_light_directions()
    sc = sphere_on_plane(24, 24)
    im = render(sc, L, "satin", noise=0.01, rng=np.random.default_rng(1)).astype(np.float32)
    tilt = sc.normals + 0.05 * np.random.default_rng(2).normal(size=sc.normals.shape)
    tilt /= np.linalg.norm(tilt, axis=-1, keepdims=True)
    sel = sc.mask
    err = np.degrees(np.arccos(np.clip(np.sum(tilt[sel] * sc.normals[sel], -1), -1, 1)))
    rho = candidate_spearman(im, L, tilt, sel, err)
    assert tuple(rho) == CANDIDATES + PHYSICS_CANDIDATES + GLOBAL_CANDIDATES
    constant = ("kept lights", "backlit share", "hidden lights")         # all alike on a convex sphere
    assert all(np.isfinite(v) and -1 <= v <= 1 for k, v in rho.items() if k not in constant)
