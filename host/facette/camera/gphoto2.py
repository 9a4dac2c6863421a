"""gphoto2 camera backend: a tethered camera over USB (optional: ``pip install gphoto2``).

The rig releases the camera through its shutter line (remote-release socket); this
backend only collects what the camera wrote: it waits for libgphoto2's
FILE_ADDED events (and, for cameras that do not send them, compares file listings),
downloads each new RAW file into `download_dir`, and hands it to the scan exactly
like `FolderWatchCamera` (same `pending`/`poll`/`wait_for_file`/`claimed` calls).
Files are left on the camera's card (nothing captured is lost if the host dies).
"""
from __future__ import annotations

import time

from facette.camera.folder import RAW_EXTENSIONS, CameraTimeout, FolderWatchCamera

__all__ = ["GPhoto2Camera", "CameraError"]


class CameraError(RuntimeError):
    """The camera could not be opened or read through gphoto2."""


def _gp():
    try:
        import gphoto2 as gp
    except ImportError as exc:
        raise CameraError("the gphoto2 backend needs python-gphoto2: `pip install gphoto2` "
                          "(or `pip install 'facette[gphoto2]'`)") from exc
    return gp


class GPhoto2Camera:
    """A camera on USB, through libgphoto2.

    Parameters
    ----------
    download_dir : folder the new RAW files are downloaded to (the scan takes them from there)
    model, port : libgphoto2 camera model and port ("usb:001,004"); default: autodetect
    extensions : RAW suffixes to collect (JPEGs of a RAW+JPEG setting are ignored)
    """

    def __init__(self, download_dir, model=None, port=None, extensions=RAW_EXTENSIONS):
        gp = _gp()
        self.gp = gp
        self.extensions = tuple(e.lower() for e in extensions)
        self.folder_cam = FolderWatchCamera(download_dir, extensions=self.extensions, stable_polls=1)
        self.camera = gp.Camera()
        try:
            if model or port:
                if model:
                    abilities = gp.CameraAbilitiesList()
                    abilities.load()
                    self.camera.set_abilities(abilities[abilities.lookup_model(model)])
                if port:
                    ports = gp.PortInfoList()
                    ports.load()
                    self.camera.set_port_info(ports[ports.lookup_path(port)])
            self.camera.init()
        except gp.GPhoto2Error as exc:
            raise CameraError(f"no camera could be opened through gphoto2 ({exc}): is it on, connected by "
                              "USB, in PTP/tethered mode, and not mounted by the desktop? "
                              "`gphoto2 --auto-detect` lists what libgphoto2 sees") from exc
        self.known = set(self._listing())

    @property
    def folder(self):
        return self.folder_cam.folder

    def __repr__(self):
        return f"GPhoto2Camera({str(self.folder)!r})"

    def _listing(self, path="/"):
        out = []
        for name, _ in self.camera.folder_list_files(path):
            out.append((path, name))
        for name, _ in self.camera.folder_list_folders(path):
            out += self._listing(path.rstrip("/") + "/" + name)
        return out

    def _download(self, path, name):
        if not name.lower().endswith(self.extensions):
            return None
        dst = self.folder / name
        tmp = self.folder / f".{name}.partial"
        f = self.camera.file_get(path, name, self.gp.GP_FILE_TYPE_NORMAL)
        f.save(str(tmp))
        tmp.replace(dst)
        return dst

    def _collect(self, timeout_ms):
        gp = self.gp
        got = False
        event, data = self.camera.wait_for_event(timeout_ms)
        while event != gp.GP_EVENT_TIMEOUT:
            if event == gp.GP_EVENT_FILE_ADDED:
                self.known.add((data.folder, data.name))
                got |= self._download(data.folder, data.name) is not None
            event, data = self.camera.wait_for_event(1)
        if not got:   # cameras without FILE_ADDED events: compare listings
            for key in self._listing():
                if key not in self.known:
                    self.known.add(key)
                    self._download(*key)

    # -- the FolderWatchCamera interface used by facette.scan --------------------------
    def pending(self):
        return self.folder_cam.pending()

    def ignore_existing(self):
        self.known = set(self._listing())
        return self.folder_cam.ignore_existing()

    def ignore(self, names):
        self.folder_cam.ignore(names)

    def poll(self):
        self._collect(10)
        return self.folder_cam.poll()

    def wait_for_file(self, timeout_s=30.0):
        deadline = time.monotonic() + timeout_s
        while True:
            path = self.poll()
            if path is not None:
                return path
            if time.monotonic() > deadline:
                raise CameraTimeout(f"the camera reported no new RAW file within {timeout_s:g} s: is it in "
                                    "RAW mode, with the release cable on the rig's shutter output?")

    def claimed(self, path):
        self.folder_cam.claimed(path)

    def close(self):
        self.camera.exit()


def available():
    """Whether python-gphoto2 is importable."""
    try:
        _gp()
    except CameraError:
        return False
    return True
