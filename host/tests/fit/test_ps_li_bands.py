"""li_alternating over row bands (facette.fit._ps_li_bands): the model fitted once over the
bands, each band solved with it fixed, gives the normals of the image solved whole."""
import numpy as np
import pytest

from facette.fit import li_model, ps_li_alternating
from facette.fit._ps_li_bands import lowered, sample_rows
from facette.recon.synthetic import Scene, render, thesis_light_directions


def _relief(h, w, lights=None, seed=1):
    """A rendered glossy relief (bumps on a plane), every pixel masked."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    z = 3.0 * np.sin(xx / 5.0) * np.cos(yy / 7.0)
    gy, gx = np.gradient(z)
    n = np.dstack([-gx, -gy, np.ones_like(z)])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    scene = Scene(n.astype(np.float32), z, np.ones((h, w), bool), np.zeros((h, w), bool),
                  ((h - 1) / 2, (w - 1) / 2), 1.0)
    lights = thesis_light_directions() if lights is None else lights
    images = render(scene, lights, "satin", noise=0.01, rng=np.random.default_rng(seed), cast_shadows=False)
    return images, lights, scene


def _bands(images, lights, mask, rows, coarse_pixels):
    """The image solved band by band with the model fitted over the same bands."""
    m, h, w = images.shape[:3]
    model = li_model(lambda r0, r1: (images[:, r0:r1], lights, mask[r0:r1]), (h, w), int(mask.sum()), rows,
                     coarse_pixels=coarse_pixels)
    normal = np.zeros((h, w, 3), np.float32)
    albedo = np.zeros((h, w, images.shape[3]), np.float32)
    for r0 in range(0, h, rows):
        part = ps_li_alternating(images[:, r0:r0 + rows], lights, mask=mask[r0:r0 + rows], model=model, row0=r0)
        normal[r0:r0 + rows], albedo[r0:r0 + rows] = part.normal, part.albedo
    return model, normal, albedo


@pytest.mark.parametrize("rows", [13])
def test_bands_give_the_normals_of_the_whole_image(rows):
    images, lights, scene = _relief(60, 48)
    whole = ps_li_alternating(images, lights, mask=scene.mask, coarse_pixels=800)
    assert whole.info["coarse"]["factor"] == 2
    model, normal, albedo = _bands(images, lights, scene.mask, rows, 800)
    assert model.factor == 2 and model.coarse_info["materials"][0]["brdf_step"]
    np.testing.assert_array_equal(normal, whole.normal)
    np.testing.assert_array_equal(albedo, whole.albedo)
    err = np.degrees(np.arccos(np.clip(np.sum(normal * scene.normals, -1), -1, 1))).mean()
    assert err < 3.0, err


def test_no_model_below_the_coarse_threshold():
    images, lights, scene = _relief(20, 20)
    assert li_model(lambda r0, r1: (images[:, r0:r1], lights, scene.mask[r0:r1]), (20, 20), 400, 8,
                    coarse_pixels=1000) is None


def test_the_sample_rows_are_spread_down_the_image_and_bounded():
    rows = sample_rows(1000, 500, pixels=50_000)
    assert rows.size == 100 and rows[0] == 5 and rows[-1] == 995
    np.testing.assert_array_equal(sample_rows(10, 10, pixels=10_000), np.arange(10))


def test_the_dark_level_is_taken_out_and_floored_keeping_saturated_values():
    im = np.float32([0.05, 0.5, 1.0]).reshape(1, 1, 3, 1)
    out = lowered(im, np.float32([[0.1]]), saturation=1.0)
    np.testing.assert_allclose(out.ravel(), [0.0, 0.4, 1.0])
    assert lowered(im, None, 1.0) is im


def test_rows_that_hold_the_image_read_it_once_and_bin_it_as_bands_do():
    # 61 rows binned 2 x 2: read whole (its last block padded) or in bands of 60 + 1 rows, the same model
    images, lights, scene = _relief(61, 48)
    reads = []

    def read(r0, r1):
        reads.append((r0, r1))
        return images[:, r0:r1], lights, scene.mask[r0:r1]
    whole = li_model(read, (61, 48), int(scene.mask.sum()), 61, coarse_pixels=800)
    assert whole.factor == 2 and reads == [(0, 61)]
    reads.clear()
    bands = li_model(read, (61, 48), int(scene.mask.sum()), 60, coarse_pixels=800)
    assert reads == [(0, 60), (60, 61)]
    np.testing.assert_array_equal(whole.coarse_normal, bands.coarse_normal)
    assert whole.coarse_info["materials"][0]["sigma"] == bands.coarse_info["materials"][0]["sigma"]
