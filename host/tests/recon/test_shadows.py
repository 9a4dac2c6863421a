"""hidden_lights: the lights a surface hides from itself, by a horizon test on its heights."""
import numpy as np
import pytest

from facette.recon import hidden_lights, horizon_excess

from shadow_scenes import groove_scene


@pytest.mark.parametrize("kind", ["groove", "bowl"])
def test_the_hidden_lights_of_true_normals_are_the_rays_that_meet_the_surface(kind):
    d = groove_scene(kind)
    truth = d["hidden"]
    assert 0.02 < truth.mean() < 0.1            # the scene does hide lights
    found, factor = hidden_lights(d["normals"], d["mask"], d["light_dirs"], 2.0)
    assert factor == 1 and found.shape == truth.shape
    # the margin keeps the lights within 2 deg of the horizon out: none found that is not hidden,
    # most of the hidden ones found
    assert (found & ~truth).sum() <= 0.01 * truth.sum()
    assert (found & truth).sum() >= 0.7 * truth.sum()
    # with no margin, more of the hidden ones, at the price of a few that are not
    loose, _ = hidden_lights(d["normals"], d["mask"], d["light_dirs"], 0.0)
    assert (loose & truth).sum() > (found & truth).sum()


def test_a_convex_dome_hides_nothing_and_a_light_on_the_axis_is_never_hidden():
    y, x = np.mgrid[:64, :64] - 31.5
    r2 = x * x + y * y
    z = np.sqrt(np.clip(40.0 ** 2 - r2, 1, None))
    n = np.dstack([x, -y, z]) / np.linalg.norm(np.dstack([x, -y, z]), axis=-1, keepdims=True)
    mask = r2 < 30 ** 2
    lights = np.array([[0.0, 0.0, 1.0], [0.7, 0.0, 0.714], [0.0, -0.6, 0.8]])
    found, _ = hidden_lights(n.astype(np.float32), mask, lights, 2.0)
    assert not found.any()
    groove = groove_scene("groove")
    excess = horizon_excess(np.zeros((8, 8), np.float32), np.ones((8, 8), bool), [[0, 0, 1.0]])
    assert np.all(excess == -90.0)
    assert not hidden_lights(groove["normals"], groove["mask"], [[0.0, 0.0, 1.0]], 2.0)[0].any()


def test_the_mask_edge_hides_nothing_beyond_it():
    # the groove's walls outside the mask are unknown: the floor sees every light
    d = groove_scene("groove")
    mask = np.zeros_like(d["mask"])
    mask[:, 40:57] = True                      # the floor of the groove only
    found, _ = hidden_lights(d["normals"], mask, d["light_dirs"], 2.0)
    assert not found[:, ~mask].any()
    inside_all, _ = hidden_lights(d["normals"], d["mask"], d["light_dirs"], 2.0)
    assert found.sum() < inside_all[:, mask].sum()


def test_bad_light_directions_are_refused():
    with pytest.raises(ValueError, match="distant directions"):
        horizon_excess(np.zeros((4, 4), np.float32), np.ones((4, 4), bool), np.zeros((4, 4, 2, 3)))
