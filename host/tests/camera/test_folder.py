"""Folder-watch camera backend."""
import os

import pytest

from facette.camera import CameraTimeout, FolderWatchCamera


def _write(path, data=b"x" * 64, mtime_ns=None):
    path.write_bytes(data)
    if mtime_ns is not None:
        os.utime(path, ns=(mtime_ns, mtime_ns))


def test_files_come_out_in_arrival_order_and_temporary_names_are_skipped(tmp_path):
    cam = FolderWatchCamera(tmp_path, stable_polls=1)
    _write(tmp_path / "B.dng", mtime_ns=2_000_000_000)
    _write(tmp_path / "A.dng", mtime_ns=3_000_000_000)
    _write(tmp_path / ".C.dng.123.partial")
    _write(tmp_path / "notes.txt")
    assert [p.name for p in cam.pending()] == ["B.dng", "A.dng"]
    first = cam.wait_for_file(timeout_s=1)
    assert first.name == "B.dng"
    first.rename(tmp_path.parent / "moved.dng")
    cam.claimed(first)
    assert cam.wait_for_file(timeout_s=1).name == "A.dng"


def test_a_file_must_keep_its_size_before_it_is_taken(tmp_path):
    cam = FolderWatchCamera(tmp_path, stable_polls=2)
    _write(tmp_path / "IMG_1.NEF", b"abc")
    assert cam.poll() is None                 # seen once: maybe still being written
    _write(tmp_path / "IMG_1.NEF", b"abcdef")
    assert cam.poll() is None                 # it grew
    assert cam.poll().name == "IMG_1.NEF"     # same size twice: complete


def test_existing_files_can_be_ignored_and_timeouts_explain(tmp_path):
    _write(tmp_path / "old.dng")
    cam = FolderWatchCamera(tmp_path, stable_polls=1)
    assert cam.ignore_existing() == ["old.dng"]
    assert cam.pending() == []
    with pytest.raises(CameraTimeout, match="in RAW mode"):
        cam.wait_for_file(timeout_s=0.0)


def test_a_full_camera_folder_disk_stops_the_wait_and_says_so(small_disk):
    import time
    from facette.camera.folder import FULL_DISK_WAIT_S
    disk = small_disk(256)
    cam = FolderWatchCamera(disk, poll_s=0.05)
    with open(disk / "filler", "wb") as fh:            # what fills it: not a RAW, not taken
        try:
            fh.write(b"\0" * (300 << 10))
        except OSError:
            pass
    t0 = time.monotonic()
    with pytest.raises(CameraTimeout) as exc:
        cam.wait_for_file(timeout_s=60)
    assert time.monotonic() - t0 < FULL_DISK_WAIT_S + 5
    assert f"(mounted at {disk}) is full" in str(exc.value) and "the scan resumes" in str(exc.value)
