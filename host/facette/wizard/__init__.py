"""facette.wizard: the calibration wizard (`facette calibrate`).

- `steps`: the step sequence (`Wizard`: noise, mirror, positions, matte, spectralon,
  gains) that builds the profile from the captures;
- `station`: the rig I/O (`RigStation`: place a target, scan, merge, write the LED
  gains and reboot);
- the checks of each capture are `facette.calib.checks` (no rig needed).
"""
from facette.calib.checks import Tolerances, WizardError, angle_deg, check_exposure
from facette.wizard.station import INSTRUCTIONS, RigStation
from facette.wizard.steps import BRACKETS_US, DARK_US, FLAT_US, STEPS, Wizard

__all__ = ["Wizard", "RigStation", "WizardError", "Tolerances", "STEPS", "BRACKETS_US", "DARK_US",
           "FLAT_US", "INSTRUCTIONS", "check_exposure", "angle_deg"]
