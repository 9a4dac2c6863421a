"""`facette bench lights`: the default's cost per megapixel-light, and over bands (--banded)."""
from facette.bench import lights


def test_banded_runs_the_default_over_bands_of_a_relief_rendered_band_by_band(capsys):
    model_c, bands_c, wall, err, parts = lights.banded(64, 40, 12, "satin", rows=16)
    assert model_c < 0.5 and bands_c > 0 and wall > 0       # below coarse_pixels: no model, one band
    assert err < 2.0, err
    assert lights.main(["--banded", "48x32", "--lights", "12"]) == 0
    out = capsys.readouterr().out
    assert "48x32" in out and "24 MP x 60 lights" in out
