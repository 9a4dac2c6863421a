"""`process` on a bare metal: the pixels no light reaches above the noise get their normals
interpolated from the measured ones (pipeline._filled), marked grey in mask.png and kept out of
the reflectance samples."""
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from facette.io.png import read_png
from facette.pipeline import process
from facette.pipeline._report import fmt
from facette.recon.synthetic import angular_error_deg

from mitsuba_scan import calibrated_scan, render


@pytest.fixture(scope="module")
def gold():
    """A Mitsuba sphere in polished gold (64 px, 32 spp): dark between its 12 highlights."""
    return render("sphere", "gold")


def test_a_bare_metal_is_filled_between_its_highlights(tmp_path, gold):
    scan = calibrated_scan(tmp_path / "scan", gold)
    res = process(scan, outputs=["normals", "mask", "samples", "report"], out_dir=tmp_path / "out", mask=gold["mask"])
    seen = res.ps.valid & gold["mask"]
    assert res.filled is not None and res.filled.sum() > seen.sum()          # most of it: no light
    assert np.array_equal(res.mask, seen | res.filled) and not (res.filled & seen).any()
    sel = binary_erosion(gold["mask"])
    err = angular_error_deg(res.normals, gold["normals"])[sel].mean()
    unfilled = angular_error_deg(res.ps.normal, gold["normals"])[sel].mean()  # the gap's zeros: 90°
    ls = process(scan, outputs=["normals"], method="woodham1980", mask=gold["mask"])
    err_ls = angular_error_deg(ls.normals, gold["normals"])[sel].mean()
    assert err < 0.5 * err_ls and err < 0.5 * unfilled, (err, err_ls, unfilled)
    assert any(n.startswith("normals interpolated at") for n in res.notes)
    png = read_png(tmp_path / "out" / "mask.png")
    assert np.array_equal(png == 128, res.filled) and np.array_equal(png == 255, seen)
    raw = np.load(tmp_path / "out" / "samples.npz")["raw_pixel"]
    assert not res.filled.ravel()[raw].any()                                 # samples: measured pixels only
    page = (tmp_path / "out" / "report.html").read_text()
    assert f"{fmt(int(res.filled.sum()))} pixels had no light above the noise" in page
    assert "interpolated pixels at half brightness" in page                 # the normal map says which


def test_a_noisy_bare_metal_solves_only_what_its_data_carries(tmp_path, gold):
    # noise at 1/10⁴ of the highlights: every dark value is noise, which a solver alone reads as light
    from facette.fit import is_metal
    peak = float(np.median(gold["images"][..., 1][:, gold["mask"]].max(0)))
    scan = calibrated_scan(tmp_path / "scan", gold, noise=peak / 1e4)
    res = process(scan, outputs=["normals"], mask=gold["mask"])
    ls = process(scan, outputs=["normals"], method="woodham1980", mask=gold["mask"])
    carried = np.count_nonzero(res.inputs.usable, axis=0) >= 3
    assert not (res.ps.valid & ~carried).any()                                 # no normal solved on noise
    assert is_metal(res.ps.info["rounds"][-1]["n_i"])                          # the lobe fitted on the highlights
    assert any("from every light's half vector" in n for n in res.notes)       # the fill kept out of the lobes
    sel = binary_erosion(gold["mask"])
    err, err_ls = (angular_error_deg(r.normals, gold["normals"])[sel].mean() for r in (res, ls))
    assert err < 0.5 * err_ls, (err, err_ls)


def test_read_by_bands_the_noisy_metal_solves_only_what_its_data_carries(tmp_path, gold):
    peak = float(np.median(gold["images"][..., 1][:, gold["mask"]].max(0)))
    scan = calibrated_scan(tmp_path / "scan", gold, noise=peak / 1e4)
    whole = process(scan, outputs=["normals"], mask=gold["mask"], method="rank_trimmed")
    banded = process(scan, outputs=["normals"], mask=gold["mask"], method="rank_trimmed", memory="1GB")
    carried = np.count_nonzero(whole.inputs.usable, axis=0) >= 3
    assert not (banded.ps.valid & ~carried).any() and np.array_equal(banded.ps.valid, whole.ps.valid)


def test_outputs_that_show_no_shape_skip_the_fill(tmp_path, gold):
    res = process(calibrated_scan(tmp_path / "scan", gold), outputs=["samples"], mask=gold["mask"])
    assert res.filled is None and np.array_equal(res.mask, res.ps.valid & gold["mask"])


def _sphere_samples(amplitude, exponent=None, seed=0):
    """12 rig lights on a sphere, green only, unit noise: a matte one (exponent None) or a sharp
    Blinn-Phong lobe; images (12, H, W, 3), usable, object mask."""
    from facette.bench._mitsuba_scenes import rig_light_directions
    from facette.capture.usable import usable_from_green
    yy, xx = (np.mgrid[:64, :64] - 31.5) / 30
    inside = xx ** 2 + yy ** 2 < 1
    n = np.dstack([xx, -yy, np.sqrt(np.clip(1 - xx ** 2 - yy ** 2, 0, 1))])
    rng = np.random.default_rng(seed)
    ims = []
    for s in rig_light_directions():
        h = (s + [0, 0, 1]) / np.linalg.norm(s + [0, 0, 1])
        shade = np.clip(n @ s, 0, None) if exponent is None else np.clip(n @ h, 0, None) ** exponent
        ims.append(np.repeat((amplitude * shade + rng.normal(size=shade.shape))[..., None], 3, -1))
    images = np.array(ims, np.float32)
    usable = np.array([usable_from_green(im[..., 1], np.ones(inside.shape, np.float32)) for im in images])
    return images, usable, inside


def test_a_dim_scan_is_refused_and_a_bare_metal_goes_on_with_a_note():
    from facette.errors import InsufficientData
    from facette.pipeline._quality import (MIN_PIXEL_FRACTION, MIN_SPARSE_FRACTION, SPARSE_CONTRAST, check_samples,
                                           lit_contrast, sample_counts)
    # a matte sphere 3 σ bright is dim; a lobe 3000 σ or 300 σ high is a metal's (at 300 σ its lit
    # samples' median is 10× the noise: the noise's crossings of the threshold weigh as much)
    for amplitude, exponent, passes in ((3.0, None, False), (3000.0, 100, True), (300.0, 100, True)):
        images, usable, inside = _sphere_samples(amplitude, exponent)
        c = sample_counts(images, usable, inside)
        assert MIN_SPARSE_FRACTION <= c["enough"] / c["object"] < MIN_PIXEL_FRACTION    # the rule's range
        contrast = lit_contrast(c)
        assert (contrast >= SPARSE_CONTRAST) == passes, contrast
        if passes:
            notes, summary = check_samples(images, usable, inside, "the given mask")
            assert "sends light back only near its highlights" in notes[0]
        else:
            with pytest.raises(InsufficientData, match="cannot carry a result") as exc:
                check_samples(images, usable, inside, "the given mask")
            assert "lengthen" in exc.value.hint


def test_read_by_bands_a_bare_metal_goes_on_and_is_filled_too(tmp_path, gold):
    # --memory judges the same counts summed over bands (their value samples joined)
    res = process(calibrated_scan(tmp_path / "scan", gold), outputs=["normals"], mask=gold["mask"], memory="1GB",
                  method="rank_trimmed")
    assert any("sends light back only near its highlights" in n for n in res.notes)
    assert res.filled is not None and res.filled.any() and not (res.filled & res.ps.valid).any()


@pytest.mark.parametrize("on_disk", [False, True])
def test_the_fill_a_piece_of_rows_at_a_time_is_the_whole_image_s(on_disk, monkeypatch):
    """`fill_in_rows` (pieces of 4 rows, grown past rows a gap crosses) solves the whole image's
    equations: solved tightly, the fill of `fill_normals` on the whole image; from a map on disk into one."""
    import facette.recon._fill as fill
    from facette._memory import disk_array
    monkeypatch.setattr(fill, "FILL_TOLERANCE", 1e-12)     # the multigrid's stopping point aside
    from facette.pipeline._filled import fill_in_rows
    from facette.recon import fill_normals
    h, w = 30, 26
    yy, xx = np.mgrid[0:h, 0:w] / 10.0
    n = np.dstack([np.sin(xx) * 0.4, np.cos(yy) * 0.3, np.ones((h, w))]).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    region = np.ones((h, w), bool)
    region[:, :2] = False
    measured = region.copy()
    measured[5:13, 8:12] = False            # crosses two pieces' boundaries
    measured[3, 20] = measured[4, 21] = False     # two pixels diagonal to each other: two pieces of gap
    measured[22:24, 3:25] = False
    measured[0, 10:13] = False                      # on the top edge
    n[~measured] = np.nan
    src = n
    if on_disk:
        src = disk_array(n.shape, np.float32)
        src[:] = n
    got, got_filled = fill_in_rows(src, measured, region, rows=4)
    want, want_filled = fill_normals(n, measured, region)
    assert isinstance(got, np.memmap) == on_disk
    assert np.array_equal(got_filled, want_filled) and want_filled.sum() == (region & ~measured).sum()
    assert np.array_equal(got[measured], want[measured])
    np.testing.assert_allclose(np.asarray(got)[want_filled], want[want_filled], atol=1e-6)
