"""The `facette` command's memory policy: freed memory is kept for reuse, not given back.

A 12 MP `facette process` allocates and frees ~10 GB of numpy temporaries, most of them over
glibc's mmap threshold (32 MB at most), so each comes as fresh pages from the kernel and is
handed back when freed: 2.5 million page faults, 9 s of kernel time on this 2-core VM. With
every allocation from the heap and the heap never trimmed, freed blocks are reused: 0.6 million
faults, 2.4 s in the kernel, the same peak (2.45–2.51 GB), 9 CPU s less in all.

The `facette` command sets this (cli/main.py), before numpy or any thread starts, and so does
`facette bench e2e` for the merge it times in a process of its own; a script importing facette
keeps its own allocator settings. Only where the C library is glibc.
"""
import ctypes
import os
import re

# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_MAX, _M_ARENA_MAX = -1, -2, -4, -8


def keep_freed_memory():
    """Every allocation from glibc's main heap (no mmap, one arena), the heap never trimmed;
    and numpy's huge-page advice off. True when glibc took the settings, False elsewhere."""
    # numpy asks for transparent huge pages on each large array; with the kernel's usual
    # `defrag=madvise` each first touch then compacts memory: 12 MP process spent 10 s in
    # the kernel with it, 7 s without (before the heap setting below).
    os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):      # not glibc (macOS, musl)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    ok = [mallopt(_M_ARENA_MAX, 1),          # worker threads share the main heap (else their
                                             # arenas, being mmap'd, cannot grow past 64 MB)
          mallopt(_M_MMAP_MAX, 0),           # large arrays from the heap too
          mallopt(_M_TRIM_THRESHOLD, 2**31 - 1),
          mallopt(_M_TOP_PAD, 64 << 20)]     # the heap grows 64 MB at a time
    return all(ok)


# `hand_back(budget)` gives nothing back below this share of the budget: the freed heap is kept for
# reuse (12 MP, every output, --memory 2GB: handed back after every stage, 1.20x the time for
# 0.05 GB less at the peak; 100 MP: 2.95 GB kept, see README)
HAND_BACK_ABOVE = 0.9


def resident_bytes():
    """This process's resident memory now (bytes); 0 where /proc is not there."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def hand_back(budget=None):
    """Give the heap's free pages back to the kernel now (glibc's malloc_trim): with
    `keep_freed_memory` nothing goes back on its own, so a stage's freed temporaries stay in the
    process's memory and the next stage's come on top of them wherever they do not fit the holes.
    `process --memory` calls it between its stages with its budget (bytes): only a process holding
    more than HAND_BACK_ABOVE of it gives back (the next stage's faults are the price). True when
    the pages were given back; False below the share, or where the C library is not glibc."""
    if budget is not None and resident_bytes() < HAND_BACK_ABOVE * budget:
        return False
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):      # not glibc
        return False
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    trim(0)
    return True


def handing_back(fn, budget=None):
    """fn (no arguments) then `hand_back(budget)`, as one function returning fn's result."""
    def run():
        try:
            return fn()
        finally:
            hand_back(budget)
    return run


def disk_array(shape, dtype, folder=None):
    """A zero-filled array kept in a temporary file (a numpy memmap) rather than in memory: the
    full-size maps of a `--memory` run, written and read a band at a time. The file has no name
    (it is gone when the array is), in `folder` or the temporary directory."""
    import tempfile

    import numpy as np
    size = int(np.prod(shape)) * np.dtype(dtype).itemsize
    if size == 0:
        return np.zeros(shape, dtype)
    with tempfile.TemporaryFile(dir=folder) as fh:     # the map keeps the file open on its own
        try:
            # the blocks taken now: a map over a sparse file would crash (SIGBUS) on a full disk
            os.posix_fallocate(fh.fileno(), 0, size)
        except OSError as exc:
            where = folder or tempfile.gettempdir()
            raise OSError(exc.errno, f"no room for a {size / 1e9:.2f} GB map in {where} ({exc.strerror}): "
                                     "free disk space there, or set TMPDIR to a disk that has it") from exc
        return np.memmap(fh, dtype=dtype, mode="r+", shape=tuple(shape))


def release(array):
    """Hand a disk array's pages back to the kernel (written out first): what was read or
    written of it stops counting in this process's memory until it is touched again. Nothing
    for an array in memory, or a view of part of one."""
    import mmap

    import numpy as np
    base = array
    while base is not None and not isinstance(base, np.memmap):
        base = getattr(base, "base", None)
    raw = getattr(base, "_mmap", None)
    if raw is None:
        return
    raw.flush()
    raw.madvise(mmap.MADV_DONTNEED)


def masked_values(array, mask, rows=1024):
    """array[mask], read a band of rows at a time: a disk array is never brought into memory
    whole (a 100 MP residual map is 0.4 GB), only the values kept."""
    import numpy as np
    out = np.empty(int(np.count_nonzero(mask)), array.dtype)
    k = 0
    for r0 in range(0, mask.shape[0], rows):
        part = array[r0:r0 + rows][mask[r0:r0 + rows]]
        out[k:k + part.size] = part
        k += part.size
        release(array)
    return out


def decimated(array, step, rows=256):
    """A copy of array[::step, ::step], read about `rows` rows of `array` at a time: from a disk
    array a strided read would still bring nearly every page in (the kernel maps the pages around
    each one it faults), so its pages are handed back after each band. The band counts the
    array's rows, not the copy's: 256 rows of the copy at step 15 were 3840 of a 100 MP normal
    map, 0.54 GB brought in before the pages went back."""
    import numpy as np
    out = np.empty((len(range(0, array.shape[0], step)), len(range(0, array.shape[1], step)))
                   + array.shape[2:], array.dtype)
    per_band = max(1, int(rows) // step)               # rows of the copy per band
    for k in range(0, out.shape[0], per_band):
        out[k:k + per_band] = array[k * step:(k + per_band) * step:step, ::step]
        release(array)
    return out


# The sizes a person writes for a memory budget: SI (kB, MB, GB, TB) and binary (KiB ... TiB)
# units, case-insensitive, "B" optional; a plain number is bytes.
SIZE_UNITS = {"": 1, "B": 1, "K": 1e3, "KB": 1e3, "M": 1e6, "MB": 1e6, "G": 1e9, "GB": 1e9, "T": 1e12, "TB": 1e12,
              "KIB": 2 ** 10, "MIB": 2 ** 20, "GIB": 2 ** 30, "TIB": 2 ** 40}


def machine_bytes():
    """This machine's physical memory (bytes); None where the system does not say."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return None


def parse_size(text, what="memory", limit=None):
    """'2GB', '1.5 GB', '512MB', '3GiB', '1TB' or a number of bytes -> bytes (int): the one size
    parser of facette's options. ValueError naming the units when it is not a size, when it is
    not > 0, or when it exceeds `limit` (bytes; default: this machine's memory, which a budget
    above cannot be kept to; 0 for none)."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
    else:
        match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([A-Za-z]*)\s*", str(text))
        if not match or match.group(2).upper() not in SIZE_UNITS:
            raise ValueError(f"{what} must be a size such as 2GB, 512MB, 3GiB or 1TB, got {text!r}")
        value = float(match.group(1)) * SIZE_UNITS[match.group(2).upper()]
    if not value >= 1:
        raise ValueError(f"{what} must be at least 1 byte, got {text!r}")
    limit = machine_bytes() if limit is None else limit
    if limit and value > limit:
        raise ValueError(f"{what} {text} is more than this machine's {limit / 1e9:.1f} GB of memory: a budget it "
                         f"cannot keep to; give at most {int(limit / 1e9)}GB")
    return int(value)
