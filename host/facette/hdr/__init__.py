"""facette.hdr: from bracketed RAW frames to linear HDR radiance with a known variance.

- `merge`, `merge_inverse_variance`, `merge_debevec1997`: merge arrays (thesis eq 2.14).
- `estimate_sensor_ptc`: gain, read noise, dark current, saturation from dark and flat
  frames (photon transfer curve) for the calibration profile's `sensor` section.
- `plan_adaptive`, `bracket_fixed`: which exposures to take.
"""
from facette.hdr._bracket import (BRACKETS, THESIS_BRACKET_S, THESIS_BRACKET_US, TIMING_MODES, BracketPlan,
                                  bracket_fixed, frame_overhead_s,
                                  plan_adaptive, predicted_snr)
from facette.hdr._merge import (MERGE_METHODS, HDRResult, as_sensor, merge, merge_debevec1997,
                                merge_inverse_variance, n_workers)
from facette.hdr._ptc import PTCResult, estimate_sensor_ptc, estimate_sensor_ptc_files, ptc_points

__all__ = ["HDRResult", "MERGE_METHODS", "merge", "merge_inverse_variance", "merge_debevec1997",
           "as_sensor", "n_workers", "PTCResult", "estimate_sensor_ptc",
           "estimate_sensor_ptc_files", "ptc_points", "BracketPlan", "BRACKETS", "THESIS_BRACKET_S", "THESIS_BRACKET_US", "TIMING_MODES", "bracket_fixed",
           "plan_adaptive", "predicted_snr", "frame_overhead_s"]
