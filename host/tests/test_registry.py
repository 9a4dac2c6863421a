"""facette._registry.Registry: case-insensitive names, aliases, and the error that lists them."""
import pytest

from facette._registry import Registry
from facette.methods import PS_METHODS, photometric_stereo
from facette.recon import ps_woodham1980


def test_names_aliases_and_case():
    r = Registry("colour method")
    r.add("finlayson2015", 1, aliases=("cheung",))
    r.add("vandermonde", 2)
    assert list(r) == ["finlayson2015", "vandermonde"] and len(r) == 2
    assert r["Finlayson2015"] == 1 and r["CHEUNG"] == 1 and r.canonical("cheung") == "finlayson2015"
    assert "Vandermonde" in r and "nope" not in r and 3 not in r
    assert r.names() == ("finlayson2015", "vandermonde", "cheung")
    with pytest.raises(ValueError, match=r"unknown colour method 'nope'; choose one of "
                                         r"finlayson2015 \(alias cheung\), vandermonde"):
        r["nope"]
    with pytest.raises(ValueError, match="registered twice"):
        r.add("Cheung", 3)


def test_photometric_stereo_dispatch_goes_through_the_registry():
    assert PS_METHODS["least_squares"] is ps_woodham1980
    with pytest.raises(ValueError, match="hierarchical_tautzia2016 \\(alias hierarchical\\)"):
        photometric_stereo(None, None, method="nope")
