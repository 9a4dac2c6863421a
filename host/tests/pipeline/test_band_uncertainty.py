"""pipeline._band_uncertainty: the normals' uncertainty over bands of rows is the whole image's, value
for value (its strided local fit and its curl read rows around each band)."""
import numpy as np
import pytest

from facette.pipeline._band_uncertainty import uncertainty_over_bands
from facette.recon import normal_uncertainty
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions


@pytest.mark.parametrize("max_values", [np.inf, 4000.0, 700.0])     # strides 1, 3 and 5 at 41 x 37, 12 lights
@pytest.mark.parametrize("rows", [5, 16])
def test_bands_give_the_whole_images_uncertainty(max_values, rows):
    sc = sphere_on_plane(37, 41)
    lights = thesis_light_directions()
    images = render(sc, lights, "satin", noise=0.01).astype(np.float32)
    rng = np.random.default_rng(1)
    normals = sc.normals + rng.normal(0, 0.03, sc.normals.shape)
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)
    normals[:3, :5] = 0                                  # pixels without a normal
    mask = sc.mask.copy()
    mask[20:24] = False                                  # a gap in the mask across the bands
    whole = normal_uncertainty(images, lights, normals, mask, saturation=0.99, max_values=max_values)
    bands = uncertainty_over_bands(lambda r0, r1: (images[:, r0:r1], lights), normals, mask, len(lights), rows,
                                   saturation=0.99, max_values=max_values)
    assert whole[mask].max() > 0
    np.testing.assert_array_equal(bands, whole)
