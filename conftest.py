"""Fixtures shared by both test trees (host/tests and hil_tests): pytest loads this file for
every test below the repository."""
import subprocess

import pytest


@pytest.fixture
def small_disk(tmp_path):
    """make(kbytes) -> the path of a fresh tmpfs of that size (another filesystem than
    tmp_path's, and one that fills up), unmounted after the test. Needs the right to mount
    (root or CAP_SYS_ADMIN); without it the test is skipped, saying so."""
    mounted = []

    def make(kbytes, name="disk"):
        point = tmp_path / f"{name}{len(mounted)}"
        point.mkdir()
        run = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={int(kbytes)}k", "tmpfs", str(point)],
                             capture_output=True, text=True)
        if run.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({run.stderr.strip() or 'mount failed'}): the "
                        "cross-filesystem and full-disk cases need root or CAP_SYS_ADMIN")
        mounted.append(point)
        return point

    yield make
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)
