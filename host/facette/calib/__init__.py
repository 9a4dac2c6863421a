"""Rig calibration: profiles (load/save), and the calibration procedures.

- profiles: `load`, `save`, `Profile`, `Lights`, `nominal_light_directions`;
- Spectralon: `spectralon_intensities`, `flat_field`, `led_current_gains`;
- mirror sphere: `mirror_sphere_directions`, `light_positions_from_rays`; matte sphere:
  `matte_sphere_directions` (cross-check);
- RTI interop: `read_lp`, `write_lp`;
- target specifications and their analytic renderings: `facette.calib.targets`; the
  checks of a capture: `facette.calib.checks`. The wizard that drives a rig
  (`facette calibrate`) is `facette.wizard`; the targets shown on the simulated rig
  are `facette.sim.targets`.
"""
from facette.calib.lp import lights_from_lp, read_lp, write_lp, write_profile_lp
from facette.calib.matte_sphere import matte_sphere_directions
from facette.calib.mirror_sphere import (directions_from_origin, light_positions_from_rays,
                                         mirror_sphere_directions)
from facette.calib.profile import (Lights, Profile, ProfileError, ResolutionError, load,
                                   nominal_light_directions, pitch_at_size, save)
from facette.calib.spectralon import (apply_flat_field, flat_field, led_current_gains,
                                      spectralon_intensities)

__all__ = ["Lights", "Profile", "ProfileError", "ResolutionError", "pitch_at_size", "load", "save",
           "nominal_light_directions",
           "spectralon_intensities", "flat_field", "led_current_gains", "mirror_sphere_directions",
           "light_positions_from_rays", "directions_from_origin", "matte_sphere_directions",
           "read_lp", "write_lp", "lights_from_lp", "write_profile_lp", "apply_flat_field"]
