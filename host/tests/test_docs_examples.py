"""The documentation's examples run: every ```python and ```sh block of README.md and docs/ is
executed, page by page in a fresh folder holding the generated inputs the pages name (`capture/`,
an RTI capture of JPEGs and an .lp; `folder/`, a DiLiGenT-style folder: tools/docs/sample_data.py),
with `facette` on the PATH. A block can be marked by an HTML comment on the line before it:

    <!-- docs-example: sim (why) -->              needs the simulated rig (make docs runs those steps)
    <!-- docs-example: skip (why) -->             needs a rig, a camera, or runs until stopped
    <!-- docs-example: requires-output NAME -->   runs once `facette process --outputs NAME` exists
    <!-- docs-example: cheap (why) -->            runs (a note for the reader of the source)

A block that is not run still has each of its `facette ...` lines parsed by facette's own argument
parser, and its Python compiled, so that a renamed option or command fails here too."""
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools" / "docs"))

import figures  # noqa: E402  (tools/docs, on the path above)
import sample_data  # noqa: E402

FENCE = re.compile(r"^```(\w+)?")
MARK = re.compile(r"<!--\s*docs-example:\s*([\w-]+)\s*(.*?)\s*-->")
RUNNABLE = {"python": "python", "py": "python", "sh": "sh", "bash": "sh", "shell": "sh"}


@dataclass
class Example:
    page: str
    line: int
    lang: str
    code: str
    mark: str = ""
    arg: str = ""


def pages():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))


def examples(path):
    """The runnable-language fenced blocks of one Markdown file, with their marks."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found, i = [], 0
    while i < len(lines):
        fence = FENCE.match(lines[i])
        if not fence:
            i += 1
            continue
        start, body = i, []
        i += 1
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        i += 1
        lang = RUNNABLE.get(fence.group(1) or "")
        if lang is None:
            continue
        prev = next((lines[j] for j in range(start - 1, -1, -1) if lines[j].strip()), "")
        mark = MARK.search(prev)
        found.append(Example(str(path.relative_to(ROOT)), start + 1, lang, "\n".join(body) + "\n",
                             *(mark.groups() if mark else ("", ""))))
    return found


ALL = [ex for p in pages() for ex in examples(p)]
RUN_PAGES = sorted({ex.page for ex in ALL if ex.mark in ("", "cheap", "requires-output")})


def _facette_lines(code):
    """The `facette ...` commands of a shell block, as argument lists (continuations joined)."""
    code = code.replace("\\\n", " ")
    out = []
    for line in code.splitlines():
        line = line.split(" #")[0].strip()
        if line.startswith("facette "):
            words = shlex.split(line.split("||")[0].split("&&")[0])
            out.append(words[1:])
    return out


@pytest.mark.parametrize("ex", ALL, ids=lambda ex: f"{ex.page}:{ex.line}")
def test_every_example_parses(ex):
    """Each command in the docs is one facette's parser accepts; each Python block compiles."""
    from facette.cli.main import COMMANDS, build_parser

    assert ex.mark in ("", "cheap", "sim", "skip", "requires-output"), f"unknown mark {ex.mark!r}"
    if ex.lang == "python":
        compile(ex.code, f"{ex.page}:{ex.line}", "exec")
        return
    for argv in _facette_lines(ex.code):
        assert argv and argv[0] in COMMANDS, f"{ex.page}:{ex.line}: no command {argv[:1]}"
        if ex.mark == "requires-output" and not _known_output(ex.arg):
            with pytest.raises(SystemExit) as refused:     # not there yet: refused as bad input
                build_parser(argv[0]).parse_args(argv)
            assert refused.value.code == 2
            continue
        build_parser(argv[0]).parse_args(argv)          # exits 2 on an unknown option


@pytest.fixture(scope="session")
def inputs(tmp_path_factory):
    """The generated inputs the pages name, made once."""
    base = tmp_path_factory.mktemp("doc-inputs")
    sample_data.rti_capture(base / "capture")
    sample_data.diligent_folder(base / "folder")
    return base


def _sandbox(tmp_path, inputs):
    for name in ("capture", "folder"):
        shutil.copytree(inputs / name, tmp_path / name)
    bindir = tmp_path / ".bin"
    bindir.mkdir()
    shim = bindir / "facette"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m facette.cli.main "$@"\n')
    shim.chmod(0o755)
    env = dict(os.environ, PATH=f"{bindir}{os.pathsep}{os.environ['PATH']}",
               PYTHONPATH=str(ROOT / "host") + os.pathsep + os.environ.get("PYTHONPATH", ""),
               MPLBACKEND="Agg")
    return env


def _known_output(name):
    from facette.pipeline._process import STAGES_FOR

    return name.replace("-", "_") in {o.replace("-", "_") for o in STAGES_FOR}


def _run(ex, cwd, env):
    if ex.lang == "python":
        cmd = [sys.executable, "-c", ex.code]
    else:
        cmd = ["bash", "-e", "-o", "pipefail", "-c", ex.code]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN_PAGES)
def test_page_examples_run(page, tmp_path, inputs):
    """Every runnable block of one page, in order, in one folder: none fails."""
    env = _sandbox(tmp_path, inputs)
    ran = 0
    for ex in (ex for ex in ALL if ex.page == page):
        if ex.mark in ("sim", "skip"):
            continue
        if ex.mark == "requires-output" and not _known_output(ex.arg):
            # not there yet: facette must refuse it as an unknown output (exit 2), not do something else
            done = _run(ex, tmp_path, env)
            assert done.returncode == 2 and ex.arg in done.stderr, \
                f"{ex.page}:{ex.line}: output {ex.arg!r} is neither known nor refused\n{done.stderr[-2000:]}"
            continue
        done = _run(ex, tmp_path, env)
        assert done.returncode == 0, (f"{ex.page}:{ex.line} failed (exit {done.returncode}):\n{ex.code}\n"
                                      f"--- stdout\n{done.stdout[-2000:]}\n--- stderr\n{done.stderr[-3000:]}")
        ran += 1
    assert ran or any(ex.mark == "requires-output" for ex in ALL if ex.page == page)


def test_marks_are_explained_and_sim_steps_are_few():
    """A block left out says why; most blocks run."""
    left_out = [ex for ex in ALL if ex.mark in ("sim", "skip")]
    assert all(ex.arg.startswith("(") for ex in left_out), [f"{ex.page}:{ex.line}" for ex in left_out if not ex.arg]
    assert len([ex for ex in ALL if ex.mark in ("", "cheap")]) >= len(left_out)


def test_the_steps_make_docs_runs_for_the_pictures_are_the_pages_own():
    """The simulated-rig steps are not run here; tools/docs/figures.py runs them at `make docs`,
    word for word as their pages show them (in blocks marked sim)."""
    for page, line in figures.STEPS.values():
        shown = [ex for ex in ALL if ex.page == f"docs/{page}" and ex.mark == "sim"]
        assert any(f"facette {line}\n" in ex.code for ex in shown), (page, line)


def test_readme_links_point_at_files():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    missing = [link for link in links if "://" not in link and not (ROOT / link).exists()]
    assert links and not missing, missing
    assert "make test" in text and "make scan" in text
    assert len(text.splitlines()) <= 150
