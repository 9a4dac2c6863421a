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
