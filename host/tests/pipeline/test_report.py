"""report.html shows the fit: data and model per incidence, residuals, parameters with their
uncertainties, truth as histograms, rounded numbers, a summary first."""
import html
import re

import numpy as np

from facette.pipeline._report import fit_predictions, fmt, fmt_pm


def _visible_text(page):
    page = re.sub(r"<script.*?</script>", "", page, flags=re.S)
    return html.unescape(re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", page))


def test_numbers_are_rounded_for_people():
    assert fmt(0.6598307291666666) == "0.660"
    assert fmt(3072) == "3\u2009072" and fmt(None) == "–" and fmt(float("nan")) == "–"
    assert fmt(12.3456) == "12.3" and fmt(4567.8) == "4\u2009568" and fmt(2.5e-6) == "2.50e-06"
    # the CI run that printed "0.000206": below 1e-3 a float takes an exponent
    assert fmt(0.000206) == "2.06e-04" and fmt(0.00123) == "0.00123"
    assert fmt_pm(3.2e-5, 2.1e-6) == "3.20e-05 ± 2.1e-06"
    assert fmt_pm(0.04421811753969342, 0.0011010062404600064) == "0.0442 ± 0.0011"
    assert fmt_pm(1.1366120278569514, 0.02330286482447957) == "1.137 ± 0.023"


def test_report_shows_the_fit_its_uncertainties_and_the_truth(simulated_result):
    res, path = simulated_result
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
    # a verdict over the models tried, first: a Cook–Torrance satin fits within the threshold
    assert res.brdf.verdict == "fits" and res.brdf.models_tried[0]["model"] == res.brdf.model
    assert f"Verdict: fits</b> (models tried: {res.brdf.model}" in text
    assert text.index("Verdict:") < text.index("Fitted to")
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
    # self-contained: nothing fetched from anywhere
    assert "http://" not in page and "https://" not in page and "<script src" not in page
    # no number printed with more digits than anyone reads
    assert not re.findall(r"\d\.\d{6,}", text)
