"""facette.calib.mirror_sphere: outline, highlight, light directions and positions."""
import numpy as np
import pytest

from facette.calib import nominal_light_directions
from facette.calib.mirror_sphere import (Circle, fit_circle, fit_sphere_outline, highlight_centroid,
                                         light_positions_from_rays, mirror_direction,
                                         mirror_sphere_directions, sphere_mask, sphere_rays)
from facette.calib.targets import render_mirror_sphere

SHAPE, PITCH = (150, 180), 0.2
CENTER, R = (88.3, 71.6), 50.4


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1)))


def _mirror_stack(dirs=None, positions=None, center=CENTER, noise=0.0, seed=0, supersample=6, **kw):
    rng = np.random.default_rng(seed)
    n = len(dirs if dirs is not None else positions)
    out = []
    for i in range(n):
        lk = {"direction": dirs[i]} if positions is None else {"position_mm": positions[i]}
        img = render_mirror_sphere(SHAPE, center, R, PITCH, source_radius_deg=1.0, psf_px=1.0,
                                   supersample=supersample, **lk, **kw)
        out.append(img + noise * rng.standard_normal(img.shape))
    return np.stack(out)


_NOMINAL = {}


def _nominal_stack():
    """The 12 nominal LEDs on the mirror sphere, rendered once for the tests that share it."""
    if "stack" not in _NOMINAL:
        _NOMINAL["stack"] = _mirror_stack(nominal_light_directions())
    return _NOMINAL["stack"]


def test_fit_circle_exact_and_rejects_too_few_points():
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    c = fit_circle(np.c_[10.25 + 7.5 * np.cos(t), -3.5 + 7.5 * np.sin(t)])
    assert (c.cx, c.cy, c.r) == pytest.approx((10.25, -3.5, 7.5), abs=1e-9)
    with pytest.raises(ValueError, match="at least 3"):
        fit_circle([[0, 0], [1, 1]])


def test_outline_is_sub_pixel_from_the_grey_edge():
    img = _nominal_stack().mean(axis=0)
    mask = sphere_mask(img, dark=True)
    binary = fit_sphere_outline(mask)
    grey = fit_sphere_outline(mask, img)
    for c, tol in ((binary, 0.3), (grey, 0.05)):
        assert abs(c.cx - CENTER[0]) < tol and abs(c.cy - CENTER[1]) < tol and abs(c.r - R) < tol


def test_mirror_directions_match_truth_to_a_tenth_of_a_degree():
    d = nominal_light_directions()
    noisy = _nominal_stack() + 0.02 * np.random.default_rng(0).standard_normal(_nominal_stack().shape)
    dirs, circle, hl = mirror_sphere_directions(noisy)
    err = _angle_deg(dirs, d)
    assert err.max() < 0.15, err
    assert not any(h.saturated for h in hl)


def test_mirror_direction_formula_and_frame():
    c = Circle(50.0, 50.0, 40.0)
    np.testing.assert_allclose(mirror_direction(c, 50.0, 50.0), [0, 0, 1], atol=1e-12)
    # a highlight right of and above the centre: the light is right (+x) and up (+y)
    l = mirror_direction(c, 50.0 + 40 * np.sin(np.radians(10)), 50.0)
    np.testing.assert_allclose(l, [np.sin(np.radians(20)), 0, np.cos(np.radians(20))], atol=1e-12)
    assert mirror_direction(c, 50.0, 40.0)[1] > 0      # row above the centre: y up
    with pytest.raises(ValueError, match="outside the sphere"):
        mirror_direction(c, 95.0, 50.0)


def test_saturated_highlight_is_flagged_and_still_centred():
    d = nominal_light_directions()[:1]
    img = _mirror_stack(d)[0]
    c = Circle(*CENTER, R)
    ref = highlight_centroid(img, c)
    white = 0.3 * ref.peak
    clipped = highlight_centroid(np.minimum(img, white), c, white_level=white)
    assert clipped.saturated and not ref.saturated
    assert np.hypot(clipped.x - ref.x, clipped.y - ref.y) < 0.05


def test_missing_sphere_or_highlight_errors():
    flat = np.ones(SHAPE)
    with pytest.raises(ValueError, match="no sphere"):
        sphere_mask(flat)
    img = render_mirror_sphere(SHAPE, CENTER, R, PITCH, direction=[0, 0, 1.0], intensity=0.0,
                               supersample=1)   # the LED did not light
    with pytest.raises(ValueError, match="no highlight"):
        highlight_centroid(img, Circle(*CENTER, R), )


def test_led_positions_from_two_placements():
    d = nominal_light_directions()
    P = d * 400.0 + np.array([5.0, -3.0, 0.0])
    origins, dirs = [], []
    for center in ((52.0, 72.0), (128.0, 78.0)):
        stack = _mirror_stack(positions=P, center=center, supersample=3)
        _, circle, hl = mirror_sphere_directions(stack)
        o, l = sphere_rays(circle, hl, SHAPE, PITCH)
        origins.append(o)
        dirs.append(l)
    est, rms = light_positions_from_rays(np.array(origins), np.array(dirs))
    err = np.linalg.norm(est - P, axis=1)
    # 15 mm baseline at 400 mm: a 0.05° ray error moves the point ~ 400²/15 · 1e-3 mm along the ray
    assert np.median(err) < 15.0, err
    assert _angle_deg(est / np.linalg.norm(est, axis=1, keepdims=True),
                      P / np.linalg.norm(P, axis=1, keepdims=True)).max() < 0.5
    with pytest.raises(ValueError, match="two sphere placements"):
        light_positions_from_rays(np.array(origins[:1]), np.array(dirs[:1]))


def test_rays_intersect_exactly_when_noise_free():
    P = np.array([[100.0, 50.0, 900.0], [-300.0, 20.0, 1200.0]])
    o = np.array([[[0, 0, 10.0], [0, 0, 10.0]], [[30.0, 0, 10.0], [30.0, 0, 10.0]],
                  [[0, 25.0, 10.0], [0, 25.0, 10.0]]])
    d = P[None] - o
    est, rms = light_positions_from_rays(o, d / np.linalg.norm(d, axis=-1, keepdims=True))
    np.testing.assert_allclose(est, P, atol=1e-8)
    assert rms.max() < 1e-8
    with pytest.raises(ValueError, match="parallel"):
        light_positions_from_rays(o[:2], np.broadcast_to([0, 0, 1.0], o[:2].shape))


def test_directions_from_origin_remove_the_sphere_parallax():
    from facette.calib.mirror_sphere import directions_from_origin

    P = nominal_light_directions() * 1500.0
    o = np.tile([10.0, -5.0, 50.0], (12, 1))            # highlight points above the table
    l = (P - o) / np.linalg.norm(P - o, axis=1, keepdims=True)
    assert _angle_deg(l, P / 1500.0).max() > 0.5          # the raw rays are off by the parallax
    d = directions_from_origin(o, l, 1500.0)
    np.testing.assert_allclose(d, P / 1500.0, atol=1e-12)
    with pytest.raises(ValueError, match="LED distance"):
        directions_from_origin(o, l, 10.0)


def test_sphere_cut_by_the_frame_or_too_small_is_refused():
    img = render_mirror_sphere(SHAPE, (5.0, 70.0), R, PITCH, direction=[0, 0, 1.0], supersample=1)
    with pytest.raises(ValueError, match="touches the edge of the frame"):
        sphere_mask(img)
    small = render_mirror_sphere(SHAPE, CENTER, 5.0, PITCH, direction=[0, 0, 1.0], supersample=2)
    with pytest.raises(ValueError, match="too small|only .* px in radius"):
        fit_sphere_outline(sphere_mask(small), small)
    with pytest.raises(ValueError, match="finite"):
        sphere_mask(np.full(SHAPE, np.nan))


def _coverage(center, radius, supersample=4):
    """Share of each pixel inside the sphere's disc, (H, W)."""
    o = (np.arange(supersample) + 0.5) / supersample - 0.5
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    inside = [np.hypot(cols + dx - center[0], rows + dy - center[1]) < radius for dy in o for dx in o]
    return np.mean(inside, axis=0)


def _sphere_on(background, dirs, env=0.02, seed=3):
    """The chrome sphere (its card black) over a given background (H, W), mirroring a faint
    environment (brighter towards the top, as a room's ceiling) besides the LED: the RTI
    photographs' sphere, not the rig's card."""
    cov = _coverage(CENTER, R)
    rows = np.mgrid[0:SHAPE[0], 0:SHAPE[1]][0]
    room = env * (1.5 - (rows - (CENTER[1] - R)) / (2 * R))
    rng = np.random.default_rng(seed)
    out = []
    for d in dirs:
        sphere = render_mirror_sphere(SHAPE, CENTER, R, PITCH, direction=d, source_radius_deg=1.0,
                                      psf_px=1.0, supersample=4, backdrop_albedo=0.0)[..., 1]
        img = sphere + cov * room + (1 - cov) * background
        out.append(img + 0.002 * rng.standard_normal(img.shape))
    return np.stack(out)


def _dark_background():
    return np.full(SHAPE, 0.01)


def _textured_background(seed=5):
    """Cloth and print: a checkerboard of 9 px squares, black and light grey, under smoothed
    noise. Its black squares join the dark sphere, so the card method finds no round region."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    checks = ((rows // 9 + cols // 9) % 2) * 0.4
    from scipy import ndimage
    return np.clip(checks + 0.05 * ndimage.gaussian_filter(rng.standard_normal(SHAPE), 2.0), 0.003, None)


@pytest.mark.parametrize("background", [_dark_background, _textured_background],
                         ids=["dark", "textured"])
def test_sphere_found_on_a_dark_or_busy_background_gives_directions_within_half_a_degree(background):
    dirs = nominal_light_directions()
    stack = _sphere_on(background(), dirs)
    got, circle, hls = mirror_sphere_directions(stack)
    assert abs(circle.cx - CENTER[0]) < 0.5 and abs(circle.cy - CENTER[1]) < 0.5
    assert abs(circle.r - R) < 0.5
    err = _angle_deg(got, dirs)
    assert err.max() < 0.5, err


def test_sphere_given_as_a_circle_or_a_mask_is_used_as_given():
    dirs = nominal_light_directions()
    stack = _sphere_on(_textured_background(), dirs)
    got_c, circle, _ = mirror_sphere_directions(stack, circle=(CENTER[0], CENTER[1], R))
    assert (circle.cx, circle.cy, circle.r) == (CENTER[0], CENTER[1], R)
    assert _angle_deg(got_c, dirs).max() < 0.5
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    mask = np.hypot(cols - CENTER[0], rows - CENTER[1]) < R
    got_m, circle_m, _ = mirror_sphere_directions(stack, mask=mask)
    assert abs(circle_m.r - R) < 1.0
    assert _angle_deg(got_m, dirs).max() < 1.0


def test_no_sphere_in_view_is_refused_with_what_to_give():
    flat = np.stack([_textured_background(s) for s in range(4)])
    with pytest.raises(ValueError, match="circle|outline|highlight"):
        mirror_sphere_directions(flat)


@pytest.mark.parametrize("background", [None, _dark_background, _textured_background],
                         ids=["card", "dark", "textured"])
@pytest.mark.parametrize("circle", [(CENTER[1], CENTER[0], R), (CENTER[0] + 8, CENTER[1], R),
                                    (CENTER[0], CENTER[1], 0.7 * R)], ids=["x-y-swapped", "8px-off", "too-small"])
def test_a_circle_given_that_the_highlights_cannot_be_on_is_refused(background, circle):
    dirs = nominal_light_directions()
    stack = _nominal_stack() if background is None else _sphere_on(background(), dirs)
    with pytest.raises(ValueError, match="not the outline|below the horizon|leaves out the highlights") as err:
        mirror_sphere_directions(stack, circle=circle)
    if "not the outline" in str(err.value):            # it names the outline the photographs show
        found = [float(v) for v in str(err.value).split("rim is at ")[1].split(" ")[0].split(",")]
        assert np.allclose(found, [*CENTER, R], atol=1.5), found


def test_a_circle_a_pixel_off_is_taken_and_a_highlight_outside_it_refused():
    dirs = nominal_light_directions()
    got, _, _ = mirror_sphere_directions(_nominal_stack(), circle=(CENTER[0] + 1, CENTER[1], R))
    assert _angle_deg(got, dirs).max() < 3.0
    far = np.array([[np.sin(np.radians(70)), 0.0, np.cos(np.radians(70))]] * 3)   # highlights near the rim
    stack = _mirror_stack(far, supersample=2)
    with pytest.raises(ValueError, match="leaves out the highlights|not the outline"):
        mirror_sphere_directions(stack, circle=(CENTER[0] - 20, CENTER[1], R - 20))


def test_lights_below_the_horizon_are_refused():
    from facette.calib.mirror_sphere import _check_horizon
    dirs = np.array([[0.0, 0.0, 1.0], [0.99, 0.0, -0.14]])
    with pytest.raises(ValueError, match="1 of 2 lights below the horizon.*photographs 2"):
        _check_horizon(Circle(10, 10, 5), dirs)
