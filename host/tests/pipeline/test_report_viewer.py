"""report.html: the fit shown against the data, and the relighting viewer in a real headless
Chromium (Debian's chromium + chromium-driver, WebGL on SwiftShader), compared with the
Python reference render of the same model."""
import html
import json
import re

import numpy as np
import pytest

import facette.brdf as brdf
from facette.bench._browser import chromium, console_errors, viewer_pixels, wait_for_viewer
from facette.bench._sim_scan import write_scan
from facette.pipeline import process
from facette.pipeline._relight import (ViewerModel, kd_map_from_albedo, light_from_angles, relight, to_srgb8,
                                       viewer_model)
from facette.pipeline._report import fit_predictions, fmt, fmt_pm
from facette.pipeline._viewer import viewer_data
from facette.recon.synthetic import render, sphere_on_plane, thesis_light_directions

# Browser against reference, 8-bit sRGB levels over the object's pixels. Sources of the
# difference: float16 normals, 8-bit K_d, the volume table's trilinear interpolation, float32
# shading, the GPU's rounding. Measured: mean 0.05-0.3, 99th percentile 1, max 6.
TOL_MEAN, TOL_P99, TOL_MAX = 0.6, 2, 12
LIGHTS = [(135.0, 45.0), (0.0, 20.0), (270.0, 70.0)]


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    """`process` on a small simulated scan (a satin sphere on a plane, with truth), every output."""
    root = tmp_path_factory.mktemp("viewer")
    sc = sphere_on_plane(48, 64)
    imgs = render(sc, thesis_light_directions(), "satin", noise=0.002)
    write_scan(root / "scan", sc, imgs)
    res = process(root / "scan", outputs=["normals", "albedo", "height", "samples", "brdf", "report"],
                  out_dir=root / "out")
    return res, root / "out" / "report.html"


def _visible_text(page):
    page = re.sub(r"<script.*?</script>", "", page, flags=re.S)
    return html.unescape(re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", page))


def test_numbers_are_rounded_for_people():
    assert fmt(0.6598307291666666) == "0.660"
    assert fmt(3072) == "3\u2009072" and fmt(None) == "–" and fmt(float("nan")) == "–"
    assert fmt(12.3456) == "12.3" and fmt(4567.8) == "4\u2009568" and fmt(2.5e-6) == "2.50e-06"
    assert fmt_pm(0.04421811753969342, 0.0011010062404600064) == "0.0442 ± 0.0011"
    assert fmt_pm(1.1366120278569514, 0.02330286482447957) == "1.137 ± 0.023"


def test_report_shows_the_fit_its_uncertainties_and_the_truth(result):
    res, path = result
    page = path.read_text()
    text = _visible_text(page)
    assert res.brdf is not None and res.brdf.success
    # summary first: what was measured, how good, what was left out
    assert text.index("Summary") < text.index("Relighting") < text.index("BRDF fit")
    for words in ("Measured:", "How good:", "Left out, and why:", "12 lights on 64 × 48 pixels"):
        assert words in text
    # each parameter with its uncertainty, as the fit computed it
    unc = res.brdf.uncertainties
    assert unc and fmt_pm(res.brdf.params["sigma"], unc["sigma"]) in text
    assert fmt_pm(res.brdf.params["kd"][1], unc["kd"][1]) in text
    assert "covariance = s² (JᵀJ)⁻¹" in text
    # data and model per incidence, residuals per cell, truth as histograms
    for caption in ("Filtered reflectance and fitted model per incidence", "Residual per sensor cell",
                    "Error against the scan's truth (histograms", "normal angular error (deg)"):
        assert caption in text
    assert "<th>truth</th>" in text and "cook_torrance" in text
    # the model drawn against the data is the one fitted: same RMS over the same cells
    f = res.filtered
    sel = f.count >= 1
    rms = np.sqrt(np.mean((fit_predictions(f, res.brdf)[sel] - f.mean[sel]) ** 2))
    np.testing.assert_allclose(rms, res.brdf.error["rms"], rtol=1e-9)
    # no number printed with more digits than anyone reads
    assert not re.findall(r"\d\.\d{6,}", text)


def test_relight_is_the_li_model_times_the_cosine():
    rng = np.random.default_rng(1)
    n = rng.normal(size=(6, 5, 3))
    n[..., 2] = np.abs(n[..., 2]) + 0.3
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    kd = np.array([0.7, 0.4, 0.2])
    m = ViewerModel("li", kd, 0.2, 1.45, volume="approx")
    light = light_from_angles(30.0, 50.0)
    got = relight(n, np.broadcast_to(kd, n.shape), np.ones(n.shape[:2], bool), m, light)
    from facette.reflect import local_frame_directions
    s, o = local_frame_directions(n.reshape(-1, 3), light, [0.0, 0.0, 1.0])
    f = brdf.brdf_li(s.astype(float), o.astype(float), kd, 0.2, 1.45, volume="approx")
    want = np.where(s[:, 2:3] > 0, f * s[:, 2:3], 0).reshape(got.shape)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-9)


def test_viewer_refuses_what_it_cannot_draw():
    with pytest.raises(ValueError, match="fit failed"):
        viewer_model({"model": "li", "success": False, "message": "no data", "parameters": {}})
    with pytest.raises(ValueError, match="draws the"):
        viewer_model({"model": "oren_nayar", "success": True, "parameters": {"kd": [0.5], "sigma": 0.2}})
    with pytest.raises(ValueError, match="isotropic"):
        viewer_model({"model": "li", "success": True, "parameters": {"kd": [0.5], "sigma": [0.1, 0.2], "n_i": 1.5}})
    kd = kd_map_from_albedo(np.full((4, 4, 3), 2.0), np.ones((4, 4), bool), [0.6, 0.5, 0.4])
    np.testing.assert_allclose(kd[0, 0], [0.6, 0.5, 0.4])


def test_viewer_in_chromium_matches_the_reference_render(result, tmp_path):
    res, path = result
    # the viewer's arrays, made as the report made them, for the Python reference
    _, arr = viewer_data(res.normals, res.mask, res.brdf, albedo=res.albedo, height=res.height,
                         pitch_mm=res.inputs.pixel_pitch_mm, material_mask=res.inputs.sample_mask())
    mask = arr["mask"]
    with chromium() as driver:
        wait_for_viewer(driver, path)
        assert console_errors(driver) == []
        shots = {}
        for az, el in LIGHTS:
            got = viewer_pixels(driver, az, el)
            want = to_srgb8(relight(arr["normals"], arr["kd_map"], mask, arr["model"], light_from_angles(az, el)),
                            mask, arr["exposure"])
            diff = np.abs(got.astype(int) - want.astype(int))[mask]
            assert diff.mean() <= TOL_MEAN and np.percentile(diff, 99) <= TOL_P99 and diff.max() <= TOL_MAX, \
                (az, el, diff.mean(), np.percentile(diff, 99), diff.max())
            assert np.array_equal(got[~mask], want[~mask])
            shots[(az, el)] = got
        # moving the light changes the picture
        a, b = shots[LIGHTS[0]], shots[LIGHTS[1]]
        assert np.abs(a.astype(int) - b.astype(int))[mask].mean() > 5
        # and so does dragging on it, as a user does
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.by import By
        canvas = driver.find_element(By.ID, "facette-relight")
        before = viewer_pixels(driver, *LIGHTS[0])
        ActionChains(driver).move_to_element_with_offset(canvas, -canvas.size["width"] // 3, 0) \
            .click_and_hold().move_by_offset(5, 5).release().perform()
        readout = driver.find_element(By.ID, "facette-light-readout").text
        after = np.frombuffer(__import__("base64").b64decode(
            driver.execute_script("return window.facetteViewer.pixels()")), np.uint8).reshape(before.shape[:2] + (4,))
        assert "azimuth 1" in readout and "azimuth 135°" not in readout   # towards −x: about 170-190°
        assert np.abs(after[..., :3].astype(int) - before.astype(int))[mask].mean() > 2
        assert console_errors(driver) == []
