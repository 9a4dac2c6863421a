"""Sizes a newcomer can read: in `facette.scan` and the `ps_li_alternating` modules (split in
issue 27) no file over 500 lines and no function over 100 lines; elsewhere the files and
functions still longer than that are listed here with their length at most, so that none grows
and no new one appears (shorten one, then lower or drop its line; `python3 tools/size_figures.py`
prints them all)."""
import ast
from pathlib import Path

import facette

PACKAGE = Path(facette.__file__).parent
MAX_FILE, MAX_FUNCTION = 500, 100
STRICT = ("scan/", "fit/_ps_li")    # path prefixes that no listing can exempt
# the longer ones left (issue 27, December 2026): path -> lines at most
LONG_FILES = {"pipeline/_report.py": 620,
              "recon/_ps.py": 518}
LONG_FUNCTIONS = {"fit/_normals_li_jit.py _solve_one": 141,
                  "recon/_interreflect.py remove_interreflections": 120,
                  "bench/brdf.py bench_volume": 127,
                  "recon/_ps_robust.py ps_rank_trimmed": 117, "hdr/_bracket.py plan_adaptive": 106}


def _sizes():
    """({path: lines}, {"path function": lines}) of every module of the package."""
    files, functions = {}, {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        files[rel] = len(text.splitlines())
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                key = f"{rel} {node.name}"
                functions[key] = max(functions.get(key, 0), node.end_lineno - node.lineno + 1)
    return files, functions


def _over(sizes, limit, listed):
    """Entries over `limit` that are not listed, or longer than listed."""
    return sorted(f"{k}: {n} lines" for k, n in sizes.items()
                  if n > limit and (k.startswith(STRICT) or n > listed.get(k, limit)))


def test_no_file_grows_past_500_lines():
    files, _ = _sizes()
    assert _over(files, MAX_FILE, LONG_FILES) == []


def test_no_function_grows_past_100_lines():
    _, functions = _sizes()
    assert _over(functions, MAX_FUNCTION, LONG_FUNCTIONS) == []


def test_the_check_sees_a_long_strict_file_and_a_grown_listed_one():
    listed = {"io/_long.py": 619, "fit/_ps_li.py": 619}
    assert _over({"scan/acquire.py": 718, "io/_long.py": 619}, MAX_FILE, listed) == \
        ["scan/acquire.py: 718 lines"]
    assert _over({"io/_long.py": 620, "io/new.py": 501}, MAX_FILE, listed) == \
        ["io/_long.py: 620 lines", "io/new.py: 501 lines"]
    # the ps_li_alternating modules are strict: a listing does not exempt them
    assert _over({"fit/_ps_li.py": 501, "fit/_ps_li_pixels.py": 501}, MAX_FILE, listed) == \
        ["fit/_ps_li.py: 501 lines", "fit/_ps_li_pixels.py: 501 lines"]
