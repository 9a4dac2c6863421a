"""remove_interreflections: what a concave matte surface gathers from itself, taken out."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.bench._mitsuba_scenes import render_scene
from facette.methods import photometric_stereo
from facette.recon import remove_interreflections

UP = np.array([[0.0, 0.0, 1.0], [0.5, 0.0, np.sqrt(0.75)], [0.0, 0.5, np.sqrt(0.75)],
               [-0.5, 0.0, np.sqrt(0.75)]])


def _lambertian(normals, rho, lights):
    shade = np.clip(np.einsum("kd,hwd->khw", lights, normals), 0, None)
    return (rho * shade)[..., None].repeat(3, -1).astype(np.float32)


def _dome(n=48, radius=20.0):
    """A convex cap alone (its mask): no two of its points see each other. (On a plane it would
    not be: the plane's points near the cap see its side.)"""
    y, x = np.mgrid[:n, :n] - (n - 1) / 2.0
    r2 = x * x + y * y
    inside = r2 < radius ** 2
    z = np.sqrt(np.clip(radius ** 2 - r2, 0, None))
    nrm = np.dstack([x, -y, z]) / radius            # x right, y up (= -row)
    nrm[~inside] = (0, 0, 1)
    return nrm.astype(np.float32), inside


def _v_groove(width=64, length=160, slope=0.8):
    """A long groove along the columns: z = slope |x| (pixel units), its bottom at x = 0."""
    x = np.arange(width) - (width - 1) / 2.0
    z = slope * np.abs(x)
    heights = np.tile(z, (length, 1))
    nrm = np.zeros((length, width, 3))
    nrm[..., 0] = -np.sign(x) * slope              # n = (-dz/dx, 0, 1)
    nrm[..., 2] = 1.0
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    return nrm.astype(np.float32), heights.astype(np.float32), x, z


def test_a_convex_surface_gathers_nothing_and_keeps_its_images():
    nrm, mask = _dome()
    im = _lambertian(nrm, 0.7, UP)
    out, info = remove_interreflections(im, UP, nrm, np.full(mask.shape, 0.7), mask)
    np.testing.assert_array_equal(out, im)
    assert info["p95_fraction"] == 0.0 and info["capped"] == 0


def test_v_groove_matches_the_analytic_view_factor():
    # uniform radiance I0 over both faces: a strip of face A at distance u from the apex gathers
    # E = pi I0 F, F = (sin b2 - sin b1) / 2 (strip to an infinite strip, the angles of face B's
    # edges from the strip's normal); so I0 - out = rho I0 F
    nrm, heights, x, z = _v_groove()
    h, w = heights.shape
    i0, rho = 0.4, 0.6
    im = np.full((1, h, w), i0, np.float32)
    mask = np.ones((h, w), bool)
    out, info = remove_interreflections(im, UP[:1], nrm, np.full((h, w), rho), mask, grid=max(h, w),
                                        heights=heights, max_fraction=0.9)
    assert info["cell_px"] == 1
    row = h // 2
    half = w // 2
    far_b = np.array([x[-1], z[-1]])           # face B: x > 0, from the apex to its far edge
    for col in (4, 10, 20, 26):                # face A: x < 0
        p = np.array([x[col], z[col]])
        n_a = nrm[row, col, [0, 2]]
        t_a = np.array([n_a[1], -n_a[0]])      # the in-plane direction perpendicular to n_a
        apex = np.array([(x[half - 1] + x[half]) / 2, 0.0]) - p
        def sin_angle(v):
            v = v / np.linalg.norm(v)
            return float(np.dot(v, t_a))       # signed sine of the angle from n_a
        f = abs(sin_angle(far_b - p) - sin_angle(apex)) / 2
        got = (i0 - out[0, row, col]) / (rho * i0)
        assert got == pytest.approx(f, rel=0.06), (col, got, f)


def test_missing_values_stay_missing():
    nrm, heights, _, _ = _v_groove(32, 48)
    h, w = heights.shape
    im = np.full((2, h, w, 3), 0.3, np.float32)
    im[0, 5, 5] = np.nan
    im[1, 6, 6] = 2.0                          # at saturation
    out, _ = remove_interreflections(im, UP[:2], nrm, np.full((h, w, 3), 0.5), np.ones((h, w), bool),
                                     saturation=2.0, heights=heights)
    assert np.all(np.isnan(out[0, 5, 5])) and np.all(out[1, 6, 6] == 2.0)
    assert np.all(out[0, 20, 3] < 0.3)         # a groove's wall lost some light


def test_no_value_loses_more_than_the_cap():
    nrm, heights, _, _ = _v_groove(32, 48, slope=3.0)      # a deep groove: a lot gathered
    h, w = heights.shape
    im = np.full((1, h, w), 0.2, np.float32)
    out, info = remove_interreflections(im, UP[:1], nrm, np.full((h, w), 1.0), np.ones((h, w), bool),
                                        heights=heights, max_fraction=0.1, reflectance_scale=3.0)
    assert info["capped"] > 0 and np.all(out >= 0.9 * 0.2 - 1e-7)


@pytest.mark.parametrize("kwargs, words", [
    ({"reflectance_scale": 0.0}, "reflectance_scale"),
    ({"max_fraction": 1.0}, "max_fraction"),
    ({"grid": 2}, "grid"),
    ({"heights": np.zeros((3, 3))}, "heights"),
    ({"passes": 0}, "passes"),
    ({"lobe": [(0.1, 1.5)], "lobe_map": np.zeros((3, 3), int)}, "lobe_map"),
    ({"lobe": [(0.1, 1.5)], "lobe_map": np.zeros((16, 16), int), "diffuse_through": [True, False]}, "one per lobe"),
    ({"lobe": (0.0, 1.5)}, "σ > 0"),
])
def test_bad_options_are_refused_with_what_was_wrong(kwargs, words):
    nrm, mask = _dome(16, 6)
    im = _lambertian(nrm, 0.5, UP)
    with pytest.raises(ValueError, match=words):
        remove_interreflections(im, UP, nrm, np.full(mask.shape, 0.5), mask, **kwargs)


def test_shapes_that_do_not_match_are_refused():
    nrm, mask = _dome(16, 6)
    im = _lambertian(nrm, 0.5, UP)
    with pytest.raises(ValueError, match="must match"):
        remove_interreflections(im, UP, nrm[:8], np.full(mask.shape, 0.5), mask)
    with pytest.raises(ValueError, match="albedo"):
        remove_interreflections(im, UP, nrm, np.full((16, 16, 2), 0.5), mask)


def test_an_independent_renderers_concave_plaster_comes_closer_to_the_truth(tmp_path):
    # Mitsuba's path tracer (4 bounces) on a bas-relief in plaster: least squares after the
    # removal, with the shape of a first rank_trimmed pass, against least squares on the images
    d = render_scene("relief", "plaster", size=64, spp=32, cache_dir=tmp_path)
    sel = binary_erosion(d["mask"])
    im, lights = d["images"], d["light_dirs"]

    def err(images):
        n = photometric_stereo(images, lights, method="woodham1980", mask=d["mask"]).normal
        return np.degrees(np.arccos(np.clip(np.sum(n * d["normals"], -1), -1, 1)))[sel].mean()

    first = photometric_stereo(im, lights, method="rank_trimmed", mask=d["mask"])
    out, info = remove_interreflections(im, lights, first.normal, first.albedo, first.valid)
    before, after = err(im), err(out)
    assert after < 0.85 * before, (before, after)
    assert 0.005 < info["median_fraction"] < 0.1


def test_later_passes_reestimate_the_shape_of_a_deep_concavity(tmp_path):
    # the vase's neck: the first shape is turned by the light being removed; re-estimated on
    # the cells' corrected radiance, the next gathers come closer to the truth
    d = render_scene("vase", "plaster", size=64, spp=32, cache_dir=tmp_path)
    sel = binary_erosion(d["mask"])
    im, lights = d["images"], d["light_dirs"]
    first = photometric_stereo(im, lights, method="rank_trimmed", mask=d["mask"])

    def err(passes):
        out, info = remove_interreflections(im, lights, first.normal, first.albedo, first.valid, passes=passes)
        n = photometric_stereo(out, lights, method="rank_trimmed", mask=d["mask"]).normal
        return np.degrees(np.arccos(np.clip(np.sum(n * d["normals"], -1), -1, 1)))[sel].mean(), info

    (one, info1), (three, info3) = err(1), err(3)
    assert len(info1["passes"]) == 1 and len(info3["passes"]) >= 2
    assert info3["passes"][0]["median_change_deg"] > 0.1
    assert three < 0.9 * one, (one, three)


def test_per_pixel_light_directions_give_what_distant_ones_give():
    # near lights pass (H, W, m, 3); with the same direction everywhere the result must match,
    # on a bowl whose mask leaves cells empty (their directions are then not averaged from zeros)
    h = w = 32
    y, x = np.mgrid[:h, :w] - 15.5
    nrm = np.dstack([-0.04 * x, 0.04 * y, np.ones((h, w))])
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    lights = np.concatenate([UP, UP[1:] * [[-1, -1, 1]]])
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    im = _lambertian(nrm, 0.8, lights)
    mask = x * x + y * y < 14 ** 2
    for lobe in (None, (0.1, 1.4)):             # a glossy bowl's mirrors read the cells' lights too
        far, info = remove_interreflections(im, lights, nrm, np.full((h, w), 0.8), mask, grid=16, lobe=lobe)
        near, _ = remove_interreflections(im, np.broadcast_to(lights, (h, w, len(lights), 3)), nrm,
                                          np.full((h, w), 0.8), mask, grid=16, lobe=lobe)
        assert info["median_fraction"] > 0.01
        np.testing.assert_allclose(near, far, rtol=1e-5, atol=1e-7)


def _bowl_elements():
    """Four elements of a bowl, z = 0.15 ((col - 3.5)² + (row - 3.5)²), that see each other, with
    no surface grid in the way: (rows, cols, z, normals, grid), and each pair's (i, j, d, r, cos θ_i,
    cos θ_j, G_ij) where both face each other (d from i to j, camera frame: x right, y up)."""
    from facette.recon._interreflect_jit import OFF_SURFACE
    rows = np.array([0.0, 3.0, 7.0, 2.0], np.float32)
    cols = np.array([0.0, 7.0, 1.0, 4.0], np.float32)
    z = (0.15 * ((cols - 3.5) ** 2 + (rows - 3.5) ** 2)).astype(np.float32)
    nrm = np.stack([-0.3 * (cols - 3.5), 0.3 * (rows - 3.5), np.ones(4)], 1)
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32)
    pairs = []
    for i in range(4):
        for j in range(4):
            if i == j:
                continue
            d = np.array([cols[j] - cols[i], rows[i] - rows[j], z[j] - z[i]], float)
            r = np.linalg.norm(d)
            ci, cj = nrm[i] @ d / r, -(nrm[j] @ d) / r
            if ci > 0 and cj > 0:
                pairs.append((i, j, d, r, ci, cj, ci * cj / r ** 2 / max(nrm[j, 2], 0.05)))
    assert len(pairs) >= 6
    return rows, cols, z, nrm, np.full((8, 8), OFF_SURFACE, np.float32), pairs


def test_the_gather_weights_each_pair_by_the_interface_transmittance_at_both_ends():
    # the compiled gather against the sum written out, G_ij t(θ_i) t(θ_j) radiance_j, with a t(μ)
    # that is not flat
    from facette.recon._interreflect_jit import gather
    rows, cols, z, nrm, grid, pairs = _bowl_elements()
    rad = np.random.default_rng(3).uniform(0.1, 1.0, (4, 2)).astype(np.float32)
    tau = np.linspace(0.3, 0.95, 9).astype(np.float32) ** 0.5
    no_lights, ones = np.zeros((4, 2, 3), np.float32), np.ones((4, 2), np.float32)
    # element 3 has no lobe (a Lambertian material beside the others): t = 1 at its end
    lobe_of = np.array([0, 0, 0, -1], np.int32)
    no_lobe = (np.zeros(1), np.ones(1))
    got, _ = gather(rows, cols, z, nrm, rad, grid, 48, lobe_of, *no_lobe, tau[None], no_lights, ones, 0.0)
    flat, _ = gather(rows, cols, z, nrm, rad, grid, 48, np.full(4, -1, np.int32), *no_lobe, tau[None], no_lights,
                     ones, 0.0)
    t = lambda mu, k: np.interp(mu, np.linspace(0, 1, tau.size), tau) if lobe_of[k] >= 0 else 1.0
    want, plain = np.zeros((4, 2)), np.zeros((4, 2))
    for i, j, _, _, ci, cj, g in pairs:
        want[i] += g * t(ci, i) * t(cj, j) * rad[j]
        plain[i] += g * rad[j]
    np.testing.assert_allclose(flat, plain, rtol=1e-4)
    np.testing.assert_allclose(got, want, rtol=1e-4)


def test_a_glossy_cell_mirrors_its_lights_towards_the_cells_in_front_of_it():
    # each source j sends, for light l, f_s(s_l, ω_ji) (n_j·s_l) as far as it is lit; the receiver
    # takes it in as diffuse light and reflects it through its own lobe towards the camera:
    # against facette.brdf.li_specular in each element's own frame
    from facette.brdf import li_specular
    from facette.recon._interreflect_jit import gather, specular_towards_camera
    rows, cols, z, nrm, grid, pairs = _bowl_elements()
    sigma, n_i, scale = 0.3, 1.5, 0.8
    lights = np.array([[0.3, 0.2, 0.93], [-0.5, 0.1, 0.86]], np.float32)
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    lit = np.array([[1, 1], [1, 0.5], [0, 1], [1, 1]], np.float32)
    rad = np.zeros((4, 2), np.float32)                  # no diffuse light: the mirrors alone
    # two materials: elements 0-2 in one lobe, element 3 in another (σ 0.2, n_i 1.3)
    lobe_of = np.array([0, 0, 0, 1], np.int32)
    sig, nis = np.array([sigma, 0.2]), np.array([n_i, 1.3])
    out, spec = gather(rows, cols, z, nrm, rad, grid, 48, lobe_of, sig, nis, np.ones((2, 2), np.float32),
                       np.ascontiguousarray(np.broadcast_to(lights, (4, 2, 3))), lit, scale)

    def f_s(n, s, o, k):    # li_specular in the frame of normal n, element k's lobe
        e3 = n / np.linalg.norm(n)
        e1 = np.cross(e3, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        frame = np.stack([e1, np.cross(e3, e1), e3])
        return float(li_specular(frame @ s, frame @ o, sig[lobe_of[k]], nis[lobe_of[k]]))

    want, want_s = np.zeros((4, 2)), np.zeros((4, 2))
    v = np.array([0.0, 0.0, 1.0])
    for i, j, d, r, _, _, g in pairs:
        for l in range(2):
            sent = scale * lit[j, l] * max(nrm[j] @ lights[l], 0) * f_s(nrm[j], lights[l], -d / r, j)
            want[i, l] += g * sent
            want_s[i, l] += f_s(nrm[i], d / r, v, i) * g * sent
    assert np.count_nonzero(want) >= 3
    np.testing.assert_allclose(out, want, rtol=1e-3, atol=1e-7)
    np.testing.assert_allclose(spec, want_s, rtol=1e-3, atol=1e-7)
    cam = specular_towards_camera(nrm, np.ascontiguousarray(np.broadcast_to(lights, (4, 2, 3))), lobe_of, sig, nis)
    np.testing.assert_allclose(cam, [[max(n @ s, 0) * f_s(n, s, v, k) for s in lights] for k, n in enumerate(nrm)],
                               rtol=1e-4, atol=1e-6)


def test_a_glossy_reliefs_diffuse_light_is_gathered_through_its_interface(tmp_path):
    # Mitsuba's rough plastic relief (paint: σ 0.05, n_i 1.26): its inter-reflected light is what
    # a 4-bounce render holds beyond a direct-light one. A wall under an interface lets its diffuse
    # light out weaker along the relief (grazing angles) than towards the camera, and its neighbour
    # takes it in weaker: gathered as by a Lambertian surface the removed light was 1.29x the true
    # one, through the transmittance 0.96x (64 px, 32 spp; the walls' mirrored highlights in both)
    full = render_scene("relief", "paint_0.05", size=64, spp=32, cache_dir=tmp_path)
    direct = render_scene("relief", "paint_0.05", size=64, spp=32, max_depth=2, cache_dir=tmp_path)
    sel = binary_erosion(full["mask"], iterations=2)
    im, lights = full["images"], full["light_dirs"]
    first = photometric_stereo(im, lights, method="rank_trimmed", mask=full["mask"])
    true = (im - direct["images"])[:, sel].sum()
    ratio = {}
    for through in (False, True):
        out, _ = remove_interreflections(im, lights, full["normals"], first.albedo, full["mask"], passes=1,
                                         lobe=(0.05, 1.26), diffuse_through=through)
        ratio[through] = (im - out)[:, sel].sum() / true
    assert ratio[False] > 1.15 and 0.9 < ratio[True] < 1.05, ratio


def test_each_material_gathers_through_its_own_lobe():
    # a lobe map naming one material everywhere is the single lobe; a map that gives half the
    # groove a second material changes the light removed there, and a material without a lobe
    # (None) is a Lambertian one
    nrm, heights, _, _ = _v_groove(32, 48)
    h, w = heights.shape
    im = np.stack([_lambertian(nrm, 0.5, UP[k:k + 1])[0] for k in range(4)])
    args = (im, UP, nrm, np.full((h, w, 3), 0.5), np.ones((h, w), bool))
    kw = {"heights": heights, "passes": 1}
    one, _ = remove_interreflections(*args, lobe=(0.1, 1.5), **kw)
    same, _ = remove_interreflections(*args, lobe=[(0.1, 1.5), (0.3, 1.4)], lobe_map=np.zeros((h, w), int), **kw)
    np.testing.assert_allclose(same, one, rtol=1e-6, atol=1e-7)
    halves = np.zeros((h, w), int)
    halves[:, w // 2:] = 1
    two, _ = remove_interreflections(*args, lobe=[(0.1, 1.5), (0.3, 1.4)], lobe_map=halves, **kw)
    plain, _ = remove_interreflections(*args, **kw)
    lamb, _ = remove_interreflections(*args, lobe=[None], lobe_map=np.zeros((h, w), int), **kw)
    np.testing.assert_allclose(lamb, plain, rtol=1e-6, atol=1e-7)
    assert np.abs(two - one).max() > 1e-4 and not np.allclose(two, plain)


def test_the_compiled_subtraction_is_the_interpolated_capped_difference():
    # one light: the cells' light interpolated bilinearly between cell centres (np.interp along
    # rows, then columns), times the per-pixel scale, the glossy share where the surface is, capped
    # at max_fraction x the value; NaN, inf and clipped values kept as they were
    from facette.recon._interreflect import _interp_taps
    from facette.recon._interreflect_jit import subtract_gathered
    rng = np.random.default_rng(4)
    h, w, c, f = 23, 17, 2, 4
    hc, wc = -(-h // f), -(-w // f)
    g, gl = rng.random((hc, wc, c), np.float32), rng.random((hc, wc, c), np.float32) * 0.1
    v = rng.random((h, w, c), np.float32) * 2 - 0.2
    v[3, 4, 0], v[5, 6, 1], v[7, 8, 0] = np.nan, np.inf, 1.5
    scale = rng.random((h, w, c), np.float32)
    ok = rng.random((h, w)) > 0.3
    centres_r, centres_c = (np.arange(hc) + 0.5) * f - 0.5, (np.arange(wc) + 0.5) * f - 0.5

    def bilinear(cells):
        rows = np.stack([[np.interp(np.arange(h), centres_r, cells[:, j, k]) for k in range(c)]
                         for j in range(wc)])                                  # (wc, c, h)
        return np.stack([[np.interp(np.arange(w), centres_c, rows[:, k, y]) for k in range(c)]
                         for y in range(h)]).transpose(0, 2, 1)                # (h, w, c)

    ir = bilinear(g) * scale + bilinear(gl) * ok[..., None]
    limit = 0.5 * v
    with np.errstate(invalid="ignore"):
        want = np.where(v < 1.5, v - np.where(ir > limit, np.maximum(limit, 0), ir), v)
        want_capped = int(np.count_nonzero((ir > limit) & (v < 1.5)))
    out = np.empty_like(v)
    capped = subtract_gathered(v, g, gl, *_interp_taps(h, hc, f), *_interp_taps(w, wc, f), scale, ok,
                               np.float32(0.5), np.float32(1.5), out)
    np.testing.assert_allclose(out, want, rtol=1e-5, atol=1e-6)
    assert capped == want_capped > 0
    assert np.isnan(out[3, 4, 0]) and out[5, 6, 1] == np.inf and out[7, 8, 0] == 1.5
    # without the glossy cells (shape (0, 0, c)) only the Lambertian share goes
    capped = subtract_gathered(v, g, np.zeros((0, 0, c), np.float32), *_interp_taps(h, hc, f),
                               *_interp_taps(w, wc, f), scale, ok, np.float32(10.0), np.float32(1.5), out)
    on = (v >= 0.1) & (v < 1.5)                     # no cap there: 10 x the value is above the light
    np.testing.assert_allclose(out[on], (v - bilinear(g) * scale)[on], rtol=1e-5, atol=1e-6)
    assert np.array_equal(out[v < 0], v[v < 0])         # a negative value: nothing removed (the cap is 0)
