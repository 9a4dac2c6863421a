"""facette.wizard.steps: the step sequence refuses what it cannot run."""
import numpy as np
import pytest

from facette.calib import Lights, Profile, nominal_light_directions
from facette.wizard import STEPS, Wizard


def test_wizard_refuses_unknown_steps_and_mismatched_base():
    class _St:
        n_leds = 12

    with pytest.raises(ValueError, match="unknown steps"):
        Wizard(_St(), steps=["mirror", "flatfield"])
    base = Profile(rig="x", lights=Lights(nominal_light_directions()[:6], np.ones((6, 3))))
    with pytest.raises(ValueError, match="6 lights, the rig 12"):
        Wizard(_St(), base=base)
    assert STEPS[0] == "noise" and STEPS[-1] == "gains"
