"""Neighbouring pixels' values pooled before li_alternating under few lights (facette.fit._ps_li_pool)."""
import numpy as np

from facette.fit._ps_li import ps_li_alternating
from facette.fit._ps_li_pool import POOL_MAX_LIGHTS, pool_neighbours
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions


def _dark_8bit(material, lights, size=64, seed=0):
    """A dark sphere on a plane whose brightest value is 68 of 255 (DiLiGenT pot2's), with 0.5 %
    noise and 0.5 DN of read noise, quantised: (scene, noise-free images, images), both in DN / scale."""
    sc = sphere_on_plane(size, size)
    clean = render(sc, lights, material, albedo=(0.25, 0.2, 0.16))
    scale = 68.0 / np.percentile(clean, 99.9)
    rng = np.random.default_rng(seed)
    dn = clean * scale * (1 + 0.005 * rng.standard_normal(clean.shape)) + 0.5 * rng.standard_normal(clean.shape)
    return sc, clean, (np.clip(np.round(dn), 0, 255) / scale).astype(np.float32)


def test_pooled_values_are_nearer_the_noise_free_ones_and_the_edges_stay():
    sc, clean, im = _dark_8bit("satin", thesis_light_directions())
    pooled, info = pool_neighbours(im, sc.mask)
    assert info["applied"] and info["profile_noise"] > 0.003, info
    lit = clean > 0.05 * clean.max()
    before, after = (float(np.sqrt(np.mean(((v[lit] - clean[lit]) / clean[lit]) ** 2))) for v in (im, pooled))
    assert after < 0.6 * before, (before, after)
    # the cast shadows' and the sphere's edges are not smeared: the plane's shadowed pixels stay dark
    shadow = (clean[..., 0] == 0) & ~sc.sphere[None]
    assert np.median(pooled[..., 0][shadow]) < 0.05 * clean.max(), np.median(pooled[..., 0][shadow])


def test_noise_free_values_many_lights_and_saturated_pixels_are_left_as_they_are():
    lights = thesis_light_directions()
    sc = sphere_on_plane(40, 40)
    clean = render(sc, lights, "satin")
    out, info = pool_neighbours(clean, sc.mask)
    assert out is clean and not info["applied"], info
    _, _, im = _dark_8bit("matte", np.concatenate([lights] * 2), size=40)
    assert len(im) > POOL_MAX_LIGHTS and pool_neighbours(im, sc.mask)[0] is im
    _, _, im = _dark_8bit("matte", lights, size=40)
    im[3, 20, 20] = np.nan
    im[5, 10, 10] = 255.0
    out, info = pool_neighbours(im, sc.mask, saturation=200.0)
    assert info["applied"] and np.isnan(out[3, 20, 20, 0]) and out[5, 10, 10, 0] == 255.0
    np.testing.assert_array_equal(out[:, 20, 20], im[:, 20, 20])


def test_li_on_a_dark_8bit_sphere_under_the_rigs_12_lights_gains_from_the_pooling_asked_for():
    sc, _, im = _dark_8bit("glossy", thesis_light_directions())
    obj = sc.sphere & sc.mask
    res = ps_li_alternating(im, thesis_light_directions(), mask=sc.mask, pool=True)
    alone = ps_li_alternating(im, thesis_light_directions(), mask=sc.mask)      # the default: off
    err, err_alone = (float(np.mean(angular_error_deg(r.normal, sc.normals, obj))) for r in (res, alone))
    assert res.info["pooled"]["applied"] and "pooled" not in alone.info
    assert err < 0.7 * err_alone, (err, err_alone)
