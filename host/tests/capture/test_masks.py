import warnings

import numpy as np

from facette.capture.masks import auto_masks, object_of


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


def test_compiled_median_and_usable_test_give_numpys_values():
    from facette.capture._pixels_jit import median_over_lights
    from facette.capture.usable import MIN_SNR, usable_from_green
    rng = np.random.default_rng(3)
    for m in (1, 2, 5, 12, 96):                  # odd and even counts of known values; a dome's 96
        ch = rng.normal(size=(m, 30, 20, 3)).astype(np.float32)[..., 1]     # strided, as in auto_masks
        ch[rng.random(ch.shape) < 0.3] = np.nan
        ch[:, 0, 0] = np.nan                                                 # unknown under every light
        ch[:, 1, 1] = 0.25                                                   # ties
        out = np.full(ch.shape[1:], -1.0, np.float32)
        median_over_lights(ch, out, slice(0, 12))
        median_over_lights(ch, out, slice(12, None), workers=3)              # rows shared by threads
        with warnings.catch_warnings():                  # "All-NaN slice"
            warnings.simplefilter("ignore", RuntimeWarning)
            np.testing.assert_array_equal(out, np.nanmedian(ch, axis=0))
    g = rng.normal(size=(40, 30)).astype(np.float32)
    v = (np.abs(rng.normal(size=g.shape)) * 0.05).astype(np.float32)
    g[::7, ::3], v[::5, ::2], g[1, ::4], v[2, ::3] = np.nan, np.inf, np.inf, np.nan
    with np.errstate(all="ignore"):
        ref = np.isfinite(g) & np.isfinite(v) & (g > 0) & (g * g >= MIN_SNR ** 2 * v)
    assert 0 < ref.sum() < ref.size
    np.testing.assert_array_equal(usable_from_green(g, v), ref)


def test_object_takes_its_dark_rim_and_leaves_the_table_and_its_specks():
    """A disc whose rim is dark (2.7x the table, as a sphere's limb under lights near the axis):
    Otsu's bright class misses the rim, `object_of` takes it back; a speck lying apart on the
    table stays out."""
    yy, xx = np.mgrid[:40, :60]
    r2 = (yy - 20) ** 2 + (xx - 30) ** 2
    disc, core = r2 < 15 ** 2, r2 < 11 ** 2
    albedo = np.where(core, 0.5, np.where(disc, 0.08, 0.03))[..., None] * np.ones((40, 60, 3))
    albedo[2:4, 2:4] = 0.08                      # a speck as bright as the rim, apart on the table
    img = _stack(albedo)
    lit, material = auto_masks(img)
    assert not (material & disc & ~core).any()  # the rim fell on the table's side
    obj = object_of(img, lit, material)
    np.testing.assert_array_equal(obj, disc)
    assert object_of(img, lit, lit).all()        # no table: every lit pixel


def test_masks_from_bands_of_rows_give_the_whole_images_masks():
    from facette.capture.masks import masks_from
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:97, :61]
    disc = (yy - 48) ** 2 + (xx - 30) ** 2 < 28 ** 2
    med = np.where(disc, rng.uniform(0.2, 0.6, disc.shape), rng.uniform(0.01, 0.03, disc.shape)).astype(np.float32)
    top = (med * rng.uniform(1.5, 3.0, med.shape)).astype(np.float32)
    top[:3, :5] = np.nan                   # saturated under some light
    med[10:12] = np.nan                    # unknown under every light
    med[20, :7] = 0.0
    top[90:] = 0.0                         # unlit rows
    lit_w, mat_w = masks_from(top, med, rows=top.shape[0])     # one band: the whole images' formula
    assert mat_w.any() and (lit_w & ~mat_w).any()       # a split was made: the bins matter
    for rows in (1, 7, 512):
        lit, material = masks_from(top, med, rows=rows)
        np.testing.assert_array_equal(lit, lit_w)
        np.testing.assert_array_equal(material, mat_w)
