"""The physically grounded measures tried for the uncertainty band (bench._uncertainty_physics): the bound from
the lights in front of a facet is Lambert's (lights along the normal do not pin it; a facet turned from most of
them is pinned less), the cast-shadow share and the distance to it find a hidden light, light from behind shows,
the normal field's variation finds a crease, and the calibration sensitivity predicts how far errors of the
lights' intensities and directions move the normal."""
import numpy as np

from facette.bench._uncertainty_physics import (PHYSICS_CANDIDATES, calibration_sensitivity, front_crb,
                                               normal_variation, physics_measures)
from facette.recon import _uncertainty as unc
from facette.recon.synthetic import thesis_light_directions


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_front_bound_is_lamberts():
    lights = thesis_light_directions()                        # the rig's 12 on two rings, 15 and 30 deg from the axis
    tilts = np.radians([0, 60, 85])
    bound = front_crb(np.stack([np.sin(tilts), np.zeros(3), np.cos(tilts)], axis=1), lights)
    # facing the camera: I = diag(S / 2, S / 2), S = sum of sin^2 of each light's angle to the normal
    s = np.sum(1 - lights[:, 2] ** 2)
    assert np.isclose(bound[0], np.sqrt(4 / s))
    assert bound[1] < bound[0] and bound[2] > bound[1]      # lights across the normal pin it; fewer in front at 85
    # one light in front of the facet leaves a tangent direction free
    assert front_crb(_unit([[0.0, 0.0, 1.0]]), _unit([[0.0, 0.3, 1.0], [0.0, 0.0, -1.0]]))[0] >= 1e5


def _field(size=12):
    """A flat field facing the camera, a Lambertian pixel's values under the rig's lights, every pixel a normal."""
    lights = thesis_light_directions()
    normals = np.zeros((size, size, 3))
    normals[..., 2] = 1.0
    e = np.repeat(np.maximum(lights @ [0.0, 0.0, 1.0], 0)[None], size * size, axis=0) * 0.7
    return lights, normals, e


def test_a_hidden_light_is_a_cast_shadow_and_its_neighbours_are_near_it():
    lights, normals, e = _field()
    sel = np.ones(normals.shape[:2], bool)
    hidden = 5 * 12 + 5                                       # pixel (5, 5): its four lights on one side hidden
    e[hidden, np.argsort(lights[:, 0])[-4:]] = 0.0
    m = physics_measures(e, np.ones(e.shape, bool), normals.reshape(-1, 3), lights, sel, normals)
    assert tuple(m) == PHYSICS_CANDIDATES
    share = m["cast-shadow share"]
    assert share[hidden] >= 4 / 12 and np.all(np.delete(share, hidden) == 0)
    near = m["shadow distance"].reshape(12, 12)
    assert near[5, 5] == 1 and near[5, 6] == 0.5 and near[5, 6] > near[5, 9] > near[0, 11] > 0
    assert np.all(np.isfinite(np.stack(list(m.values()))))


def test_light_from_behind_the_facet_shows():
    lights = np.concatenate([thesis_light_directions(), _unit([[0.9, 0.0, 0.1]])])
    n = _unit([[-0.6, 0.0, 0.8], [-0.6, 0.0, 0.8]])           # the last light is behind these facets
    e = np.maximum(n @ lights.T, 0) * 0.7
    e[1, -1] = 0.3                                            # ... but the second one receives light from it
    normals = np.zeros((1, 2, 3))
    normals[0] = n
    m = physics_measures(e, np.ones(e.shape, bool), n, lights, np.ones((1, 2), bool), normals)
    assert m["backlit share"][0] == 0 and np.isclose(m["backlit share"][1], 0.3 / e[1].sum())


def test_normal_variation_finds_a_crease_at_two_scales():
    normals = np.zeros((16, 16, 3))
    normals[:, :8] = _unit([-0.5, 0.0, 1.0])                  # a V-shaped crease down the middle column
    normals[:, 8:] = _unit([0.5, 0.0, 1.0])
    has = np.ones((16, 16), bool)
    fine, coarse = normal_variation(normals, has, 1), normal_variation(normals, has, 3)
    assert fine[8, 7] > 0.1 and fine[8, 2] < 1e-3 and coarse[8, 4] > 10 * max(fine[8, 4], 1e-6)
    assert np.all(normal_variation(normals, np.zeros((16, 16), bool), 1) == 0)


def test_calibration_sensitivity_predicts_how_far_a_light_error_moves_the_normal():
    rng = np.random.default_rng(0)
    lights = thesis_light_directions()
    n = _unit([[0.3, -0.2, 0.93]])
    e = np.maximum(n @ lights.T, 0) * 0.8
    ok = np.ones(e.shape, bool)
    intensity, direction = calibration_sensitivity(e, ok, n, lights)
    moved = {"intensity": [], "direction": []}
    carry = unc._carrying(e, ok)[0] > 0
    for _ in range(400):                                      # solve again with each light's calibration off by 1 %
        scale = 1 + 0.01 * rng.normal(size=len(lights))
        tilt = _unit(lights + 0.01 * rng.normal(size=lights.shape))
        for name, l, v in (("intensity", lights, e[0] * scale), ("direction", tilt, e[0])):
            b = _unit(np.linalg.lstsq(l[carry], v[carry], rcond=None)[0])
            moved[name].append(np.arccos(np.clip(b @ n[0], -1, 1)))
    assert 0.8 < np.sqrt(np.mean(np.square(moved["intensity"]))) / (0.01 * intensity[0]) < 1.25
    # a direction error of 0.01 rad per axis is sqrt(2) x 0.01 across the light
    assert 0.7 < np.sqrt(np.mean(np.square(moved["direction"]))) / (0.01 * np.sqrt(2) * direction[0]) < 1.4
