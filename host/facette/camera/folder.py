"""Folder-watch camera backend: a camera (or tethering software, or the simulated
rig) writes each RAW file into a folder; the scan takes them in arrival order.

Files are claimed by moving them out of the folder (into the scan's raw/), so a
file still in the watched folder is a file nobody has accounted for yet.
"""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

__all__ = ["FolderWatchCamera", "CameraTimeout", "RAW_EXTENSIONS"]

FULL_DISK_BYTES = 1 << 20    # under this free, a camera cannot write a RAW into the folder
FULL_DISK_WAIT_S = 3.0       # how long the folder's disk must stay full before the wait stops

RAW_EXTENSIONS = (".dng", ".nef", ".cr2", ".cr3", ".arw", ".raf", ".orf", ".rw2", ".pef")


class CameraTimeout(TimeoutError):
    """No new image arrived in time."""


class FolderWatchCamera:
    """Watch `folder` for new RAW files.

    Parameters
    ----------
    folder : path the camera writes to (created if missing)
    extensions : accepted suffixes (case-insensitive)
    stable_polls : a file counts as complete once its size is unchanged over this
        many polls (cameras writing in place); temporary names (``.*``, ``*.partial``,
        ``*.tmp``) are never taken
    poll_s : polling interval, s
    """

    def __init__(self, folder, extensions=RAW_EXTENSIONS, stable_polls=2, poll_s=0.005):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.extensions = tuple(e.lower() for e in extensions)
        self.stable_polls = int(stable_polls)
        self.poll_s = float(poll_s)
        self.ignored = set()
        self._sizes = {}

    def __repr__(self):
        return f"FolderWatchCamera({str(self.folder)!r})"

    def _candidates(self):
        out = []
        with os.scandir(self.folder) as it:
            for e in it:
                name = e.name
                if name.startswith(".") or name.endswith((".partial", ".tmp")) or not e.is_file():
                    continue
                if not name.lower().endswith(self.extensions) or name in self.ignored:
                    continue
                st = e.stat()
                out.append((st.st_mtime_ns, name, st.st_size))
        out.sort()
        return out

    def pending(self):
        """Files in the folder nobody claimed yet (oldest first), complete or not."""
        return [self.folder / name for _, name, _ in self._candidates()]

    def ignore_existing(self):
        """Treat every file already in the folder as not ours (before a fresh scan)."""
        self.ignored |= {name for _, name, _ in self._candidates()}
        return sorted(self.ignored)

    def ignore(self, names):
        """Never take these file names (files that were there before the scan began)."""
        self.ignored |= set(names)

    def poll(self):
        """The oldest complete new file, or None."""
        for _, name, size in self._candidates():
            hist = self._sizes.setdefault(name, [])
            hist.append(size)
            if len(hist) >= self.stable_polls and len(set(hist[-self.stable_polls:])) == 1 and size > 0:
                return self.folder / name
            return None   # keep arrival order: wait for the oldest
        return None

    def wait_for_file(self, timeout_s=30.0, alive=None):
        """Block until a new complete file is there; returns its path (still in the folder).

        `alive` : optional callable; when it returns a message string the wait
        stops early with CameraTimeout(message) (e.g. the device faulted).
        """
        deadline = time.monotonic() + timeout_s
        full_since = None
        while True:
            path = self.poll()
            if path is not None:
                return path
            if alive is not None:
                why = alive()
                if why:
                    raise CameraTimeout(why)
            full = self._disk_full()
            full_since = (full_since or time.monotonic()) if full else None
            if full and time.monotonic() - full_since > FULL_DISK_WAIT_S:
                raise CameraTimeout(full)
            if time.monotonic() > deadline:
                try:
                    free = f" (its disk has {shutil.disk_usage(self.folder).free / 1e6:.0f} MB free)"
                except OSError:
                    free = ""
                raise CameraTimeout(f"no new image in {self.folder}{free} within {timeout_s:g} s: is the camera "
                                    "on, in RAW mode, and writing to this folder?")
            time.sleep(self.poll_s)

    def _disk_full(self):
        """The sentence saying the folder's disk is full (no RAW can be written there), or None."""
        try:
            free = shutil.disk_usage(self.folder).free
        except OSError:
            return None
        if free >= FULL_DISK_BYTES:
            return None
        mount = Path(self.folder).absolute()
        while not os.path.ismount(mount) and mount != mount.parent:
            mount = mount.parent
        return (f"the disk holding the camera folder {self.folder} (mounted at {mount}) is full ({free / 1e3:.0f} kB "
                "free): the camera cannot write its images there; free space on it, then run the same command "
                "again (the scan resumes where it stopped)")

    def claimed(self, path):
        """Forget a file that was moved away."""
        self._sizes.pop(Path(path).name, None)
