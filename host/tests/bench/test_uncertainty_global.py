"""The non-local measures tried for the uncertainty band (bench._uncertainty_global): a surface's own normals agree
with their least-squares heights and a twist no surface has does not, a pit sees less sky than the plane around it
and a wall hides the lights behind it."""
import numpy as np

from facette.bench._uncertainty_global import GLOBAL_CANDIDATES, global_measures, integrability_angle
from facette.recon.synthetic import thesis_light_directions


def _normals_of(z):
    """(H, W, 3) unit normals of heights z (pixels; row 0 the top, y up)."""
    dzdr, dzdc = np.gradient(z)
    n = np.stack([-dzdc, dzdr, np.ones_like(z)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _bump(size=40):
    r, c = np.mgrid[0:size, 0:size] - size / 2
    return 6.0 * np.exp(-(r ** 2 + c ** 2) / (2 * 8.0 ** 2))


def test_a_surfaces_normals_agree_with_their_heights_and_a_twist_does_not():
    n = _normals_of(_bump())
    mask = np.ones(n.shape[:2], bool)
    ang, z = integrability_angle(n, mask)
    assert np.degrees(np.percentile(ang, 99)) < 1.0
    assert np.corrcoef(z.ravel(), _bump().ravel())[0, 1] > 0.999
    twisted = n.copy()                                  # rotate the normals about the axis in one patch: a curl
    patch = (slice(8, 16), slice(24, 32))
    p = -twisted[patch][..., 0] / twisted[patch][..., 2]
    q = -twisted[patch][..., 1] / twisted[patch][..., 2]
    t = np.stack([-(q + 0.3), p + 0.3, np.ones_like(p)], axis=-1)
    twisted[patch] = t / np.linalg.norm(t, axis=-1, keepdims=True)
    ang2, _ = integrability_angle(twisted, mask)
    inside = np.degrees(np.median(ang2[patch]))
    assert inside > 5.0 and inside > 5 * np.degrees(np.median(ang2[30:, :10]))
    coarse, _ = integrability_angle(twisted, mask, block=2)
    assert coarse.shape == mask.shape and np.degrees(np.median(coarse[patch])) > 3.0


def test_a_pit_sees_less_sky_and_a_wall_hides_the_lights_behind_it():
    size = 48
    r, c = np.mgrid[0:size, 0:size]
    z = np.zeros((size, size))
    pit = (r - 24) ** 2 + (c - 24) ** 2 < 8 ** 2
    z[pit] = -10.0                                      # a well 10 px deep, 16 across
    lights = thesis_light_directions()
    n = _normals_of(z)
    mask = np.ones((size, size), bool)
    m = global_measures(n, mask, lights)
    assert tuple(m) == GLOBAL_CANDIDATES
    sky = m["sky view"].reshape(size, size)
    hidden = m["hidden lights"].reshape(size, size)
    assert sky[24, 24] > 0.2 and sky[2, 2] < 0.05       # the well's floor sees the wall; the far plane sees the sky
    assert hidden[24, 18] >= 0.25 and hidden[2, 2] == 0  # the floor by the wall: the lights beyond it (3 of 12) hidden
    assert np.all(np.isfinite(np.stack(list(m.values()))))
