"""`bench lights --shadow-rates`: the cast-shadow step's hidden lights scored against the geometry's."""
import numpy as np

from facette.bench._render_jit import cast_hidden
from facette.bench._shadow_rates import found_hidden, rates
from facette.bench.lights import dome_lights, relief_heights, render_band


def test_the_step_finds_the_reliefs_cast_shadows_and_its_margin_trades_hits_for_false_alarms():
    h, w = 80, 120
    lights = dome_lights(24)
    truth = cast_hidden(relief_heights(h, w), 0, h, lights)
    images, normals = render_band(0, h, w, min(h, w), lights, "satin", hidden=truth)
    mask = np.ones((h, w), bool)
    eager = rates(found_hidden(images, lights, mask, -3.0), truth, normals, lights, mask)
    strict = rates(found_hidden(images, lights, mask, 1.5), truth, normals, lights, mask)
    share, found, hit, false = eager
    assert share > 0.01 and eager[0] == strict[0]          # the relief hides lit samples, whatever the margin
    assert hit > 0.9 and hit > strict[2]                   # the lower margin finds more of them ...
    assert false > strict[3] and found > strict[1]         # ... and more that are lit
    assert strict[3] < 0.002


def test_rates_count_over_the_lit_samples_only():
    normals = np.tile([0.0, 0.0, 1.0], (1, 2, 1))
    lights = np.array([[0.0, 0.6, 0.8], [0.0, -0.6, -0.8]])        # the second behind the surface
    truth = np.array([[[True, False]], [[True, True]]])
    found = np.array([[[True, True]], [[True, True]]])
    share, found_share, hit, false = rates(found, truth, normals, lights, np.ones((1, 2), bool))
    assert (share, found_share, hit, false) == (0.5, 1.0, 1.0, 0.5)
