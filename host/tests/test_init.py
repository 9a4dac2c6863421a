"""facette/__init__.py: every subpackage resolves lazily, in layer order, with the shortcuts."""
import importlib

import pytest

import facette


def test_every_subpackage_and_shortcut_resolves():
    for name in facette._SUBPACKAGES:
        assert getattr(facette, name) is importlib.import_module(f"facette.{name}")
    assert facette.scan.ScanDirectory is not None          # an AttributeError before scan was listed
    assert facette.connect is facette.scan.connect and facette.process is facette.pipeline.process
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        facette.nope
