"""The uncertainty of each normal (recon/_uncertainty.py) ranks the true errors and its 90 % band
holds about 90 % of the normals, on a generated sphere whose noise grows across the picture."""
import numpy as np
import pytest
from scipy.stats import spearmanr

from facette.methods import photometric_stereo
from facette.recon import normal_uncertainty, uncertainty_summary
from facette.recon import _uncertainty as unc
from facette.recon._uncertainty import MAX_DEG, curl_angle
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()


def _noisy_sphere(size=64, seed=0):
    """A satin sphere on a plane; the relative noise grows from 0.2 % (left) to 4 % (right)."""
    sc = sphere_on_plane(size, size)
    im = render(sc, L, "satin").astype(np.float64)
    level = np.linspace(0.002, 0.04, size)[None, None, :, None]
    im *= 1 + level * np.random.default_rng(seed).standard_normal(im.shape)
    return sc, im.astype(np.float32)


def _errors(n, truth, sel):
    return np.degrees(np.arccos(np.clip(np.sum(n * truth, -1), -1, 1)))[sel]


@pytest.mark.parametrize("method", ["woodham1980", "rank_trimmed"])
def test_uncertainty_ranks_the_errors_and_its_band_holds_them(method, monkeypatch):
    sc, im = _noisy_sphere()
    r = photometric_stereo(im, L, method=method, mask=sc.mask)
    sel = sc.mask & r.valid
    u = normal_uncertainty(im, L, r.normal, sel)
    err, uu = _errors(r.normal, sc.normals, sel), u[sel]
    assert spearmanr(uu, err).statistic >= 0.5
    assert np.mean(err <= uu) >= 0.9           # the curl adds to the band: noise alone is over-covered
    assert np.all(u[~sel] == 0) and u.dtype == np.float32
    monkeypatch.setattr(unc, "K_CURL", 0.0)    # the local fit's band alone is calibrated on noise
    fit_only = normal_uncertainty(im, L, r.normal, sel)[sel]
    assert 0.8 <= np.mean(err <= fit_only) <= 0.99 and np.all(fit_only <= uu + 1e-4)


def _bumps(size=48):
    """Unit normals (size, size, 3) of the height field z = 3 sin(x/5) cos(y/7) (pixels)."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    zx, zy = 0.6 * np.cos(x / 5) * np.cos(y / 7), -3 / 7 * np.sin(x / 5) * np.sin(y / 7)
    n = np.stack([-zx, zy, np.ones_like(zx)], -1)         # rows run down as y runs up
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _swirled(n, centre=(24, 24), radius=6.0, slope=0.3):
    """n with a swirl of slopes (curl, no surface's) added in a disc: the kind of error
    inter-reflections and shadows leave. Returns (normals, the disc)."""
    y, x = np.mgrid[0:n.shape[0], 0:n.shape[1]].astype(np.float64)
    dy, dx = y - centre[0], x - centre[1]
    g = slope * np.exp(-(dx * dx + dy * dy) / (2 * radius ** 2))
    p, q = -n[..., 0] / n[..., 2] - g * dy / radius, n[..., 1] / n[..., 2] + g * dx / radius
    out = np.stack([-p, q, np.ones_like(p)], -1)
    return out / np.linalg.norm(out, axis=-1, keepdims=True), dx * dx + dy * dy < radius ** 2


def test_curl_is_nil_on_a_surface_and_finds_a_swirl():
    n = _bumps()
    mask = np.ones(n.shape[:2], bool)
    assert np.degrees(curl_angle(n, mask)).max() < 0.3       # every field of a surface: ~0
    sw, disc = _swirled(n)
    c = np.degrees(curl_angle(sw, mask))
    y, x = np.mgrid[0:48, 0:48]
    far = np.hypot(y - 24, x - 24) > 20           # beyond the swirl's reach (3.3 radii and the gather)
    assert np.median(c[disc]) > 2 and c[far].max() < 0.3
    assert np.all(curl_angle(n, np.zeros_like(mask)) == 0)


def test_a_swirl_the_data_explain_is_less_certain():
    """Images rendered from the swirled normals (the data agree with the wrong normal, as with
    inter-reflections): the local fit sees nothing, the curl does."""
    n = _bumps()
    sw, disc = _swirled(n)
    im = np.maximum(np.einsum("hwi,mi->mhw", sw, L), 0).astype(np.float32)
    u = normal_uncertainty(im, L, sw, None)
    err = _errors(sw, n, np.ones(disc.shape, bool)).reshape(disc.shape)
    inside = disc & (err > 2)
    assert np.median(u[inside]) > 5 * np.median(u[~disc]) and np.mean(err[inside] <= u[inside]) > 0.6


def test_wrong_normals_are_less_certain():
    sc, im = _noisy_sphere(48)
    sel = sc.mask
    tilt = np.radians(8.0)                 # every normal rotated 8° about the view axis' x
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    wrong = sc.normals @ rot.T
    good_u = normal_uncertainty(im, L, sc.normals, sel)[sel]
    wrong_u = normal_uncertainty(im, L, wrong, sel)[sel]
    assert np.median(wrong_u) > 2 * np.median(good_u)


def test_pixels_without_lights_or_normal_and_bad_shapes():
    sc, im = _noisy_sphere(16)
    im[:, 4, 4] = 0.0                               # black under every light: nothing known
    n = sc.normals.copy()
    n[5, 5] = 0.0                                   # no normal: not rated
    u = normal_uncertainty(im, L, n, np.ones((16, 16), bool))
    assert u[4, 4] == MAX_DEG and u[5, 5] == 0
    assert np.all(np.isfinite(u))
    with pytest.raises(ValueError, match="normals"):
        normal_uncertainty(im, L, n[:8], None)
    with pytest.raises(ValueError, match="light_dirs"):
        normal_uncertainty(im, L[:5], n, None)
    with pytest.raises(ValueError, match="images"):
        normal_uncertainty(im[0, 0], L, n, None)


def test_near_lights_per_pixel_give_the_same_as_distant():
    sc, im = _noisy_sphere(16)
    per_pixel = np.broadcast_to(L[None, None], (16, 16, len(L), 3))
    a = normal_uncertainty(im, L, sc.normals, sc.mask)
    b = normal_uncertainty(im, per_pixel, sc.normals, sc.mask)
    assert np.allclose(a, b, rtol=1e-4, atol=1e-4)


def test_summary():
    u = np.array([[1.0, 2.0], [3.0, 50.0]], np.float32)
    s = uncertainty_summary(u, np.array([[1, 1], [1, 0]], bool))
    assert s["median_deg"] == 2.0 and 2.5 < s["p90_deg"] < 3.0
    assert "whole object" in s["not_in_band"]        # a global error is named, not put in the ranking
    assert uncertainty_summary(u, np.zeros((2, 2), bool)) is None


def test_large_maps_are_computed_on_a_coarser_grid():
    sc, im = _noisy_sphere(48)
    full = normal_uncertainty(im, L, sc.normals, sc.mask)
    coarse = normal_uncertainty(im, L, sc.normals, sc.mask, max_values=400 * 12)
    assert np.all(coarse[~sc.mask] == 0) and np.all(coarse[sc.mask] > 0)
    # the same map, in cells of a few pixels: the medians agree
    assert abs(np.median(coarse[sc.mask]) / np.median(full[sc.mask]) - 1) < 0.2
