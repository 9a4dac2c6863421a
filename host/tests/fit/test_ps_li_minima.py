"""The search of a pixel's minima (facette.fit._ps_li_minima): its starts, the relative gap of
the two best minima's costs, and the search on values the LI model made."""
import numpy as np

from facette.brdf import kappa_from_kd, li_shading_terms
from facette.fit._ps_li_minima import minima_starts, relative_gap, search_pixel_minima
from facette.fit._ps_li_pixels import angle_deg
from facette.recon.synthetic import thesis_light_directions


def test_the_starts_are_unit_normals_facing_the_camera_and_each_lights_half_vector():
    lights = thesis_light_directions()
    st = minima_starts(lights, count=24)
    assert st.shape == (24 + len(lights), 3) and st.dtype == np.float32
    assert np.allclose(np.linalg.norm(st, axis=1), 1, atol=1e-6) and (st[:, 2] > 0.1).all()
    half = (lights + [0, 0, 1]) / np.linalg.norm(lights + [0, 0, 1], axis=1, keepdims=True)
    assert np.allclose(st[24:], half, atol=1e-6)


def test_the_gap_is_the_relative_difference_of_the_two_costs_and_one_without_a_second_minimum():
    g = relative_gap([1.0, 2.0, 1.0, 0.0, 0.0], [3.0, 2.0, np.inf, 0.0, 1.0])
    assert np.allclose(g, [0.5, 0.0, 1.0, 1.0, 1.0])


def _pixels(normals, sigma=0.1, n_i=1.5, kd=(0.3, 0.25, 0.2)):
    lights = thesis_light_directions()
    a, b = li_shading_terms(normals, lights, sigma, n_i, volume_model="approx")
    kappa = kappa_from_kd(np.float32(kd), n_i, "approx", sigma)
    return (a[..., None] + b[..., None] * kappa).astype(np.float32), lights


def test_the_search_finds_the_true_normal_from_starts_far_off_and_reports_both_minima():
    """Values of the model itself at known normals, the current normals 50° off: the best minimum
    is the true normal (the cost there ~0, below the current one's), the result one row per pixel."""
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 3)) * [0.4, 0.4, 0] + [0, 0, 1]
    truth = (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    e, lights = _pixels(truth)
    axis = np.cross(truth, [1, 0, 0])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    t = np.radians(50)     # Rodrigues: each normal turned 50° about an axis orthogonal to it
    off = (truth * np.cos(t) + np.cross(axis, truth) * np.sin(t)).astype(np.float32)
    off[:, 2] = np.abs(off[:, 2])
    off /= np.linalg.norm(off, axis=1, keepdims=True)
    mm = search_pixel_minima(e, np.ones(e.shape[:2], bool), off, lights, 0.1, 1.5, "approx")
    assert mm.normals.shape == (40, 3) and mm.cost_here.shape == mm.cost_best.shape == mm.cost_second.shape == (40,)
    err = angle_deg(mm.normals, truth)
    assert np.percentile(err, 90) < 0.5, np.sort(err)
    assert (mm.cost_best <= mm.cost_here + 1e-9).all()
    # a second minimum, where found, costs more than the best
    has2 = np.isfinite(mm.cost_second)
    assert (mm.cost_second[has2] >= mm.cost_best[has2]).all()


def test_per_pixel_starts_and_a_pixel_with_fewer_than_three_usable_lights():
    truth = np.float32([[0, 0, 1], [0.3, 0, 0.954]])
    truth /= np.linalg.norm(truth, axis=1, keepdims=True)
    e, lights = _pixels(truth)
    usable = np.ones(e.shape[:2], bool)
    usable[1, 2:] = False                                    # two lights left: nothing to solve
    start = np.float32([[0.2, 0.2, 0.959]])
    mm = search_pixel_minima(e, usable, np.repeat(start, 2, 0), lights, 0.1, 1.5, "approx",
                             starts=truth[:, None, :])
    assert angle_deg(mm.normals[0], truth[0]) < 0.5
    assert np.allclose(mm.normals[1], start[0] / np.linalg.norm(start[0]), atol=1e-5) and np.isinf(mm.cost_second[1])
