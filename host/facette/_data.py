"""Packaged data, found one way (`importlib.resources`): the calibration target
specifications and the committed profiles (the simulated rig's ``sim-default``), and the
text files that ship beside a subpackage's modules (the report viewer's ``viewer.js``).

In the source tree ``facette/data`` is a link to the repository's ``calibration/``
folder; an installed package carries a copy (package data in pyproject.toml).
"""
from importlib.resources import files
from pathlib import Path

__all__ = ["data_dir", "targets_dir", "profiles_dir", "sim_profile_dir", "package_text"]


def data_dir():
    """The package's data folder (targets/, profiles/), as a Path."""
    return Path(str(files("facette") / "data"))


def targets_dir():
    """Target specifications: spectralon-99.json, mirror-sphere.json, matte-sphere.json."""
    return data_dir() / "targets"


def profiles_dir():
    """Calibration profiles, one folder per rig (the wizard's default output)."""
    return data_dir() / "profiles"


def sim_profile_dir():
    """The committed profile of the simulated rig (calibration/profiles/sim-default)."""
    return profiles_dir() / "sim-default"


def package_text(package, name):
    """A text file shipped beside a subpackage's modules, e.g. package_text("facette.pipeline",
    "viewer.js") (package data in pyproject.toml)."""
    return files(package).joinpath(name).read_text(encoding="utf-8")
