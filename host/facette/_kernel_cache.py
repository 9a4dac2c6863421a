"""Where numba keeps facette's compiled kernels: one folder per version of the kernels' sources.

numba's `cache=True` keys a kernel on its own file's path and modification time only. A kernel that
calls a kernel of another file (`_normals_li_jit` calls `_select_jit.kth_smallest`) keeps the callee's
old machine code when only the callee's file changes: after a `git pull`, `facette process` could run
yesterday's code, or fail to load a function that has moved. So, unless NUMBA_CACHE_DIR is set, the
cache goes to a folder named by a digest of every module that uses numba: any change to one of them
starts a new folder, and the whole set is compiled again (`make setup`, or the first run, ~15-40 s).
Hashing the 41 files costs ~7 ms at import.
"""
import hashlib
import os
import sys
from pathlib import Path

__all__ = ["kernel_cache_dir", "use_kernel_cache", "stale_kernel_caches"]

PACKAGE = Path(__file__).resolve().parent
PREFIX = "kernels-"


def _digest():
    h = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            h.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0" + text)
    return h.hexdigest()[:16]


def _root():
    """The package's __pycache__ when it can be written (a clone), else the user's cache folder (an
    installed, read-only package)."""
    local = PACKAGE / "__pycache__"
    if os.access(PACKAGE, os.W_OK) and (not local.exists() or os.access(local, os.W_OK)):
        return local
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "facette"


def kernel_cache_dir():
    """The folder numba caches facette's kernels in, for the sources as they are now."""
    return _root() / f"{PREFIX}{_digest()}"


def use_kernel_cache():
    """Point numba at `kernel_cache_dir()`, unless the user set NUMBA_CACHE_DIR; before any kernel is
    compiled (numba reads the folder when a kernel module is imported)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    folder = str(kernel_cache_dir())
    os.environ["NUMBA_CACHE_DIR"] = folder
    config = sys.modules.get("numba.core.config")
    if config is not None:            # numba imported before facette: it has read the environment already
        config.CACHE_DIR = folder


def stale_kernel_caches():
    """The cache folders of earlier versions of the sources (safe to delete)."""
    current = kernel_cache_dir()
    return sorted(p for p in current.parent.glob(f"{PREFIX}*") if p.is_dir() and p != current)
