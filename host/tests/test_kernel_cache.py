"""numba's cache of facette's kernels: one folder per version of the kernels' sources, so that a
kernel never runs the old code of a kernel it inlined from another file."""
import os
import subprocess
import sys

from facette import _kernel_cache as kc


def test_the_cache_folder_follows_every_kernel_source_and_only_them(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    (pkg / "fit").mkdir(parents=True)
    (pkg / "fit" / "_solve_jit.py").write_text("from numba import njit\n")
    (pkg / "_select_jit.py").write_text("from numba import njit\n")
    (pkg / "plain.py").write_text("x = 1\n")
    monkeypatch.setattr(kc, "PACKAGE", pkg)
    first = kc.kernel_cache_dir()
    assert first.parent == pkg / "__pycache__" and first.name.startswith(kc.PREFIX)
    (pkg / "plain.py").write_text("x = 2\n")
    assert kc.kernel_cache_dir() == first            # no kernel changed
    (pkg / "_select_jit.py").write_text("from numba import njit\n# the callee changed, not its caller\n")
    second = kc.kernel_cache_dir()
    assert second != first
    first.mkdir(parents=True)
    second.mkdir(parents=True)
    assert kc.stale_kernel_caches() == [first]


def _cache_dir_seen_by_numba(env):
    code = ("import numba; import facette; from numba.core import config; "
            "from facette._kernel_cache import kernel_cache_dir; print(config.CACHE_DIR); print(kernel_cache_dir())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split("\n")[:2]


def test_numba_imported_first_still_caches_in_the_sources_folder_and_the_users_choice_wins(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    seen, expected = _cache_dir_seen_by_numba(env)
    assert seen == expected
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    seen, _ = _cache_dir_seen_by_numba(env)
    assert seen == str(tmp_path / "mine")
