import numpy as np

from facette.pipeline._inputs import auto_masks


def _stack(albedo, m=12, seed=0):
    rng = np.random.default_rng(seed)
    shading = rng.uniform(0.5, 1.0, (m, 1, 1, 1))
    img = (albedo[None] * shading).astype(np.float32)
    img[0, 5, 5, :] = 50.0          # a specular spike must not move the split
    return img


def test_dark_background_is_left_out():
    yy, xx = np.mgrid[:40, :60]
    disc = (yy - 20) ** 2 + (xx - 30) ** 2 < 15 ** 2
    albedo = np.where(disc[..., None], 0.5, 0.04) * np.ones((40, 60, 3))
    lit, material = auto_masks(_stack(albedo))
    assert lit.all()                                  # the dark table is lit: normals there
    np.testing.assert_array_equal(material, disc)     # but samples come from the object only


def test_object_filling_the_frame_keeps_every_lit_pixel():
    albedo = np.random.default_rng(1).uniform(0.3, 0.6, (30, 30, 3))  # texture, no background
    lit, material = auto_masks(_stack(albedo))
    assert lit.all() and material.all()


def test_unknown_pixels_and_black_frames():
    albedo = np.full((20, 20, 3), 0.5)
    img = _stack(albedo)
    img[:, :, :2] = np.nan           # two columns unknown under every light
    for mask in auto_masks(img):
        assert not mask[:, :2].any() and mask[:, 2:].all()
    assert not any(m.any() for m in auto_masks(np.zeros((4, 8, 8, 3), np.float32)))
