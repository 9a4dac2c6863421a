import numpy as np

from facette.pipeline._inputs import _auto_mask


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
    np.testing.assert_array_equal(_auto_mask(_stack(albedo)), disc)


def test_object_filling_the_frame_keeps_every_lit_pixel():
    albedo = np.random.default_rng(1).uniform(0.3, 0.6, (30, 30, 3))  # texture, no background
    assert _auto_mask(_stack(albedo)).all()


def test_unknown_pixels_and_black_frames():
    albedo = np.full((20, 20, 3), 0.5)
    img = _stack(albedo)
    img[:, :, :2] = np.nan           # two columns unknown under every light
    mask = _auto_mask(img)
    assert not mask[:, :2].any() and mask[:, 2:].all()
    assert not _auto_mask(np.zeros((4, 8, 8, 3), np.float32)).any()
