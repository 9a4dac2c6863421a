"""Tests of facette.scan (a package: test_rig.py is also a name in sim/)."""
