"""Files that appear complete or not at all, on any filesystem; a full disk said plainly.

Every output facette writes goes through `atomic_path` (or `write_bytes_atomic` /
`write_text_atomic`): the data go to a hidden temporary name in the destination's own folder
(``.NAME.PID.partial``), are flushed to the disk (fsync), then renamed over the final name,
so a reader, a crash or a full disk never leaves a truncated file under the final name.
`move_file` moves a file onto another filesystem (a camera's tethering folder on a tmpfs,
the scan on a disk) by copying it to a temporary name beside the destination, then renaming:
`os.replace` alone cannot cross filesystems (EXDEV).

A write that fails because the disk is full (ENOSPC, EDQUOT) raises `DiskFullError`, a
`FacetteError` naming the disk (its mount point), its free space and what the file needed;
its exit code is 3 (`process`: nothing more can be written there); a scan turns it into a
stopped scan (exit 1) that resumes when space is freed.
"""
import contextlib
import errno
import os
import shutil
import threading
from pathlib import Path

from facette.errors import EXIT_NO_RESULT, EXIT_STOPPED, FacetteError

__all__ = ["DiskFullError", "atomic_path", "write_bytes_atomic", "write_text_atomic", "move_file",
           "is_disk_full", "disk_full_error", "PARTIAL_SUFFIX"]

PARTIAL_SUFFIX = ".partial"
FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
LOW_FREE_BYTES = 1 << 20     # a library's own write error with less than this free: the disk is full


class DiskFullError(FacetteError):
    """The disk (or the user's quota) holding a file is full; nothing was left half-written."""

    exit_code = EXIT_NO_RESULT


def _existing_dir(path):
    p = Path(path).absolute()
    while not p.is_dir() and p != p.parent:
        p = p.parent
    return p


def _mount_point(path):
    p = _existing_dir(path)
    while not os.path.ismount(p) and p != p.parent:
        p = p.parent
    return p


def _free_bytes(path):
    try:
        return shutil.disk_usage(_existing_dir(path)).free
    except OSError:
        return None


def _mb(n):
    return f"{n / 1e6:.1f} MB" if n >= 1e5 else f"{n / 1e3:.1f} kB"


def is_disk_full(exc, path=None):
    """True when `exc` says the disk is full: ENOSPC / EDQUOT, or (libraries such as OpenEXR
    that report no errno) any write error while `path`'s disk has under 1 MiB free."""
    if isinstance(exc, DiskFullError):
        return True
    if isinstance(exc, OSError) and exc.errno in FULL_ERRNOS:
        return True
    if path is not None and isinstance(exc, (OSError, RuntimeError, ValueError)):
        free = _free_bytes(path)
        return free is not None and free < LOW_FREE_BYTES
    return False


def disk_full_error(path, needed=None, written=None, exit_code=None):
    """The `DiskFullError` for writing `path`: the disk (mount point), its free space, and the
    space needed (`needed` bytes when known, else more than the `written` bytes that fitted)."""
    path = Path(path)
    free = _free_bytes(path)
    mount = _mount_point(path)
    if needed:
        need = f"{path.name} needs {_mb(needed)}"
    elif written:
        need = f"{path.name} needs more than the {_mb(written)} that fitted"
    else:
        need = f"{path.name} did not fit"
    said = f"{_mb(free)} free" if free is not None else "its free space unknown"
    return DiskFullError(f"the disk holding {path} (mounted at {mount}) is full (or your quota on it): "
                         f"{need}, {said}",
                         hint=("free space on that disk, then run the same command again: the scan resumes "
                               "where it stopped" if exit_code == EXIT_STOPPED else
                               "free space on that disk (or choose a folder on another disk), then run the "
                               "same command again") + "; nothing was left half-written",
                         exit_code=exit_code)


def _fsync_dir(folder):
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:        # some filesystems refuse a directory fsync: the rename is still atomic
        pass
    finally:
        os.close(fd)


def _temporary_name(path):
    return path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident() % 100000}{PARTIAL_SUFFIX}")


@contextlib.contextmanager
def atomic_path(path, needed=None, fsync=True, exit_code=None):
    """A temporary path beside `path` to write to; when the block ends without error it is
    flushed to disk and renamed to `path` (else removed). A full disk raises `DiskFullError`.

    needed : the bytes the file will take, when known (said in the error).
    exit_code : the `DiskFullError`'s exit code (default 3; a scan passes 1: it resumes).
    Usage: ``with atomic_path(p) as tmp: library.write(str(tmp))``.
    """
    path = Path(path)
    tmp = _temporary_name(path)
    try:
        yield tmp
        if fsync:
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        os.replace(tmp, path)
    except BaseException as exc:
        written = tmp.stat().st_size if tmp.exists() else None
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, Exception) and not isinstance(exc, DiskFullError) and is_disk_full(exc, path):
            raise disk_full_error(path, needed, written, exit_code) from exc
        raise
    if fsync:
        _fsync_dir(path.parent)


def write_bytes_atomic(path, data, fsync=True, exit_code=None):
    """Write `data` (bytes) to `path` atomically (see `atomic_path`)."""
    with atomic_path(path, needed=len(data), fsync=fsync, exit_code=exit_code) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)


def write_text_atomic(path, text, fsync=True, exit_code=None):
    """Write `text` (UTF-8) to `path` atomically (see `atomic_path`)."""
    write_bytes_atomic(path, text.encode("utf-8"), fsync=fsync, exit_code=exit_code)


def move_file(src, dst, exit_code=None):
    """Move the file `src` to `dst` (replacing it), across filesystems too: a rename when both
    are on one filesystem; else a copy to a temporary name beside `dst`, flushed, renamed to
    `dst`, and only then `src` removed (an interruption leaves `src` in place, never a
    truncated `dst`). A full destination disk raises `DiskFullError` with `src` untouched."""
    src, dst = Path(src), Path(dst)
    try:
        os.replace(src, dst)
        return dst
    except OSError as exc:
        if exc.errno != errno.EXDEV:
            raise
    with atomic_path(dst, needed=src.stat().st_size, exit_code=exit_code) as tmp:
        shutil.copyfile(src, tmp)
        with contextlib.suppress(OSError):     # times and modes: kept where the filesystem can
            shutil.copystat(src, tmp)
    os.unlink(src)
    return dst
