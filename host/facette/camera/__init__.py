"""facette.camera: RAW decode (`facette.camera.raw`) and camera backends.

Backends deliver the RAW files the camera took, in order: `FolderWatchCamera`
(a folder the camera or its tethering software writes to; used by the simulated
rig) and `GPhoto2Camera` (tethered over USB, optional: ``pip install gphoto2``).
"""
from facette.camera.folder import CameraTimeout, FolderWatchCamera

__all__ = ["FolderWatchCamera", "CameraTimeout", "GPhoto2Camera"]


def __getattr__(name):
    if name == "GPhoto2Camera":
        from facette.camera.gphoto2 import GPhoto2Camera
        return GPhoto2Camera
    raise AttributeError(name)
