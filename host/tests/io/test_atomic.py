"""Atomic writes, moves across filesystems and full disks (facette.io.atomic), on real tmpfs
mounts where the test may make one."""
import errno
import hashlib
import os

import numpy as np
import pytest

from facette.errors import EXIT_NO_RESULT, EXIT_STOPPED
from facette.io.atomic import DiskFullError, atomic_path, move_file, write_bytes_atomic
from facette.io.exr import write_exr
from facette.io.png import write_png


def _sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_an_atomic_write_leaves_the_file_or_nothing(tmp_path):
    p = tmp_path / "a.bin"
    write_bytes_atomic(p, b"first")
    with pytest.raises(RuntimeError):
        with atomic_path(p) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("stopped mid-write")
    assert p.read_bytes() == b"first"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.bin"]     # no temporary left


def test_a_move_crosses_filesystems_by_copy_then_rename(tmp_path, small_disk):
    camera = small_disk(1024, "camera")           # a tethering folder on a tmpfs, the scan elsewhere
    src = camera / "IMG_0001.dng"
    src.write_bytes(os.urandom(50_000))
    digest = _sha(src)
    with pytest.raises(OSError) as exc:            # what os.replace alone does
        os.replace(src, tmp_path / "x")
    assert exc.value.errno == errno.EXDEV
    dst = move_file(src, tmp_path / "L00_E0.dng")
    assert not src.exists() and _sha(dst) == digest
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".partial")] == []


def test_a_move_onto_a_full_disk_keeps_the_source(tmp_path, small_disk):
    scan = small_disk(64, "scan")
    src = tmp_path / "IMG_0002.dng"
    src.write_bytes(os.urandom(200_000))
    digest = _sha(src)
    with pytest.raises(DiskFullError) as exc:
        move_file(src, scan / "L00_E0.dng", exit_code=EXIT_STOPPED)
    assert exc.value.exit_code == EXIT_STOPPED
    assert f"mounted at {scan}" in exc.value.message and "L00_E0.dng needs 0.2 MB" in exc.value.message
    assert "run the same command again" in exc.value.hint
    assert _sha(src) == digest and list(scan.iterdir()) == []      # nothing lost, nothing half-written


@pytest.mark.parametrize("writer", ["exr", "png"])
def test_writers_on_a_full_disk_say_so_and_leave_no_truncated_file(small_disk, writer):
    disk = small_disk(64)
    img = np.random.default_rng(0).random((200, 200, 3))
    with pytest.raises(DiskFullError) as exc:
        if writer == "exr":
            write_exr(disk / "normal.exr", img, compression="none")
        else:
            write_png(disk / "mask.png", (img * 65535).astype(np.uint16))
    assert exc.value.exit_code == EXIT_NO_RESULT and "is full" in exc.value.message
    assert list(disk.iterdir()) == []
