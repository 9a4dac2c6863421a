"""The relighting files' set-up after the maps (pipeline._relight_later): their exposure is found
when the ptm / rti stage first asks, once, and not when `process` starts the stages after
photometric stereo; then each stage fits its own files, on its own thread."""
import threading
from types import SimpleNamespace

import numpy as np

import facette.pipeline._relight_later as later


def _patched(monkeypatch):
    """The calls `relight_after_maps` makes, recorded: (exposures found, whole_bands' (outputs, exposure, thread))."""
    exposures, fits = [], []

    def exposure_of(inp, encoding, gains, images, mask):
        exposures.append(threading.get_ident())
        return "exposure"

    def whole_bands(relight, res, inp, images, light_dirs, o, outputs, exposure=None):
        fits.append((tuple(outputs), exposure, threading.get_ident()))
        res.rti_exposure = exposure
        return SimpleNamespace(fitted=lambda: f"fits of {'+'.join(outputs)}")

    monkeypatch.setattr(later, "exposure_of", exposure_of)
    monkeypatch.setattr(later, "whole_bands", whole_bands)
    return exposures, fits


def test_the_set_up_waits_for_the_first_stage_that_asks_and_each_stage_fits_its_own_files(monkeypatch):
    exposures, fits = _patched(monkeypatch)
    res = SimpleNamespace(rti_exposure=None, light_gains=None, object_mask=None)
    images = np.zeros((3, 2, 2, 3), np.float32)
    o = SimpleNamespace(rti_encoding="srgb")
    relight = later.relight_after_maps(None, res, None, images, None, o, ["normals", "ptm", "rti", "relight-web"])
    assert exposures == [] and fits == [] and res.rti_exposure is None          # nothing before a stage asks
    got = {}
    threads = [threading.Thread(target=lambda n=n: got.setdefault(n, relight.fitted(n))) for n in ("ptm", "rti")]
    for t in threads:                   # the ptm and rti stages at once
        t.start()
    for t in threads:
        t.join()
    assert len(exposures) == 1 and res.rti_exposure == "exposure"      # the exposure once, for both
    assert sorted((f[0], f[1]) for f in fits) == [(("ptm",), "exposure"), (("rti", "relight-web"), "exposure")]
    assert got == {"ptm": "fits of ptm", "rti": "fits of rti+relight-web"}
    assert relight.fitted("ptm") == "fits of ptm" and len(fits) == 2          # each stage's fits made once


def test_a_stage_fits_only_the_files_asked(monkeypatch):
    exposures, fits = _patched(monkeypatch)
    res = SimpleNamespace(rti_exposure=None, light_gains=None, object_mask=None)
    relight = later.relight_after_maps(None, res, None, np.zeros((3, 2, 2, 3), np.float32), None,
                                       SimpleNamespace(rti_encoding="srgb"), ["relight-web"])
    assert relight.fitted("rti") == "fits of relight-web" and [f[0] for f in fits] == [("relight-web",)]


def test_nothing_to_set_up_without_the_relighting_files_or_with_given_fits():
    res = SimpleNamespace(rti_exposure=None)
    images = np.zeros((3, 2, 2, 3), np.float32)
    assert later.relight_after_maps(None, res, None, images, None, None, ["normals", "height"]) is None
    assert later.relight_after_maps(None, res, None, None, None, None, ["ptm"]) is None
    given = object()                  # --memory's fits, made over bands with photometric stereo
    assert later.relight_after_maps(given, res, None, images, None, None, ["ptm"]) is given
