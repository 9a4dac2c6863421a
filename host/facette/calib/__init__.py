"""Rig calibration: profiles (load/save), and the calibration procedures."""
from facette.calib.profile import (Lights, Profile, ProfileError, load, nominal_light_directions,
                                   save)

__all__ = ["Lights", "Profile", "ProfileError", "load", "save", "nominal_light_directions"]
