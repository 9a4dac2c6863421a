"""facette._memory: the `facette` command's allocator settings."""
import os
import platform
import subprocess
import sys

import pytest


@pytest.mark.skipif(platform.system() != "Linux" or platform.libc_ver()[0] != "glibc",
                    reason="the settings exist in glibc only")
def test_the_command_keeps_freed_memory_for_reuse():
    """In a fresh interpreter (the settings are process-wide): glibc takes every setting, and
    numpy, imported after, gives no huge-page advice; 1 GB freed and allocated again is
    reused, so the second touch faults (almost) no new pages."""
    code = """
import resource
from facette._memory import keep_freed_memory
ok = keep_freed_memory()
import numpy as np
a = np.ones(1 << 27); del a                    # 1 GB from the heap, then freed
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(1 << 27)
print(ok, np._core.multiarray._get_madvise_hugepage(), resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    out = subprocess.run([sys.executable, "-W", "ignore", "-c", code], capture_output=True, text=True,
                         env=env, check=True).stdout.split()
    assert out[0] == "True" and out[1] == "False"
    assert int(out[2]) < 100           # 1 GB of fresh 4 KiB pages would be 262144 faults (0 measured)


def _resident_kb():
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("VmRSS:"))


@pytest.mark.skipif(platform.system() != "Linux", reason="reads /proc/self/status")
def test_a_disk_array_keeps_what_was_written_and_its_pages_leave_memory():
    """`disk_array` + `release`: 256 MB written band by band stays readable after each band's
    pages are handed back, and the process holds far less than the array at the end."""
    import numpy as np
    from facette._memory import disk_array, release
    a = disk_array((4096, 8192, 2), np.float32)            # 256 MB
    start = _resident_kb()
    for r0 in range(0, 4096, 512):
        a[r0:r0 + 512] = r0
        release(a)
    assert _resident_kb() - start < 64 * 1024              # well under the 256 MB written
    assert a[0, 0, 0] == 0 and a[4095, 8191, 1] == 3584 and a[1000, 5, 0] == 512
    release(np.zeros(3))                                   # an array in memory: nothing to do


def test_a_disk_array_on_a_full_disk_says_where_and_what_to_do(small_disk):
    import numpy as np
    from facette._memory import disk_array
    disk = small_disk(1024)
    with pytest.raises(OSError, match="no room for a 0.02 GB map in .*disk0 .*No space left.*TMPDIR"):
        disk_array((2000, 1000, 3), np.float32, folder=disk)


def test_masked_values_of_a_disk_array_by_bands_equal_the_mask_taken_at_once():
    import numpy as np
    from facette._memory import disk_array, masked_values
    rng = np.random.default_rng(0)
    a = disk_array((37, 23), np.float32)
    a[:] = rng.random((37, 23))
    mask = rng.random((37, 23)) > 0.4
    for rows in (1, 5, 100):
        np.testing.assert_array_equal(masked_values(a, mask, rows=rows), np.asarray(a)[mask])
    assert masked_values(a, np.zeros((37, 23), bool)).size == 0


def test_decimated_equals_the_strided_view_for_any_band():
    import numpy as np
    from facette._memory import decimated, disk_array
    a = disk_array((23, 17, 3), np.float32)
    a[:] = np.arange(a.size, dtype=np.float32).reshape(a.shape)
    for step in (1, 2, 5, 30):
        for rows in (1, 3, 256):
            np.testing.assert_array_equal(decimated(a, step, rows=rows), np.asarray(a)[::step, ::step])


def test_decimated_brings_in_about_rows_of_the_array_at_a_time(monkeypatch):
    import numpy as np
    from facette import _memory
    a = _memory.disk_array((600, 8, 3), np.float32)
    spans = []
    monkeypatch.setattr(_memory, "release", lambda array: spans.append(None))
    real = type(a).__getitem__

    def spy(self, key):
        if isinstance(key, tuple) and isinstance(key[0], slice):
            spans.append(min(key[0].stop, self.shape[0]) - key[0].start)
        return real(self, key)
    monkeypatch.setattr(type(a), "__getitem__", spy)
    _memory.decimated(a, 15, rows=60)
    read = [s for s in spans if s is not None]
    assert read and max(read) <= 60 and len(read) == 10      # 600 rows, 60 (4 of the copy's) a band


def test_hand_back_gives_the_freed_heap_back_near_the_budget():
    import subprocess
    import sys
    code = """
import numpy as np
from facette._memory import keep_freed_memory, hand_back, resident_bytes as rss
assert keep_freed_memory()
parts = [np.ones(5_000_000) for _ in range(8)]      # 320 MB from the heap
pin = np.ones(10)                                    # the heap's top stays in use
before = rss()
del parts
assert not hand_back(budget=10 * rss())              # far below its budget: kept for reuse
kept = rss()
assert hand_back(budget=rss())                       # at its budget: given back
print(before - kept, kept - rss())
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    still, given = map(int, out.split())
    assert still < 20e6 < 300e6 < given          # kept after the frees, gone after hand_back


@pytest.mark.parametrize("text, want", [("2GB", 2e9), ("1.5 gb", 1.5e9), ("512MB", 512e6), ("3GiB", 3 * 2 ** 30),
                                        ("1e9", 1e9), (1000, 1000), ("1TB", 1e12), ("2TiB", 2 * 2 ** 40)])
def test_one_size_parser_reads_si_and_binary_units(text, want):
    from facette._memory import parse_size
    assert parse_size(text, limit=0) == int(want)


def test_a_size_that_is_none_or_more_than_the_machine_is_said():
    from facette._memory import machine_bytes, parse_size
    for bad, words in (("2 apples", "a size such as"), ("0GB", "at least 1 byte"), ("-1GB", "a size such as")):
        with pytest.raises(ValueError, match=words):
            parse_size(bad)
    with pytest.raises(ValueError, match="more than this machine's"):
        parse_size("1TB", limit=24 * 10 ** 9)
    assert machine_bytes() is None or parse_size(f"{machine_bytes()}") == machine_bytes()
