"""`facette bench lights`: the default's cost per megapixel-light, and over bands (--banded)."""
import numpy as np

from facette.bench import lights


def test_banded_runs_the_default_over_bands_of_a_relief_rendered_band_by_band(capsys):
    model_c, bands_c, wall, err, parts = lights.banded(64, 40, 12, "satin", rows=16)
    assert model_c < 0.5 and bands_c > 0 and wall > 0       # below coarse_pixels: no model, one band
    assert err < 2.0, err
    assert lights.main(["--banded", "48x32", "--lights", "12"]) == 0
    out = capsys.readouterr().out
    assert "48x32" in out and "24 MP x 60 lights" in out


def test_a_rendered_row_is_the_same_whichever_band_holds_it():
    dirs = lights.dome_lights(12)
    whole, n_whole = lights.render_band(0, 12, 40, 30, dirs, "satin")
    part, n_part = lights.render_band(5, 12, 40, 30, dirs, "satin")
    assert whole.shape == (12, 12, 40, 3) and whole.dtype == np.float32
    np.testing.assert_array_equal(part, whole[:, 5:])
    np.testing.assert_array_equal(n_part, n_whole[5:])
    again, _ = lights.render_band(0, 12, 40, 30, dirs, "satin", noise=0.0)
    assert 0.001 < np.std(whole[again > 0.05] / again[again > 0.05] - 1) < 0.02     # the 1 % noise, per value


def test_a_band_holds_its_photographs_within_the_budget():
    rows = lights.band_rows(6000, 60)
    assert rows * 6000 * 60 * 3 * 4 <= lights.BAND_BYTES < (rows + 1) * 6000 * 60 * 3 * 4
    assert lights.band_rows(10 ** 6, 100, budget=1000) == 1


def test_banded_reads_and_solves_bands_of_at_most_its_rows_when_a_model_is_fitted(monkeypatch):
    seen, render_band = [], lights.render_band

    def spy(r0, r1, *args, **kw):
        seen.append(r1 - r0)
        return render_band(r0, r1, *args, **kw)
    monkeypatch.setattr(lights, "render_band", spy)
    # coarse_pixels 1000 of 4800 pixels: the model is fitted across the bands (binned 3 x 3)
    model_c, bands_c, wall, err, parts = lights.banded(80, 60, 12, "satin", rows=8, coarse_pixels=1000)
    assert max(seen) <= 8
    assert sum(seen) == 2 * 60          # every row read twice: the model's pass, then the solve's bands
    assert err < 2.0, err
