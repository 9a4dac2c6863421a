"""`facette bench bands`'s capture: a field of cups whose walls hide lights from their floors."""
import numpy as np

from facette.bench.bands import PERIOD, crater_field
from facette.recon.synthetic import thesis_light_directions


def test_the_cups_hide_the_tilted_lights_from_their_floors_and_nothing_from_the_flat():
    lights = thesis_light_directions()
    d = crater_field(PERIOD * 2, PERIOD, lights)
    assert d["images"].shape == (len(lights), PERIOD, 2 * PERIOD) and d["hidden"].shape == d["images"].shape
    np.testing.assert_allclose(np.linalg.norm(d["normals"], axis=-1), 1, atol=1e-5)
    centre, corner = (PERIOD // 2, PERIOD // 2), (0, 0)       # a cup's floor; the flat between cups
    assert d["normals"][centre][2] > 0.999 and d["normals"][corner][2] > 0.999
    tilted = np.degrees(np.arccos(lights[:, 2])) > 20
    assert d["hidden"][tilted][:, centre[0], centre[1]].all()      # 30° off the axis: under the walls
    assert not d["hidden"][:, corner[0], corner[1]].any()
    # a hidden value keeps a share of its direct light: dimmer than lit, not black
    lit_value = 0.7 * (lights @ d["normals"][centre])
    np.testing.assert_allclose(d["images"][tilted, centre[0], centre[1]], 0.3 * lit_value[tilted], rtol=1e-5)
