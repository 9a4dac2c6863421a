"""Published peers (recon/_ps_peers.py): a non-Lambertian sphere better than least squares, and
black, saturated and shadowed pixels give finite output or are marked not valid."""
import numpy as np
import pytest

from facette.methods import PS_METHODS, photometric_stereo

from peer_scenes import blinn_phong, sphere
from peer_scenes import lights as scene_lights

PEERS = ("bipolynomial_shi2014", "bivariate_ikehata2014")


def _mean_error(res, n, mask):
    dot = np.clip(np.sum(res.normal * n, -1), -1, 1)
    return float(np.degrees(np.arccos(dot))[mask].mean())


@pytest.mark.parametrize("method", PEERS)
def test_peer_recovers_glossy_sphere_better_than_least_squares(method):
    n, mask = sphere()
    lights = scene_lights()
    img = blinn_phong(n, lights, noise=0.005)
    ls = _mean_error(photometric_stereo(img, lights, method="woodham1980", mask=mask), n, mask)
    res = photometric_stereo(img, lights, method=method, mask=mask)
    err = _mean_error(res, n, mask)
    assert res.valid[mask].mean() > 0.99
    assert err < 0.5 * ls, (err, ls)
    assert err < 5.0


@pytest.mark.parametrize("method", PEERS)
def test_peer_is_exact_on_lambertian(method):
    n, mask = sphere(24)
    lights = scene_lights(24)
    img = blinn_phong(n, lights, ks=0.0)
    res = photometric_stereo(img, lights, method=method, mask=mask)
    # pixels whose lit lights are too few for the model are not valid; the others are exact
    assert res.valid[mask].mean() > 0.9
    good = res.valid & mask
    assert _mean_error(res, n, good) < 0.1


@pytest.mark.parametrize("method", PEERS)
def test_peer_black_saturated_and_shadowed_pixels(method):
    n, mask = sphere(16)
    lights = scene_lights(30)
    img = blinn_phong(n, lights)
    img[:, 3, 8] = 0.0                                 # black everywhere
    img[:, 8, 3] = np.nan                              # saturated (missing) everywhere
    img[:20, 8, 8] = 0.0                               # shadowed under most lights
    img[:, 8, 12] = np.where(np.arange(len(img)) < 27, 0.0, img[:, 8, 12])   # lit by 3 lights only
    res = photometric_stereo(img, lights, method=method, mask=mask, saturation=10.0)
    assert np.all(np.isfinite(res.normal)) and np.all(np.isfinite(res.albedo))
    assert np.all(np.isfinite(res.residual))
    for r, c in ((3, 8), (8, 3), (8, 12)):
        assert not res.valid[r, c]
        assert np.all(res.normal[r, c] == 0)
    norms = np.linalg.norm(res.normal[res.valid], axis=-1)
    assert np.allclose(norms, 1, atol=1e-5)


@pytest.mark.parametrize("method", PEERS)
def test_peer_metal_without_diffuse_part_gives_finite_output(method):
    """A mirror-like lobe and no diffuse part (a metal): most pixels are black under every
    light; the output stays finite, unit normals where valid, zero where not."""
    n, mask = sphere(24)
    lights = scene_lights(24)
    img = blinn_phong(n, lights, kd=0.0, ks=1.0, shininess=200.0)
    res = photometric_stereo(img, lights, method=method, mask=mask)
    assert np.all(np.isfinite(res.normal)) and np.all(np.isfinite(res.albedo))
    norms = np.linalg.norm(res.normal, axis=-1)
    assert np.allclose(norms[res.valid], 1, atol=1e-5) and np.all(norms[~res.valid] == 0)


@pytest.mark.parametrize("method", PEERS)
def test_peer_refuses_near_lights_and_bad_options(method):
    n, mask = sphere(8)
    lights = scene_lights(8)
    img = blinn_phong(n, lights)
    per_pixel = np.broadcast_to(lights, (8, 8, 8, 3))
    with pytest.raises(ValueError, match="distant lights"):
        photometric_stereo(img, per_pixel, method=method, mask=mask)
    with pytest.raises(ValueError, match="t_shadow"):
        photometric_stereo(img, lights, method=method, mask=mask, t_shadow=1.5)


def test_peers_are_registered_with_short_names():
    assert PS_METHODS.canonical("st14") == "bipolynomial_shi2014"
    assert PS_METHODS.canonical("IA14") == "bivariate_ikehata2014"


def test_empty_mask_gives_an_empty_result():
    n, _ = sphere(8)
    lights = scene_lights(8)
    img = blinn_phong(n, lights)
    for method in PEERS:
        res = photometric_stereo(img, lights, method=method, mask=np.zeros((8, 8), bool))
        assert not res.valid.any()


def test_ia14_paper_form_and_the_variant_recover_a_glossy_sphere():
    n, mask = sphere()
    lights = scene_lights()
    img = blinn_phong(n, lights, noise=0.005)
    ls = _mean_error(photometric_stereo(img, lights, method="woodham1980", mask=mask), n, mask)
    for form in ("paper", "variant"):
        res = photometric_stereo(img, lights, method="ia14", mask=mask, form=form)
        assert res.info["form"] == form
        assert _mean_error(res, n, mask & res.valid) < 0.5 * ls
    with pytest.raises(ValueError, match="form"):
        photometric_stereo(img, lights, method="ia14", mask=mask, form="lsqlin")


def test_ia14_retro_test_keeps_the_better_run():
    from facette.recon._ia14_paper import ia14_paper_normals
    n, mask = sphere(16)
    lights = scene_lights(40)
    img = blinn_phong(n, lights)
    e = img[:, mask].T.astype(np.float64)
    w = (e > 0.02 * e.max(axis=1, keepdims=True)).astype(float)
    one, r_one = ia14_paper_normals(e, w, lights, retro=False)
    both, r_both = ia14_paper_normals(e, w, lights, retro=True)
    assert np.all(r_both <= r_one + 1e-12)
    err = np.degrees(np.arccos(np.clip(np.sum(both * n[mask], 1), -1, 1)))
    assert np.median(err) < 3.0


def test_st14_recovers_a_bi_polynomial_sphere_and_its_darkest_half_is_kept():
    """A reflectance inside ST14's model, ρ = 0.2 + 0.5 cos²θ_h (α >= 0), on a sphere under
    48 lights with a sharp lobe on top: the normals within 0.3°, far better than least squares;
    the lights above the kept darkest half are marked specular, the kept ones never."""
    n, mask = sphere(24)
    lights = scene_lights(48)
    h = (lights + [0, 0, 1.0]) / np.linalg.norm(lights + [0, 0, 1.0], axis=1, keepdims=True)
    nl = np.clip(np.einsum("hwk,mk->mhw", n, lights), 0, None)
    nh = np.clip(np.einsum("hwk,mk->mhw", n, h), 0, None)
    img = (nl * (0.2 + 0.5 * nh ** 2) + 2.0 * nh ** 200 * nl).astype(np.float32)
    ls = _mean_error(photometric_stereo(img, lights, method="woodham1980", mask=mask), n, mask)
    res = photometric_stereo(img, lights, method="st14", mask=mask)
    good = mask & res.valid
    assert good.sum() > 0.95 * mask.sum()
    assert _mean_error(res, n, good) < 0.3 < ls
    lit = (img > 0.1 * img.max(axis=0))[:, good]
    kept = lit & ~res.specular.transpose(2, 0, 1)[:, good]
    assert np.all(kept.sum(0) == np.ceil(0.5 * lit.sum(0)))
    with pytest.raises(ValueError, match="t_low"):
        photometric_stereo(img, lights, method="st14", mask=mask, t_low=0.0)


def test_st14_coefficients_are_never_negative():
    from facette.recon._ps_peers import _nonneg_lstsq, _projected_lstsq
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 1, (200, 12, 3))
    y = np.einsum("nmp,np->nm", a, rng.normal(0, 1, (200, 3)))
    w = np.ones((200, 12))
    c, r = _nonneg_lstsq(a, y, w)
    c_free, r_free = _projected_lstsq(a, y, w)
    assert np.all(c >= 0)
    free_ok = np.all(c_free >= 0, axis=1)          # where the free solution is feasible, it is the answer
    assert free_ok.any() and (~free_ok).any()
    assert np.allclose(c[free_ok], c_free[free_ok], atol=1e-6)
    assert np.all(np.sum(r * r, 1) >= np.sum(r_free * r_free, 1) - 1e-9)
