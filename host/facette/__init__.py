"""facette: reflectance capture, from the rig's LEDs to shape and material.

Scripting entry points (see docs/conventions.md, "Scripting")::

    import facette
    rig = facette.connect("sim")
    scan = rig.scan("out/plaque", profile=facette.calib.load("calibration/profiles/sim-default"))
    result = facette.process(scan, outputs=["normals", "height", "brdf"])
"""
import importlib

from facette._kernel_cache import use_kernel_cache

__version__ = "0.1.0"

# numba's cache of the compiled kernels, one folder per version of their sources (see _kernel_cache)
use_kernel_cache()

# Lowest layer first (docs/ARCHITECTURE.md).
_SUBPACKAGES = ("device", "camera", "io", "hdr", "recon", "reflect", "brdf", "fit", "calib", "methods", "sim",
                "scan", "capture", "pipeline", "wizard", "cli", "bench")
# Top-level conveniences, resolved on first use so `import facette` stays fast.
_SHORTCUTS = {"connect": ("facette.scan", "connect"), "process": ("facette.pipeline", "process")}

__all__ = list(_SUBPACKAGES) + list(_SHORTCUTS)


def __getattr__(name):
    if name in _SHORTCUTS:
        module, attr = _SHORTCUTS[name]
        return getattr(importlib.import_module(module), attr)
    if name in _SUBPACKAGES:
        return importlib.import_module(f"facette.{name}")
    raise AttributeError(f"module 'facette' has no attribute {name!r}")
