"""refine_normals_li: per-pixel normals and K_d against a given LI model, and its edges."""
import numpy as np
import pytest

from facette.brdf import li_kappa, li_shading_terms
from facette.fit import refine_normals_li

RIG = np.array([[np.sin(np.radians(t)) * np.cos(np.radians(p)), np.sin(np.radians(t)) * np.sin(np.radians(p)),
                 np.cos(np.radians(t))] for k in range(6) for t, p in ((30, 60 * k), (15, 30 + 60 * k))])


# a dome's lights (MANY_LIGHTS or more: the solve's second start only where the first explains poorly)
DOME = np.array([[np.sin(np.radians(t)) * np.cos(np.radians(p)), np.sin(np.radians(t)) * np.sin(np.radians(p)),
                  np.cos(np.radians(t))] for k in range(12) for t, p in ((20, 30 * k), (45, 15 + 30 * k), (65, 30 * k))])


def _scene(n=400, sigma=0.1, n_i=1.3, seed=0, lights=RIG):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3)) * [0.5, 0.5, 0]
    v[:, 2] = 1
    normals = (v / np.linalg.norm(v, axis=1, keepdims=True)).astype(np.float32)
    kd = rng.uniform(0.2, 0.8, size=(n, 3))
    a, b = li_shading_terms(normals, lights, sigma, n_i)
    e = a[..., None] + b[..., None] * li_kappa(kd, n_i)[:, None, :]
    return normals, kd, e.astype(np.float32)


def _perturb(normals, deg, seed=1):
    rng = np.random.default_rng(seed)
    p = normals + np.radians(deg) * rng.normal(size=normals.shape)
    return (p / np.linalg.norm(p, axis=1, keepdims=True)).astype(np.float32)


def _err(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, -1), -1, 1)))


def test_recovers_normals_and_kd_of_model_images():
    normals, kd, e = _scene()
    r = refine_normals_li(e, RIG, _perturb(normals, 3), 0.1, 1.3)
    assert np.median(_err(r.normals, normals)) < 0.05
    assert np.percentile(_err(r.normals, normals), 95) < 0.5
    np.testing.assert_allclose(np.median(r.kd / kd, axis=0), 1, atol=0.01)
    assert r.normals.shape == (400, 3) and r.kd.shape == (400, 3) and r.used.shape == (400, 12)


def test_a_cast_shadow_and_an_outlier_are_left_out():
    normals, kd, e = _scene(sigma=0.3, n_i=1.5)
    e = e.copy()
    e[:, 3] *= 0.05            # a cast shadow on light 3
    e[:, 7] *= 3.0             # an inter-reflection or a stray light on light 7
    for engine in ("arrays", "compiled"):
        r = refine_normals_li(e, RIG, _perturb(normals, 3), 0.3, 1.5, iterations=30, engine=engine)
        assert not r.used[:, 3].any(), engine
        assert np.median(_err(r.normals, normals)) < 0.15, engine


def test_compiled_engine_solves_the_same_problem_as_the_array_code():
    # one channel: the compiled engine's normal from the channels' mean is then the same problem
    normals, kd, e = _scene(sigma=0.1, n_i=1.3)
    e = e[..., 1:2].copy()
    e[:, 5] *= 0.1
    start = _perturb(normals, 4)
    ra = refine_normals_li(e, RIG, start, 0.1, 1.3, engine="arrays", extra_starts=[normals])
    rc = refine_normals_li(e, RIG, start, 0.1, 1.3, engine="compiled", extra_starts=[normals])
    assert np.median(_err(ra.normals, rc.normals)) < 0.01
    assert np.percentile(_err(ra.normals, rc.normals), 95) < 0.1
    np.testing.assert_allclose(np.median(rc.kd / ra.kd), 1, atol=2e-3)
    np.testing.assert_array_equal(ra.used, rc.used)
    # three channels: the normal from their mean, K_d per channel still
    normals, kd, e3 = _scene(sigma=0.1, n_i=1.3)
    r3 = refine_normals_li(e3, RIG, _perturb(normals, 3), 0.1, 1.3, engine="compiled")
    assert np.median(_err(r3.normals, normals)) < 0.05
    np.testing.assert_allclose(np.median(r3.kd / kd, axis=0), 1, atol=0.01)


@pytest.mark.parametrize("tilts", [(0, 60), (80, 89.5)])
def test_volume_table_matches_the_direct_evaluation(tilts):
    # up to the rim too: on a grid of (n_x, n_y) the steep normals' B was 2 % off (median) at
    # 80-87° of tilt and 21 % at 87-89.5°, with the table in stereographic coordinates ≤ 2e-4
    from facette.fit._normals_li_jit import volume_table
    rng = np.random.default_rng(3)
    th, ph = np.radians(rng.uniform(*tilts, 5000)), rng.uniform(0, 2 * np.pi, 5000)
    n = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).astype(np.float32)
    _, b = li_shading_terms(n, RIG, 0.1, 1.3, specular=False)
    tab = volume_table(RIG, 0.1, 1.3)
    g = tab.shape[0]                      # the table's cell: stereographic (u, v) = (n_x, n_y) / (1 + n_z)
    fx, fy = (n[:, 0] / (1 + n[:, 2]) + 1) / 2 * (g - 1), (n[:, 1] / (1 + n[:, 2]) + 1) / 2 * (g - 1)
    ix, iy = fx.astype(int), fy.astype(int)
    wx, wy = (fx - ix)[:, None], (fy - iy)[:, None]
    bi = ((1 - wx) * (1 - wy) * tab[iy, ix] + wx * (1 - wy) * tab[iy, ix + 1]
          + (1 - wx) * wy * tab[iy + 1, ix] + wx * wy * tab[iy + 1, ix + 1])
    lit = b > 0.05 * b.max()
    rel = np.abs(bi - b)[lit] / b[lit]
    assert np.median(rel) < 2e-4 and np.percentile(rel, 99) < 5e-3


def test_volume_table_in_blocks_equals_one_evaluation_of_the_whole_disk():
    # the table is evaluated TABLE_BLOCK normals at a time on threads: not a bit may change
    from facette.fit._normals_li_jit import TABLE_BLOCK, _volume_table
    from facette.fit._stereo import stereo_grid
    grid = 81
    gn, r2 = stereo_grid(grid)
    inside = r2 < 1
    gn = gn[inside].astype(np.float32)
    assert len(gn) > 3 * TABLE_BLOCK
    for volume_model in ("approx", "tables"):
        tab = _volume_table(RIG, 0.15, 1.4, grid, volume_model)
        _, whole = li_shading_terms(gn, RIG, 0.15, 1.4, specular=False, volume_model=volume_model)
        np.testing.assert_array_equal(tab[inside], whole)
        near = ~inside & (np.sqrt(r2) < 1 + 2.5 * 2 / (grid - 1))     # the continuation across the rim
        assert (tab[near] >= 0).all() and tab[near].any() and not tab[~inside & ~near].any()


def test_coarse_volume_tables_are_remembered_within_their_byte_budget(monkeypatch):
    # the model choice asks for the same coarse tables in every li run: kept (more than the solve's
    # KEEP_LARGE of them), the same numbers as a fresh one, the oldest let go past SMALL_BYTES
    import facette.fit._normals_li_table as T
    monkeypatch.setattr(T, "_SMALL", {})
    first = T.volume_table(RIG, 0.2, 1.4, grid=17)
    for k in range(T.KEEP_LARGE + 2):
        T.volume_table(RIG, 0.1 + 0.01 * k, 1.3, grid=17)
    assert T.volume_table(RIG, 0.2, 1.4, grid=17) is first
    np.testing.assert_array_equal(first, T._volume_table(np.asarray(RIG, np.float64), 0.2, 1.4, 17, "approx"))
    monkeypatch.setattr(T, "SMALL_BYTES", 3 * first.nbytes)
    T.volume_table(RIG, 0.5, 1.3, grid=17)
    assert len(T._SMALL) == 3 and T.volume_table(RIG, 0.2, 1.4, grid=17) is not first


def test_the_compiled_lobe_derivative_matches_central_differences():
    # the per-pixel solve's Jacobian of the lobe A (eq 3.10) is analytic (`_model`'s pa, qa):
    # dA/dt = pa (s·t) + qa t_z along a tangent t of the normal; central differences of A agree
    # (G_1 from its table: the derivative is the tabulated G_1's own)
    from facette.brdf import fresnel_dielectric
    from facette.brdf._lobe_jit import SMITH_G1_TABLE
    from facette.fit._normals_li_jit import _model
    rng = np.random.default_rng(5)
    s = RIG.astype(np.float64)
    sh = np.sqrt((1 + s[:, 2]) / 2)
    m = len(s)
    btab = np.zeros((5, 5, m))
    every = np.arange(m)
    out = [np.empty(m) for _ in range(5)]
    lo, hi = [np.empty(m) for _ in range(5)], [np.empty(m) for _ in range(5)]
    checked = 0
    for sigma, n_i in ((0.05, 1.5), (0.2, 1.3), (0.4, 1.45)):
        fres = fresnel_dielectric(sh, n_i).astype(np.float64)
        for _ in range(40):
            n = np.array([*rng.normal(0, 0.4, 2), 1.0])
            n /= np.linalg.norm(n)
            t = np.cross(n, rng.normal(size=3))
            t /= np.linalg.norm(t)
            _model(*n, s, sh, fres, btab, SMITH_G1_TABLE, sigma, True, every, m, *out)
            h = 1e-6
            for sign, buf in ((1, hi), (-1, lo)):
                p = n + sign * h * t
                _model(*(p / np.linalg.norm(p)), s, sh, fres, btab, SMITH_G1_TABLE, sigma, True, every, m, *buf)
            fd = (hi[0] - lo[0]) / (2 * h)
            analytic = out[2] * (s @ t) + out[3] * t[2]
            lit = out[0] > 1e-3 * out[0].max()      # away from the lobe's cut-off
            np.testing.assert_allclose(analytic[lit], fd[lit], rtol=1e-4, atol=1e-6 * out[0].max())
            checked += lit.sum()
    assert checked > 200


def test_compiled_engine_refuses_what_it_cannot_do():
    normals, kd, e = _scene(n=10)
    lights = np.broadcast_to(RIG, (10, 12, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="compiled"):
        refine_normals_li(e, lights, normals, 0.1, 1.3, engine="compiled")
    with pytest.raises(ValueError, match="engine"):
        refine_normals_li(e, RIG, normals, 0.1, 1.3, engine="fast")


def test_per_pixel_lights():
    normals, kd, e = _scene(n=100)
    lights = np.broadcast_to(RIG, (100, 12, 3)).astype(np.float32)
    r = refine_normals_li(e, lights, _perturb(normals, 2), 0.1, 1.3)
    assert np.median(_err(r.normals, normals)) < 0.05


def test_stability_black_saturated_and_shadowed_pixels():
    normals, kd, e = _scene(n=6)
    e = e.copy()
    e[0] = 0                                   # black under every light
    usable = np.ones((6, 12), bool)
    usable[1] = False                          # saturated under every light
    usable[2, 1:] = False                      # a single light left after elimination
    e[3] = np.nan                              # missing values
    start = _perturb(normals, 2)
    r = refine_normals_li(e, RIG, start, 0.1, 1.3, usable=usable)
    for name in ("normals", "kappa", "kd", "cost", "rel_residual"):
        assert np.all(np.isfinite(getattr(r, name)[[0, 1, 2, 3, 4, 5]] if name != "rel_residual"
                                  else getattr(r, name)[[0, 4, 5]])), name
    # pixels with fewer than 3 kept values keep their starting normal (documented)
    np.testing.assert_allclose(r.normals[1:4], start[1:4], atol=1e-6)
    assert np.all(r.kd[0] == 0)
    assert np.median(_err(r.normals[4:], normals[4:])) < 0.2


def test_sigma_to_zero_and_no_interface_give_finite_normals():
    normals, kd, e = _scene(n=50, sigma=0.1, n_i=1.3)
    for sigma, n_i in ((0.0, 1.3), (1e-4, 1.3), (0.1, 1.0)):
        r = refine_normals_li(e, RIG, _perturb(normals, 2), sigma, n_i)
        assert np.all(np.isfinite(r.normals)) and np.allclose(np.linalg.norm(r.normals, axis=1), 1, atol=1e-5)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="lights"):
        refine_normals_li(np.zeros((5, 12, 3)), np.ones((4, 3)), np.tile([0, 0, 1.0], (5, 1)), 0.1, 1.3)


def test_compiled_engine_same_result_on_one_thread_and_on_all():
    # the per-pixel loop runs on numba's threads (prange over chunks of pixels): each pixel is
    # solved alone, so the thread count and the chunking must not change a single bit
    import numba
    from facette.fit._normals_li_jit import _refine_all, refine_distant_compiled
    assert _refine_all.targetoptions.get("parallel"), "the per-pixel loop is no longer threaded"
    normals, kd, e = _scene(n=1500, sigma=0.2, n_i=1.4, seed=3)
    e = e.copy()
    e[::7, 4] *= 0.05                       # some cast shadows and outliers: pixels of uneven cost
    e[::5, 9] *= 2.5
    start, extra = _perturb(normals, 5), _perturb(normals, 2, seed=4)
    rows = np.arange(len(normals)) % 3 == 0
    ok = np.ones(e.shape[:2], bool)
    args = (e, RIG, start, 0.2, 1.4, ok, 24, extra, rows)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        serial = refine_distant_compiled(*args)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        threaded = refine_distant_compiled(*args)
        small_chunks = refine_distant_compiled(*args, chunk=7)
    finally:
        numba.set_num_threads(before)
    for other in (threaded, small_chunks):
        for a, b in zip(serial, other):
            np.testing.assert_array_equal(a, b)
    assert np.median(_err(serial[0], normals)) < 0.05   # and it did solve something


@pytest.mark.parametrize("lights", [RIG, DOME], ids=["rig, 12 lights", "dome, 36 lights"])
def test_compiled_solve_equals_the_all_lights_reference_bit_for_bit(lights):
    # the kernel evaluates only the kept lights (packed to the front): a light left out weighed 0
    # in every sum, so the result must be that of evaluating every light (li_solve_reference),
    # to the last bit, also for unusable values, cast shadows, too few lights and no light at all
    from facette.brdf import fresnel_dielectric
    from facette.brdf._lobe_jit import SMITH_G1_TABLE
    from facette.fit._normals_li_jit import _refine_all, volume_table
    from li_solve_reference import refine_reference
    sigma, n_i = 0.25, 1.45
    normals, kd, e = _scene(n=24, sigma=sigma, n_i=n_i, seed=7)
    rng = np.random.default_rng(8)
    e = e * rng.uniform(0.9, 1.1, e.shape).astype(np.float32)
    ok = rng.random(e.shape[:2]) > 0.25          # a quarter of the values unusable
    ok[0] = False                                # no usable light
    ok[1, 2:] = False                            # two lights: too few
    e[2:12:2, 4] *= 0.05                         # cast shadows
    e[3:12:2, 6] *= 3.0                          # outliers
    e = np.where(ok[..., None], e, 0).astype(np.float32)   # as refine_distant_compiled hands them
    s = RIG.astype(np.float64)
    sh = np.sqrt(np.maximum((1 + s[:, 2]) / 2, 1e-12))
    fres = fresnel_dielectric(sh, n_i).astype(np.float64)
    btab = volume_table(RIG, sigma, n_i, grid=33)
    n0 = _perturb(normals, 6).astype(np.float64)
    n1 = _perturb(normals, 3, seed=2).astype(np.float64)
    has1 = np.arange(len(e)) % 2 == 0            # a second start on every other pixel
    args = (e, ok, n0, n1, has1, s, sh, fres, btab, sigma, True, 24, 0.25, 0.03, 0.15, 2e-4, 0.0)
    out = (np.empty((len(e), 3)), np.empty((len(e), 3)), np.empty(e.shape[:2], bool), np.empty(len(e)),
           np.empty(len(e)), np.empty(len(e), np.int32))
    _refine_all(*args[:9], SMITH_G1_TABLE, *args[9:], *out, 5)
    ref = refine_reference(*args)
    for name, got, want in zip(("normals", "kappa", "used", "cost", "rel", "iterations"), out, ref):
        np.testing.assert_array_equal(got, want, err_msg=name)
    assert not out[2][0].any() and out[4][0] == 1.0 and out[5][0] == 0     # no light: the start kept
    assert (out[5][2:] > 0).all() and (ok & ~out[2]).any()                 # the others solved, shadows out


@pytest.mark.parametrize("engine", ["arrays", "compiled"])
def test_a_broad_lobe_converges_from_a_distant_start(engine):
    # κ is solved again at every candidate, so the step must be the variable-projection one (the
    # Jacobian's part a change of κ cannot mimic); the plain Gauss–Newton step zig-zagged between
    # the normal and κ and stopped 0.6–0.8° short (median) after 24 steps on these noiseless pixels
    normals, _, e = _scene(sigma=0.3, n_i=1.5)
    r = refine_normals_li(e, RIG, _perturb(normals, 10), 0.3, 1.5, iterations=24, engine=engine)
    err = _err(r.normals, normals)
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.1
