"""Photometric stereo: least squares and hierarchical elimination, values, shapes and edges."""
import numpy as np
import pytest

from facette.methods import photometric_stereo
from facette.recon import near_light_directions, ps_hierarchical_tautzia2016, ps_woodham1980, triplet_inverses
from facette.recon.synthetic import angular_error_deg, render, sphere_on_plane, thesis_light_directions

L = thesis_light_directions()
ALBEDO = np.array([0.6, 0.5, 0.4])


def plane_images(normal, lights=L, albedo=ALBEDO, h=6, w=7):
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    shade = np.maximum(lights @ n, 0)
    imgs = (albedo / np.pi)[None, :] * shade[:, None]
    return np.broadcast_to(imgs[:, None, None, :], (len(lights), h, w, 3)).astype(np.float32).copy(), n


@pytest.mark.parametrize("method", ["woodham1980", "hierarchical_tautzia2016"])
def test_lambertian_plane_gives_its_normal_and_albedo(method):
    imgs, n = plane_images([0.2, -0.1, 1.0])
    r = photometric_stereo(imgs, L, method=method)
    assert r.valid.all()
    assert np.max(angular_error_deg(r.normal, n)) < 0.01
    np.testing.assert_allclose(r.albedo, np.broadcast_to(ALBEDO, r.albedo.shape), rtol=1e-4)


def test_hierarchical_without_shortcut_is_the_mean_of_all_conditioned_triplets():
    imgs, n = plane_images([0.1, 0.3, 1.0])
    r = ps_hierarchical_tautzia2016(imgs, L, t_residual=0)
    _, _, kept = triplet_inverses(L)
    assert (r.n_triplets == kept.sum()).all()
    assert not r.skipped.any() and not r.shadow.any() and not r.specular.any()
    assert np.max(angular_error_deg(r.normal, n)) < 0.01


def test_sphere_with_shadows_hierarchical_beats_least_squares():
    sc = sphere_on_plane(96, 96)
    imgs = render(sc, L, "matte")
    ls = ps_woodham1980(imgs, L)
    hi = ps_hierarchical_tautzia2016(imgs, L)
    e_ls = angular_error_deg(ls.normal, sc.normals, sc.mask & ls.valid)
    e_hi = angular_error_deg(hi.normal, sc.normals, sc.mask & hi.valid)
    assert np.percentile(e_ls, 95) > 10          # shadows bend least squares
    assert np.percentile(e_hi, 95) < 1.0
    assert hi.valid[sc.mask].mean() > 0.99


def test_cast_shadow_is_flagged_for_the_light_that_casts_it():
    sc = sphere_on_plane(96, 96)
    imgs = render(sc, L, "matte")
    hi = ps_hierarchical_tautzia2016(imgs, L)
    # plane pixels in a cast shadow (pixels shadowed from almost every light, next to the
    # sphere, have no normal at all and are left out)
    dark = (imgs[..., 1] == 0) & ~sc.sphere[None] & hi.valid[None]
    light, rows, cols = np.nonzero(dark)
    assert light.size > 50
    assert hi.shadow[rows, cols, light].mean() > 0.95


def test_glossy_highlight_flagged_specular_and_normals_better_than_least_squares():
    sc = sphere_on_plane(128, 128)
    imgs = render(sc, L, "glossy", ks=5.0)
    ls = ps_woodham1980(imgs, L)
    hi = ps_hierarchical_tautzia2016(imgs, L)
    sel = sc.sphere
    assert angular_error_deg(hi.normal, sc.normals, sel).mean() < \
        0.5 * angular_error_deg(ls.normal, sc.normals, sel).mean()
    # the pixel whose normal is the half vector of light 3 and the view is its highlight
    h = L[3] + [0, 0, 1]
    h /= np.linalg.norm(h)
    d = np.sum((sc.normals - h) ** 2, -1)
    r, c = np.unravel_index(np.argmin(np.where(sel, d, np.inf)), d.shape)
    assert hi.specular[r, c, 3]
    assert angular_error_deg(hi.normal[r, c], sc.normals[r, c]) < 2.0


def test_shortcut_changes_little_and_skips_lambertian_pixels():
    sc = sphere_on_plane(96, 96)
    imgs = render(sc, L, "matte", noise=0.005)
    fast = ps_hierarchical_tautzia2016(imgs, L)
    full = ps_hierarchical_tautzia2016(imgs, L, t_residual=0)
    assert 0.3 < fast.info["skipped_fraction"] < 1.0
    diff = angular_error_deg(fast.normal, full.normal, sc.mask & fast.valid & full.valid)
    assert np.percentile(diff, 99) < 1.0


@pytest.mark.parametrize("method", ["woodham1980", "hierarchical_tautzia2016"])
def test_black_saturated_and_nan_pixels_are_marked_not_valid_and_stay_finite(method):
    imgs, n = plane_images([0.0, 0.2, 1.0])
    imgs[:, 0, 0] = 0.0                  # black in every image
    imgs[:, 0, 1] = 5.0                  # saturated in every image
    imgs[:, 0, 2] = np.nan               # unknown in every image
    imgs[4, 1, 1] = np.nan               # unknown in one image only: that light is ignored
    r = photometric_stereo(imgs, L, method=method, saturation=1.0)
    for name in ("normal", "albedo", "residual"):
        assert np.all(np.isfinite(getattr(r, name)))
    assert not r.valid[0, 0] and not r.valid[0, 1] and not r.valid[0, 2]
    assert np.all(r.normal[0, :3] == 0)
    assert r.valid[1, 1]
    assert angular_error_deg(r.normal[1, 1], n) < 0.01


def test_fewer_than_four_lights_is_a_clear_error():
    imgs, _ = plane_images([0, 0, 1], lights=L[:3])
    with pytest.raises(ValueError, match="at least 4 lights"):
        ps_hierarchical_tautzia2016(imgs, L[:3])
    with pytest.raises(ValueError, match="at least 4 lights"):
        ps_woodham1980(imgs, L[:3])


def test_near_singular_triplets_are_dropped_and_coplanar_lights_refused():
    trip, inv, kept = triplet_inverses(L)
    assert len(trip) == 220
    worst = np.abs(inv).max(axis=(1, 2))
    assert kept.sum() == 184 and np.all(worst[kept] <= 10) and np.all(worst[~kept] > 10)
    # four lights almost on one great circle: every triplet is ill-conditioned
    phi = np.radians([0, 60, 120, 180])
    eps = 1e-4
    flat = np.stack([np.cos(phi), np.sin(phi), np.full(4, eps)], 1)
    flat /= np.linalg.norm(flat, axis=1, keepdims=True)
    imgs = np.ones((4, 3, 3), np.float32)
    with pytest.raises(ValueError, match="T_source"):
        ps_hierarchical_tautzia2016(imgs, flat)
    # the same images through least squares stay finite
    assert np.all(np.isfinite(ps_woodham1980(imgs, flat).normal))


def test_shapes_grey_input_channel_and_mask():
    imgs, n = plane_images([0.3, 0.0, 1.0])
    grey = imgs[..., 1]
    r = ps_hierarchical_tautzia2016(grey, L)
    assert r.normal.shape == (6, 7, 3) and r.albedo.shape == (6, 7, 1)
    assert r.shadow.shape == (6, 7, 12)
    mask = np.zeros((6, 7), bool)
    mask[2:4, 1:5] = True
    r = ps_woodham1980(imgs, L, mask=mask, channel=0)
    assert (r.valid == mask).all()
    assert np.all(r.normal[~mask] == 0)


def test_bad_arguments_raise_value_errors_that_say_what_to_do():
    imgs, _ = plane_images([0, 0, 1])
    with pytest.raises(ValueError, match="unit vectors"):
        ps_woodham1980(imgs, L * 2)
    with pytest.raises(ValueError, match="light_dirs must have shape"):
        ps_woodham1980(imgs, L[:5])
    with pytest.raises(ValueError, match="mask has shape"):
        ps_woodham1980(imgs, L, mask=np.ones((2, 2), bool))
    with pytest.raises(ValueError, match="unknown photometric-stereo method"):
        photometric_stereo(imgs, L, method="magic")
    with pytest.raises(ValueError, match="NaN"):
        ps_woodham1980(imgs, np.where(np.eye(12, 3, dtype=bool), np.nan, L))


def test_near_lights_per_pixel_directions_recover_a_plane():
    h, w, pitch = 40, 50, 1.0
    pos = L * 300.0                       # lights 300 mm away, the object 40-50 mm across
    dirs, fall = near_light_directions(pos, (h, w), pitch)
    assert dirs.shape == (h, w, 12, 3) and fall.shape == (h, w, 12)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1, atol=1e-6)
    n = np.array([0.1, 0.2, 1.0]) / np.linalg.norm([0.1, 0.2, 1.0])
    shade = np.maximum(np.einsum("hwmi,i->mhw", dirs, n), 0) * np.transpose(fall, (2, 0, 1))
    imgs = (0.5 / np.pi * shade).astype(np.float32)
    far = ps_woodham1980(imgs, L)
    corrected = imgs / np.transpose(fall, (2, 0, 1))
    for fn in (ps_woodham1980, ps_hierarchical_tautzia2016):
        near = fn(corrected, dirs)
        assert np.max(angular_error_deg(near.normal, n)) < 0.05
        np.testing.assert_allclose(near.albedo[..., 0], 0.5, rtol=1e-3)
    assert np.max(angular_error_deg(far.normal, n)) > 1.0    # ignoring positions costs degrees


def test_many_lights_keep_only_the_best_conditioned_triplets():
    rng = np.random.default_rng(5)
    d = rng.normal(size=(30, 3))
    d[:, 2] = np.abs(d[:, 2]) + 1.5
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    trip, inv, kept = triplet_inverses(d, max_triplets=300)
    assert len(trip) == 4060 and kept.sum() == 300
    worst = np.abs(inv).max(axis=(1, 2))
    assert worst[kept].max() <= worst[~kept & (np.abs(np.linalg.det(d[trip])) > 1e-6)].min()
    sc = sphere_on_plane(32, 32)
    imgs = render(sc, d, "glossy", ks=3.0)
    r = ps_hierarchical_tautzia2016(imgs, d, max_triplets=300)
    assert r.info["triplets_conditioned"] == 300
    every = ps_hierarchical_tautzia2016(imgs, d, max_triplets=None)
    ls = ps_woodham1980(imgs, d)
    med = np.median(angular_error_deg(r.normal, sc.normals, sc.mask & r.valid))
    assert med < 0.5 * np.median(angular_error_deg(ls.normal, sc.normals, sc.mask))
    assert med < np.median(angular_error_deg(every.normal, sc.normals, sc.mask & every.valid)) + 1.0
