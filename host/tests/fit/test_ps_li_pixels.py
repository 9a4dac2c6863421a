"""The per-pixel steps of ps_li_alternating (facette.fit._ps_li_pixels): which lights are in the
lobe, the highlight starts, the Lambertian level's correction, and the state's pixel levels."""
import numpy as np
import pytest

from facette.brdf import li_shading_terms
from facette.fit._ps_li_pixels import (LOBE_TAN, NEIGHBOUR_ROUNDS, Pixels, Settings, _highlight_starts, _in_lobe,
                                       _lambertian_correction, _neighbour_means, angle_deg)
from facette.recon import ps_woodham1980
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


def _unit(v):
    v = np.asarray(v, np.float32)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_a_light_is_in_the_lobe_when_its_half_vector_is_within_lobe_tan_sigma():
    n = np.float32([[0, 0, 1]])
    # a light 60° off the view: half-vector 30° off the normal, tan 30° = 0.577
    lights = _unit([[np.sin(np.radians(60)), 0, np.cos(np.radians(60))]])
    assert not _in_lobe(n, lights, 0.5 / LOBE_TAN)[0]
    assert _in_lobe(n, lights, 0.6 / LOBE_TAN)[0]
    # per-pixel lights (N, m, 3): the same answer per pixel
    per_pixel = np.stack([lights, _unit([[0, 0, 1]])])            # (2, 1, 3)
    np.testing.assert_array_equal(_in_lobe(np.repeat(n, 2, 0), per_pixel, 0.1), [False, True])


def test_the_highlight_start_is_the_half_vector_of_the_light_above_the_lambertian_prediction():
    lights = _unit([[0.5, 0, 1], [-0.5, 0, 1], [0, 0.5, 1], [0, -0.5, 1]])
    normals = np.tile(np.float32([0, 0, 1]), (3, 1))
    albedo = np.float32([1, 1, 1])
    values = (normals @ lights.T) / np.pi
    values[1, 2] += 0.5 * values[1].mean()          # a highlight under light 2 at pixel 1
    values[2, 3] += 0.05 * values[2].mean()         # too small to stand out (< 10 % of the mean)
    has, start = _highlight_starts(values.astype(np.float32), np.ones_like(values, bool), normals, lights, albedo)
    np.testing.assert_array_equal(has, [False, True, False])
    np.testing.assert_allclose(start[1], _unit(lights[2] + [0, 0, 1]), atol=1e-6)


def test_the_lambertian_correction_removes_the_volume_parts_bias_from_least_squares():
    rng = np.random.default_rng(0)
    truth = _unit(np.c_[rng.uniform(-0.6, 0.6, (200, 2)), np.ones(200)])
    lights = thesis_light_directions().astype(np.float32)
    _, b = li_shading_terms(truth, lights, 0.1, 1.5, specular=False, volume_model="approx")
    g = np.linalg.lstsq(lights, b.T, rcond=None)[0].T          # least squares of the model's values
    n_ls = _unit(g)
    fixed = _lambertian_correction(n_ls, lights, 0.1, 1.5, "approx")
    before, after = angle_deg(n_ls, truth), angle_deg(fixed, truth)
    assert before.max() > 0.5 and after.max() < 0.25 * before.max(), (before.max(), after.max())
    np.testing.assert_allclose(np.linalg.norm(fixed, axis=1), 1, atol=1e-6)


def _pixels(material="glossy", seed=0, fit_pixels=50):
    sc = sphere_on_plane(40, 40)
    lights = thesis_light_directions()
    im = render(sc, lights, material, noise=0.002, rng=np.random.default_rng(1))
    base = ps_woodham1980(im, lights, mask=sc.mask)
    settings = Settings(iterations=8, fine_iterations=2, fit_pixels=fit_pixels, t_residual=0.05, engine="arrays",
                        highlight_start="all", diffuse_models=("approx",))
    return Pixels.start(im.astype(np.float32), lights, 1, None, base, settings, seed), base


def test_the_state_starts_from_the_initial_solution_of_every_valid_pixel():
    px, base = _pixels()
    np.testing.assert_array_equal(px.idx, np.flatnonzero(base.valid.ravel()))
    np.testing.assert_array_equal(px.nrm, base.normal.reshape(-1, 3)[px.idx])
    assert px.nrm is not px.nrm0 and px.shape == (40, 40) and px.vm == "approx"
    assert not px.refined.any() and px.gather(np.arange(3)).shape == (3, len(thesis_light_directions()), 3)


def test_fit_pixels_are_drawn_sorted_without_repeats_and_reproducibly():
    px, _ = _pixels(seed=3)
    trust = np.arange(0, 400, 2)
    a = px.draw(trust)
    assert a.size == 50 and np.all(np.diff(a) > 0) and np.isin(a, trust).all()
    assert px.draw(trust[:20]).size == 20                        # fewer than fit_pixels: all of them
    np.testing.assert_array_equal(_pixels(seed=3)[0].draw(trust), a)


def test_pixels_outside_the_lobe_that_least_squares_explains_take_the_lambertian_level():
    px, _ = _pixels("matte")
    pix = np.arange(px.idx.size)
    before = px.nrm.copy()
    lobe, lam_ok, todo = px.split_levels(pix, 0.05, 1.2)
    assert lam_ok.sum() > 0.5 * pix.size                           # a matte scene: least squares explains most
    assert not (lam_ok & lobe).any()
    np.testing.assert_array_equal(todo, pix[~lam_ok & lobe])
    assert not px.refined[pix[lam_ok]].any()
    np.testing.assert_array_equal(px.nrm[~lam_ok], before[~lam_ok])    # the others keep their normal
    assert np.any(px.nrm[lam_ok] != before[lam_ok])                # corrected (n_i 1.2 tilts them)


def test_a_later_round_gives_the_first_rounds_starts_only_to_pixels_new_to_the_brdf_step():
    px, _ = _pixels()
    todo = np.arange(0, 300, 3)
    px.refined[todo[::2]] = True                     # half of them were solved in an earlier round
    mixed = px.refine_round(todo, 0.1, 1.5)
    new, old = todo[1::2], todo[::2]
    alone_new = px.refine(new, 0.1, 1.5, first_round=True)
    alone_old = px.refine(old, 0.1, 1.5, first_round=False)
    # each pixel's answer is its group's, in the order of `todo`
    np.testing.assert_array_equal(mixed.normals[1::2], alone_new.normals)
    np.testing.assert_array_equal(mixed.normals[::2], alone_old.normals)
    np.testing.assert_array_equal(mixed.used[1::2], alone_new.used)
    # the first round's highlight start changes some answers: the two forms are not the same solve
    assert np.any(px.refine(old, 0.1, 1.5, first_round=True).normals != alone_old.normals)


@pytest.mark.parametrize("per_pixel", [False, True])
def test_the_lambertian_levels_least_squares_is_woodhams_where_every_light_is_usable(per_pixel):
    from facette.fit._ps_li_pixels import _least_squares_level
    sc = sphere_on_plane(40, 40)
    lights = thesis_light_directions()
    im = render(sc, lights, "glossy", noise=0.002, rng=np.random.default_rng(1))[..., 1]
    im[3, 5:9] = np.nan                                      # a light not usable on a few pixels
    dirs = np.broadcast_to(lights, (40, 40) + lights.shape).copy() if per_pixel else lights
    ref = ps_woodham1980(im, dirs, mask=sc.mask)
    idx = np.flatnonzero(sc.mask)
    values = im.reshape(len(lights), -1)[:, idx].T.astype(np.float32)
    ok = np.isfinite(values)
    nrm, resid = _least_squares_level(values, ok, dirs.reshape(-1, len(lights), 3)[idx] if per_pixel else lights)
    full = ok.all(1)
    assert (~full).sum() > 0 and np.isinf(resid[~full]).all()
    if per_pixel:                 # lights that do not span 3-D on one pixel: no level, no error
        flat = dirs.reshape(-1, len(lights), 3)[idx].copy()
        flat[0] = lights[0]
        _, r_flat = _least_squares_level(values, ok, flat)
        assert np.isinf(r_flat[0]) and np.isfinite(r_flat[1:][full[1:]]).all()
    np.testing.assert_allclose(nrm[full], ref.normal.reshape(-1, 3)[idx][full], atol=2e-5)
    np.testing.assert_allclose(resid[full], ref.residual.reshape(-1)[idx][full], rtol=1e-3, atol=1e-6)


def test_the_lambertian_correction_solves_its_fixed_point_at_oblique_normals():
    # n = n_LS + δ(n): one pass takes δ at n_LS, which at 40-70° of tilt left 0.37° (p95)
    rng = np.random.default_rng(3)
    th, ph = np.radians(rng.uniform(40, 70, 3000)), rng.uniform(0, 2 * np.pi, 3000)
    truth = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).astype(np.float32)
    lights = thesis_light_directions().astype(np.float32)
    _, b = li_shading_terms(truth, lights, 0.1, 1.3, specular=False, volume_model="approx")
    lit = (b > 0).all(1)                  # the Lambertian level holds pixels every light reaches
    n_ls = _unit(b[lit] @ np.linalg.pinv(lights).T)
    one = angle_deg(_lambertian_correction(n_ls, lights, 0.1, 1.3, "approx", passes=1), truth[lit])
    solved = angle_deg(_lambertian_correction(n_ls, lights, 0.1, 1.3, "approx"), truth[lit])
    assert np.percentile(one, 95) > 0.3 and np.percentile(solved, 95) < 0.15, (np.percentile(one, 95),
                                                                             np.percentile(solved, 95))


@pytest.mark.parametrize("engine", ["arrays", "compiled"])
def test_a_pixel_apart_from_its_neighbours_gets_their_mean_as_a_start_and_its_own_values_choose(engine):
    """`neighbour_round`: a solved normal far from its neighbours' mean is solved again from that
    mean, and the start of lower robust cost is kept. A pixel pushed 35° off (as a solve stopped in
    another minimum) comes back; a pixel whose own surface stands apart (a one-pixel facet tilted
    30° on the plane) keeps its own normal: the neighbours only propose."""
    from dataclasses import replace
    sc = sphere_on_plane(40, 40)
    facet = (5, 5)                                         # on the plane, away from the sphere
    tilt = np.radians(30)
    sc.normals[facet] = [np.sin(tilt), 0, np.cos(tilt)]
    lights = thesis_light_directions()
    im = render(sc, lights, "glossy", noise=0.002, rng=np.random.default_rng(1)).astype(np.float32)
    base = ps_woodham1980(im, lights, mask=sc.mask)
    # the minima search off: it would bring the pushed pixels back before the neighbours do (its test below)
    settings = Settings(iterations=24, fine_iterations=2, fit_pixels=50, t_residual=0.05, engine=engine,
                        highlight_start="all", diffuse_models=("approx",), neighbour_deg=10.0, minima_search=False)
    px = Pixels.start(im, lights, 1, None, base, settings, 0)
    pix = np.arange(px.idx.size)
    px.store(pix, px.refine(pix, 0.05, 1.2))
    truth = sc.normals.reshape(-1, 3)[px.idx].astype(np.float32)
    flat = np.flatnonzero(sc.normals.reshape(-1, 3)[px.idx, 2] > 0.999)
    pushed = flat[[40, 160, 300]]                          # plane pixels, 35° off about y
    c, s = np.cos(np.radians(35)), np.sin(np.radians(35))
    px.nrm[pushed] = _unit(px.nrm[pushed] @ np.float32([[c, 0, -s], [0, 1, 0], [s, 0, c]]))
    f = int(np.flatnonzero(px.idx == facet[0] * 40 + facet[1])[0])
    assert angle_deg(px.nrm[f], truth[f]) < 2                  # the facet's solve found its own normal
    apart = angle_deg(px.nrm, _neighbour_means(px.nrm, px.idx, px.shape)) > 10
    assert apart[pushed].all() and apart[f]                  # all four are tried
    tried, moved = px.neighbour_round(pix, 0.05, 1.2)
    assert tried[0] >= pushed.size + 1 and moved[0] >= pushed.size
    assert len(tried) == len(moved) <= NEIGHBOUR_ROUNDS
    assert angle_deg(px.nrm[pushed], truth[pushed]).max() < 2, angle_deg(px.nrm[pushed], truth[pushed])
    assert angle_deg(px.nrm[f], truth[f]) < 2                  # kept: its values say 30°, not the plane's 0°
    # a 5 × 5 patch pushed off together: inside it a pixel agrees with its neighbours, so only its
    # rim stands apart; a ring that comes back leaves the next one apart, tried in the next round
    # (only the pixels around those that moved: their proposed start changed)
    plane = np.flatnonzero(sc.normals.reshape(-1, 3)[px.idx, 2] > 0.999)
    rows, cols = np.divmod(px.idx[plane], 40)
    patch = plane[(rows >= 30) & (rows < 35) & (cols >= 3) & (cols < 8)]
    good, back = px.nrm[patch].copy(), {}
    for rounds in (1, NEIGHBOUR_ROUNDS):
        px.nrm[patch] = _unit(good @ np.float32([[c, 0, -s], [0, 1, 0], [s, 0, c]]))
        tried, moved = px.neighbour_round(pix, 0.05, 1.2, rounds=rounds)
        back[rounds] = int((angle_deg(px.nrm[patch], truth[patch]) < 2).sum())
        if rounds > 1:
            assert len(tried) >= 3 and all(t < tried[0] for t in tried[1:]) and all(moved), (tried, moved)
    assert patch.size == 25 and back[NEIGHBOUR_ROUNDS] > back[1], back
    # no pixel this far from its neighbours: nothing tried
    px.settings = replace(settings, neighbour_deg=90.0)
    assert px.neighbour_round(pix, 0.05, 1.2) == ([], [])


def test_the_minima_search_brings_back_a_pixel_whose_solve_stopped_in_another_minimum():
    """`search_minima`: pixels pushed 35° off (as a solve stopped in another minimum) stand apart
    from their neighbours and are searched; each comes back to its own normal, the pixels that
    agree with their neighbours are left as they were (not searched), and the searched ones get
    the gap of their two best minima. Under more than SEARCH_MAX_LIGHTS lights nothing is searched."""
    from facette.fit._ps_li_minima import SEARCH_MAX_LIGHTS
    sc = sphere_on_plane(40, 40)
    lights = thesis_light_directions()
    im = render(sc, lights, "glossy", noise=0.002, rng=np.random.default_rng(1)).astype(np.float32)
    base = ps_woodham1980(im, lights, mask=sc.mask)
    settings = Settings(iterations=24, fine_iterations=2, fit_pixels=50, t_residual=0.05, engine="auto",
                        highlight_start="all", diffuse_models=("approx",), neighbour_deg=10.0)
    px = Pixels.start(im, lights, 1, None, base, settings, 0)
    pix = np.arange(px.idx.size)
    px.store(pix, px.refine(pix, 0.05, 1.2))
    truth = sc.normals.reshape(-1, 3)[px.idx].astype(np.float32)
    flat = np.flatnonzero(sc.normals.reshape(-1, 3)[px.idx, 2] > 0.999)
    pushed = flat[[40, 160, 300]]
    c, s = np.cos(np.radians(35)), np.sin(np.radians(35))
    px.nrm[pushed] = _unit(px.nrm[pushed] @ np.float32([[c, 0, -s], [0, 1, 0], [s, 0, c]]))
    before = px.nrm.copy()
    searched, moved = px.search_minima(pix, 0.05, 1.2)
    assert lights.shape[0] <= SEARCH_MAX_LIGHTS and searched < pix.size and moved >= pushed.size
    assert angle_deg(px.nrm[pushed], truth[pushed]).max() < 2, angle_deg(px.nrm[pushed], truth[pushed])
    alone = np.isnan(px.minima_gap)                        # not searched: untouched
    assert alone.sum() > pix.size // 2 and np.array_equal(px.nrm[alone], before[alone])
    assert ((px.minima_gap[~alone] >= 0) & (px.minima_gap[~alone] <= 1)).all()
    many = np.concatenate([lights, lights])                 # 24 lights: no search
    px24 = Pixels.start(np.concatenate([im, im]), many, 1, None, ps_woodham1980(np.concatenate([im, im]), many,
                        mask=sc.mask), settings, 0)
    assert px24.search_minima(pix, 0.05, 1.2) == (0, 0)


def test_a_cheaper_minimum_is_taken_only_toward_the_neighbours():
    """`_move_to_cheaper` (the minima search's and the isolated flags' last step): of two pixels each
    offered a minimum its cost calls cheaper, the one pushed 35° off whose minimum is the plane's own
    normal (nearer its neighbours' mean) moves there; the plane pixel offered a minimum 35° off (further
    from its neighbours) keeps its normal."""
    from facette.fit._ps_li_minima import Minima
    sc = sphere_on_plane(40, 40)
    lights = thesis_light_directions()
    im = render(sc, lights, "glossy", noise=0.002, rng=np.random.default_rng(1)).astype(np.float32)
    settings = Settings(iterations=24, fine_iterations=2, fit_pixels=50, t_residual=0.05, engine="auto",
                        highlight_start="all", diffuse_models=("approx",), neighbour_deg=10.0)
    px = Pixels.start(im, lights, 1, None, ps_woodham1980(im, lights, mask=sc.mask), settings, 0)
    pix = np.arange(px.idx.size)
    px.store(pix, px.refine(pix, 0.05, 1.2))
    truth = sc.normals.reshape(-1, 3)[px.idx].astype(np.float32)
    flat = np.flatnonzero(sc.normals.reshape(-1, 3)[px.idx, 2] > 0.999)
    pushed, kept = flat[40], flat[300]
    c, s = np.cos(np.radians(35)), np.sin(np.radians(35))
    turn = np.float32([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    px.nrm[pushed] = _unit(px.nrm[[pushed]] @ turn)[0]
    before = px.nrm[kept].copy()
    sel = np.array([pushed, kept])
    offered = np.stack([truth[pushed], _unit(truth[[kept]] @ turn)[0]])
    mm = Minima(normals=offered, cost_here=np.ones(2), cost_best=np.zeros(2), cost_second=np.full(2, np.inf))
    moved = px._move_to_cheaper(sel, mm, 0.05, 1.2, _neighbour_means(px.nrm, px.idx, px.shape)[sel])
    assert moved == 1
    assert angle_deg(px.nrm[pushed], truth[pushed]) < 2 and np.array_equal(px.nrm[kept], before)
