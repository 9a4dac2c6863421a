"""Consensus photometric stereo (recon/_ps_consensus.py, HM10): a Lambertian sphere, a glossy one
far better than least squares, an increasing camera response that changes nothing, and black,
saturated, shadowed and barely lit pixels finite and marked not valid."""
import numpy as np
import pytest

from facette.methods import PS_METHODS, photometric_stereo
from facette.recon import ps_consensus_higo2010, ps_woodham1980

from peer_scenes import blinn_phong, sphere
from peer_scenes import lights as scene_lights


def _errors(res, n, sel):
    dot = np.clip(np.sum(res.normal * n, -1), -1, 1)
    return np.degrees(np.arccos(dot))[sel]


def test_lambertian_sphere_within_a_degree_and_a_half():
    n, mask = sphere(48)
    lights = scene_lights(32)
    res = ps_consensus_higo2010(blinn_phong(n, lights, ks=0.0), lights, mask=mask)
    assert res.valid[mask].all()
    err = _errors(res, n, mask)
    assert err.mean() < 1.5 and np.percentile(err, 95) < 3.5, (err.mean(), np.percentile(err, 95))   # 1.0, 2.6
    assert np.allclose(np.linalg.norm(res.normal[mask], axis=-1), 1, atol=1e-5)
    assert res.method == "consensus_higo2010" and res.info["pixels"] == mask.sum()


def test_glossy_sphere_far_better_than_least_squares():
    n, mask = sphere(48)
    lights = scene_lights(32)
    img = blinn_phong(n, lights, noise=0.005)
    ls = _errors(ps_woodham1980(img, lights, mask=mask), n, mask).mean()
    res = photometric_stereo(img, lights, method="hm10", mask=mask)
    err = _errors(res, n, mask).mean()
    assert res.valid[mask].mean() > 0.99
    assert err < 0.25 * ls and err < 3.0, (err, ls)      # 2.4° against 11.7°


def test_only_the_order_of_the_values_counts():
    """An increasing response (a gamma, a scale) gives the same normals: the method orders the
    values and compares each with the pixel's brightest."""
    n, mask = sphere(24)
    lights = scene_lights(32)
    img = blinn_phong(n, lights)
    linear = ps_consensus_higo2010(img, lights, mask=mask)
    exact = {"t_shadow": 0.0, "tie_share": 0.0, "tie_ratio": 0.0}    # thresholds on values: none
    encoded = ps_consensus_higo2010(3.0 * img ** 0.8, lights, mask=mask, **exact)
    plain = ps_consensus_higo2010(img, lights, mask=mask, **exact)
    np.testing.assert_array_equal(encoded.normal, plain.normal)
    assert _errors(linear, n, mask).mean() < 3.0     # 2.5° (24 px, 32 lights)


def test_black_saturated_shadowed_and_barely_lit_pixels():
    n, mask = sphere(16)
    lights = scene_lights(30)
    img = blinn_phong(n, lights)
    m = len(img)
    img[:, 3, 8] = 0.0                                          # black everywhere
    img[:, 8, 3] = 20.0                                         # saturated everywhere
    img[:, 7, 7] = np.nan                                       # missing everywhere
    img[:, 8, 12] = np.where(np.arange(m) < m - 2, 0.0, img[:, 8, 12])   # lit by 2 lights only
    img[:, 10, 8] = np.where(np.arange(m) < m - 3, 0.0, 0.1)    # lit by 3: still a normal
    res = ps_consensus_higo2010(img, lights, mask=mask, saturation=10.0)
    for field in ("normal", "albedo", "residual"):
        assert np.all(np.isfinite(getattr(res, field))), field
    for r, c in ((3, 8), (8, 3), (7, 7), (8, 12)):
        assert mask[r, c] and not res.valid[r, c], (r, c)
        assert np.all(res.normal[r, c] == 0) and np.all(res.albedo[r, c] == 0)
    assert res.valid[10, 8]
    assert res.shadow[10, 8].sum() == m - 3 and not res.shadow[8, 12].any()   # flags of valid pixels
    norms = np.linalg.norm(res.normal[res.valid], axis=-1)
    assert np.allclose(norms, 1, atol=1e-5) and np.all(res.normal[res.valid][:, 2] > 0)


def test_empty_mask_gives_an_empty_result():
    n, _ = sphere(8)
    lights = scene_lights(8)
    res = ps_consensus_higo2010(blinn_phong(n, lights), lights, mask=np.zeros((8, 8), bool))
    assert not res.valid.any() and res.info["pixels"] == 0


def test_refuses_near_lights_too_few_lights_and_bad_options():
    n, mask = sphere(8)
    lights = scene_lights(8)
    img = blinn_phong(n, lights)
    with pytest.raises(ValueError, match="distant lights.*ps_rank_trimmed"):
        ps_consensus_higo2010(img, np.broadcast_to(lights, (8, 8, 8, 3)), mask=mask)
    with pytest.raises(ValueError, match="at least 4 lights"):
        ps_consensus_higo2010(img[:3], lights[:3], mask=mask)
    for bad in ({"pairs_per_light": 0}, {"tie_share": 1.0}, {"t_shadow": -0.1}, {"diffuse_weight": 2.0},
                {"order_margin": -0.01}, {"tie_ratio": 1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            ps_consensus_higo2010(img, lights, mask=mask, **bad)


def test_registered_with_a_short_name():
    assert PS_METHODS.canonical("HM10") == "consensus_higo2010"
    assert PS_METHODS["consensus_higo2010"] is ps_consensus_higo2010
