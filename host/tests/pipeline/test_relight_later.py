"""The relighting files' set-up after the maps (pipeline._relight_later): their exposure is found
when the ptm / rti stage first asks, once, and not when `process` starts the stages after
photometric stereo."""
import threading
from types import SimpleNamespace

import numpy as np

import facette.pipeline._relight_later as later


def test_the_set_up_waits_for_the_first_stage_that_asks_and_runs_once(monkeypatch):
    calls = []

    def whole_bands(relight, res, inp, images, light_dirs, o, outputs):
        calls.append(threading.get_ident())
        res.rti_exposure = "exposure"
        return SimpleNamespace(fitted=lambda: "fits")

    monkeypatch.setattr(later, "whole_bands", whole_bands)
    res = SimpleNamespace(rti_exposure=None)
    images = np.zeros((3, 2, 2, 3), np.float32)
    relight = later.relight_after_maps(None, res, None, images, None, None, ["normals", "ptm", "rti"])
    assert calls == [] and res.rti_exposure is None          # nothing before a stage asks
    threads = [threading.Thread(target=relight.fitted) for _ in range(2)]      # ptm and rti at once
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(calls) == 1 and res.rti_exposure == "exposure" and relight.fitted() == "fits"


def test_nothing_to_set_up_without_the_relighting_files_or_with_given_fits():
    res = SimpleNamespace(rti_exposure=None)
    images = np.zeros((3, 2, 2, 3), np.float32)
    assert later.relight_after_maps(None, res, None, images, None, None, ["normals", "height"]) is None
    assert later.relight_after_maps(None, res, None, None, None, None, ["ptm"]) is None
    given = object()                  # --memory's fits, made over bands with photometric stereo
    assert later.relight_after_maps(given, res, None, images, None, None, ["ptm"]) is given
