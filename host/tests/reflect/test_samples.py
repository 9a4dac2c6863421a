"""Reflectance samples (eq 4.11) and the hemispherical equal-area sensor (eq 4.12-4.14)."""
import numpy as np
import pytest

from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions
from facette.reflect import (HemisphereSensor, ReflectanceSamples, beckers_partition,
                             hemisphere_filter, local_frame_directions, reflectance_samples)

L = thesis_light_directions()
ALBEDO = np.array([0.6, 0.5, 0.4])


@pytest.mark.parametrize("theta0_deg", [2.0, 3.0, 6.0])
def test_partition_cells_have_equal_solid_angles_covering_the_hemisphere(theta0_deg):
    edges, counts = beckers_partition(np.radians(theta0_deg))
    assert edges[0] == 0 and edges[-1] == pytest.approx(np.pi / 2)
    assert np.all(np.diff(edges) > 0) and counts[0] == 1
    area = 2 * np.pi * (np.cos(edges[:-1]) - np.cos(edges[1:])) / counts
    np.testing.assert_allclose(area, 2 * np.pi / counts.sum(), rtol=1e-9)
    # the cap keeps the requested size to within the rounding of the cell counts
    assert np.degrees(edges[1]) == pytest.approx(theta0_deg, rel=0.05)
    # eq 4.14 makes cells about as tall as wide: total ~ hemisphere / cap solid angle
    cap = 2 * np.pi * (1 - np.cos(np.radians(theta0_deg)))
    assert counts.sum() == pytest.approx(2 * np.pi / cap, rel=0.1)


def test_partition_first_rings_follow_eq_4_13():
    edges, counts = beckers_partition(np.radians(3.0))
    # ring 1: k_1 = k_0 (r_1 / r_0)^2 with theta_1 from eq 4.14 -> 7.7 cells in all, 7 in ring 1
    t0 = np.radians(3.0)
    t1 = t0 + 2 * np.sqrt(np.pi) * np.sin(t0 / 2)
    assert round((np.sin(t1 / 2) / np.sin(t0 / 2)) ** 2) - 1 == counts[1] == 7
    with pytest.raises(ValueError, match="theta0"):
        beckers_partition(0.0)


def test_each_cell_centre_falls_in_its_own_cell():
    sensor = HemisphereSensor(3.0)
    centres, _ = sensor.centres()
    np.testing.assert_array_equal(sensor.cell_of(centres), np.arange(sensor.n_cells))


def test_local_frame_puts_s_at_phi_zero_and_keeps_angles():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(500, 3))
    n[:, 2] = np.abs(n[:, 2]) + 0.5
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    s = L[rng.integers(0, 12, 500)]
    o = np.array([0.0, 0.0, 1.0])
    sl, ol = local_frame_directions(n, s, o)
    assert np.all(np.abs(sl[:, 1]) < 1e-6) and np.all(sl[:, 0] >= -1e-6)
    np.testing.assert_allclose(sl[:, 2], np.sum(n * s, 1), atol=1e-6)
    np.testing.assert_allclose(ol[:, 2], n[:, 2], atol=1e-6)
    np.testing.assert_allclose(np.sum(sl * ol, 1), s @ o, atol=1e-5)     # angle s-o kept
    # s along n: phi undefined but the frame stays orthonormal and finite
    sl, ol = local_frame_directions(np.array([0, 0, 1.0]), np.array([0, 0, 1.0]), o)
    assert np.all(np.isfinite(sl)) and sl[2] == pytest.approx(1)


def test_lambertian_samples_equal_rho_over_pi_per_channel():
    sc = sphere_on_plane(64, 64)
    imgs = render(sc, L, "matte", cast_shadows=False)
    smp = reflectance_samples(imgs, sc.normals, L)
    assert isinstance(smp, ReflectanceSamples) and smp.f.shape[1] == 3
    np.testing.assert_allclose(smp.f, np.broadcast_to(ALBEDO / np.pi, smp.f.shape), rtol=2e-3)
    assert np.all(smp.s[:, 2] >= 0.05)                       # grazing samples left out
    # the same samples through the rotation-matrix route
    n = sc.normals.reshape(-1, 3)[smp.pixel]
    sl, ol = local_frame_directions(n, L[smp.light], np.array([0, 0, 1.0]))
    np.testing.assert_allclose(smp.s, sl, atol=1e-4)
    np.testing.assert_allclose(smp.o, ol, atol=1e-4)


def test_samples_exclude_mask_nan_and_bad_normals():
    sc = sphere_on_plane(32, 32)
    imgs = render(sc, L, "matte", cast_shadows=False)
    imgs[2, 5, 5] = np.nan
    normals = sc.normals.copy()
    normals[6, 6] = 0.0
    exclude = np.zeros((32, 32, 12), bool)
    exclude[..., 0] = True
    smp = reflectance_samples(imgs, normals, L, exclude=exclude)
    assert not np.any(smp.light == 0)
    assert not np.any((smp.pixel == 5 * 32 + 5) & (smp.light == 2))
    assert not np.any(smp.pixel == 6 * 32 + 6)
    assert np.all(np.isfinite(smp.f))
    with pytest.raises(ValueError, match="normals must have shape"):
        reflectance_samples(imgs, normals[:4], L)


def test_filter_of_lambertian_samples_is_flat_and_of_noise_is_smoother():
    sc = sphere_on_plane(96, 96)
    imgs = render(sc, L, "matte", cast_shadows=False)
    rng = np.random.default_rng(2)
    noisy = imgs * (1 + 0.3 * rng.standard_normal(imgs.shape)).astype(np.float32)
    smp = reflectance_samples(noisy, sc.normals, L)
    fr = hemisphere_filter(smp, theta0_deg=3.0)
    s, o, f, count = fr.flat(min_count=20)
    assert len(f) > 50 and np.all(count >= 20)
    raw_err = np.mean(np.abs(smp.f * np.pi / ALBEDO - 1))
    cell_err = np.mean(np.abs(f * np.pi / ALBEDO - 1))
    assert raw_err > 0.2 and cell_err < 0.06
    assert fr.mean.shape == (len(fr.theta_s), len(fr.o), 3)
    assert np.all(np.isnan(fr.mean[fr.count == 0]))


def test_filter_keeps_the_glossy_lobe_at_the_mirror_direction():
    sc = sphere_on_plane(128, 128)
    imgs = render(sc, L, "glossy", ks=5.0, cast_shadows=False)
    smp = reflectance_samples(imgs, sc.normals, L, mask=sc.sphere)
    fr = hemisphere_filter(smp)
    b = np.searchsorted(fr.edges, np.radians(15.0)) - 1   # the bin of the inner ring's lights
    cells = np.flatnonzero(fr.count[b] > 0)
    peak = cells[np.nanargmax(fr.mean[b, cells, 1])]
    mirror = fr.s[b] * [-1, 1, 1]                     # reflection of s about n, phi = pi
    ang = np.degrees(np.arccos(np.clip(fr.o[peak] @ mirror, -1, 1)))
    assert ang < 8.0


@pytest.mark.parametrize("theta0_deg", [1.0, 3.0, 6.0])
def test_ring_lookup_table_agrees_with_the_edges(theta0_deg):
    sensor = HemisphereSensor(theta0_deg)
    theta = np.r_[np.random.default_rng(4).random(200_000) * np.pi / 2, sensor.edges]
    expected = np.clip(np.searchsorted(sensor.edges, theta, side="right") - 1, 0, sensor.n_bins - 1)
    np.testing.assert_array_equal(sensor.ring_of(theta), expected)


def test_grid_accumulation_equals_accumulating_gathered_samples():
    from facette.reflect import sample_grid
    sc = sphere_on_plane(48, 48)
    imgs = render(sc, L, "glossy", ks=3.0)
    imgs[3, 10, 10] = np.nan
    smp = reflectance_samples(imgs, sc.normals, L)
    a = hemisphere_filter(smp)
    sensor = HemisphereSensor(channels=3)
    e = imgs.reshape(12, -1, 3)
    g = sample_grid(e, sc.normals.reshape(-1, 3), L)
    sensor.add_grid(g["cos_s"], g["o_x"], g["o_y"], g["cos_o"], e, g["keep"], g["scale"])
    b = sensor.result()
    np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_allclose(np.nan_to_num(a.mean), np.nan_to_num(b.mean), rtol=1e-5)


def test_min_cos_must_be_positive():
    sc = sphere_on_plane(8, 8)
    imgs = render(sc, L, "matte")
    with pytest.raises(ValueError, match="min_cos must be > 0"):
        reflectance_samples(imgs, sc.normals, L, min_cos=0.0)
