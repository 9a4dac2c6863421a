import numpy as np
import pytest

import facette.brdf as B
from facette.fit import cell_spread_directions, fit_hemisphere_cells

reflect = pytest.importorskip("facette.reflect")


def test_spread_directions_fall_in_their_own_cells():
    sensor = reflect.HemisphereSensor(3.0, channels=1)
    cells = np.arange(sensor.n_cells)
    spread = cell_spread_directions(sensor.edges, sensor.counts, cells, k=3)
    assert spread.shape == (sensor.n_cells, 9, 3)
    np.testing.assert_allclose(np.linalg.norm(spread, axis=-1), 1.0)
    inside = sensor.cell_of(spread.reshape(-1, 3)).reshape(spread.shape[:2])
    assert np.array_equal(inside, np.broadcast_to(cells[:, None], inside.shape))
    with pytest.raises(ValueError, match="cell indices"):
        cell_spread_directions(sensor.edges, sensor.counts, [sensor.n_cells])


def test_filtered_cells_fit_recovers_a_narrow_lobe():
    rng = np.random.default_rng(0)
    sensor = reflect.HemisphereSensor(3.0, channels=1)
    _, mid = sensor.centres()
    for ts in mid[np.searchsorted(mid, np.radians([25, 40, 55]))]:
        n = 60_000
        s = np.broadcast_to([np.sin(ts), 0.0, np.cos(ts)], (n, 3))
        z = rng.random(n)
        phi = 2 * np.pi * rng.random(n)
        o = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
        sensor.add(s, o, B.cook_torrance1982(s, o, 0.5, 0.05, 1.3)[:, None])
    filt = sensor.result()
    fwd = fit_hemisphere_cells(filt, model="cook_torrance", spread=4, select=False, n_starts=2)
    centres = fit_hemisphere_cells(filt, model="cook_torrance", spread=0, select=False, n_starts=2)
    assert fwd.success
    assert fwd.params["sigma"] == pytest.approx(0.05, rel=0.03)
    assert fwd.params["n_i"] == pytest.approx(1.3, rel=0.03)
    # the bias the forward model removes: the cell centres widen the lobe
    assert centres.params["sigma"] - 0.05 > 2 * abs(fwd.params["sigma"] - 0.05)
