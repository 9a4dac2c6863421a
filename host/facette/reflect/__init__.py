"""Reflectance samples (thesis eq 4.11) and the hemispherical equal-area sensor filter
(Beckers & Beckers 2012; thesis eq 4.12-4.14)."""
from ._samples import (ReflectanceSamples, reflectance_samples, samples_from_pixels, sample_angles, sample_grid,
                       local_frame_directions, MIN_COS)
from ._hemisphere import (beckers_partition, HemisphereSensor, FilteredReflectance,
                          hemisphere_filter, THETA0_DEG)

__all__ = ["ReflectanceSamples", "reflectance_samples", "samples_from_pixels", "sample_angles", "sample_grid", "local_frame_directions", "MIN_COS",
           "beckers_partition", "HemisphereSensor", "FilteredReflectance", "hemisphere_filter",
           "THETA0_DEG"]
