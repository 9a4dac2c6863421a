"""The benchmarks page, written from the benchmarks' own output (`make bench`: `facette bench all`).

`run_teed` runs one benchmark with its printed output copied to a buffer; `write_page` turns the
outputs of a whole run into docs/benchmarks.md: the date and the machine, the DiLiGenT tables
parsed from `facette bench diligent` beside the published methods (`bench.diligent.PUBLISHED_LS`
and `PUBLISHED_OTHERS`), a plot of mean error against run time, and each benchmark's output, its
sections as printed. Nothing on the page is typed by hand: a figure the run did not print is not
there.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import io
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

from facette.bench.diligent import PUBLISHED_LS, PUBLISHED_OTHERS

PAPER_OBJECTS = ("ball", "cat", "pot2", "buddha", "reading")     # the order of PUBLISHED_OTHERS
TABLE_TITLE = re.compile(r"^-- DiLiGenT, (.*?): mean / median angular error")
CELL = re.compile(r"^\s*([\d.]+|nan)\s+([\d.]+|nan)\s+([\d.]+)s\s*$")


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for stream in self.streams:
            stream.write(text)
        return len(text)

    def flush(self):
        for stream in self.streams:
            stream.flush()


def run_teed(fn):
    """(fn()'s status as int, what it printed to stdout, seconds): the output still shows."""
    buf = io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(_Tee(sys.stdout, buf)):
        status = int(fn() or 0)
    return status, buf.getvalue(), time.perf_counter() - t0


def machine():
    """What the figures were measured on: CPU, cores, memory, OS, Python, the code's commit."""
    cpu = platform.processor() or platform.machine()
    try:
        info = Path("/proc/cpuinfo").read_text()
        cpu = next((line.split(":", 1)[1].strip() for line in info.splitlines() if line.startswith("model name")), cpu)
        mem_kb = int(next(line.split()[1] for line in Path("/proc/meminfo").read_text().splitlines()
                          if line.startswith("MemTotal")))
        memory = f"{mem_kb / 1024 ** 2:.1f} GiB"
    except (OSError, StopIteration, ValueError):
        memory = "unknown"
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(__file__).parent,
                                capture_output=True, text=True, timeout=10).stdout.strip() or "unknown"
    except OSError:
        commit = "unknown"
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return {"cpu": cpu, "cores": os.cpu_count(), "memory": memory, "system": platform.platform(),
            "python": platform.python_version(), "commit": commit, "load": load}


def diligent_tables(text):
    """The DiLiGenT tables `facette bench diligent` printed: [(label, methods, {row: [(mean, median,
    seconds)] per method})]."""
    tables, lines = [], text.splitlines()
    for i, line in enumerate(lines):
        title = TABLE_TITLE.match(line)
        if not title or i + 1 >= len(lines):
            continue
        methods = [m.strip() for m in lines[i + 1].split("|")[1:]]
        rows = {}
        for row in lines[i + 2:]:
            parts = row.split("|")
            if len(parts) != len(methods) + 1:
                break
            cells = [CELL.match(p) for p in parts[1:]]
            if not all(cells):
                break
            key = re.sub(r"(\s+[\d.]+|\s+nan){1,2}\s*$", "", parts[0]).strip()
            rows[key] = [tuple(float(x) for x in c.groups()) for c in cells]
        tables.append((title.group(1), methods, rows))
    return tables


def _object(key):
    """'diligent_crop8/cat 8-bit' -> 'cat'."""
    return key.split("/")[-1].split(" ")[0]


def _paper_table(label, methods, rows):
    group = max({k.split("/")[0] for k in rows if "/" in k},
                key=lambda g: sum(1 for k in rows if k.startswith(g + "/") and _object(k) in PAPER_OBJECTS),
                default=None)
    if group is None:
        return []
    ours = {_object(k): v for k, v in rows.items() if k.startswith(group + "/")}
    head = ["object"] + [f"{m} (facette)" for m in methods] + ["least squares (pub.)"] + list(PUBLISHED_OTHERS)
    out = [f"Mean angular error (°) on `{group}`, {label}, beside the figures published for the full "
           "16-bit DiLiGenT images under all 96 lights (Shi et al.'s benchmark table): the inputs are "
           "not the same, so read the columns as an order of magnitude, not a ranking.", "",
           "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for j, name in enumerate(PAPER_OBJECTS):
        if name not in ours:
            continue
        cells = [f"{c[0]:.2f}" for c in ours[name]] + [f"{PUBLISHED_LS[name]:.2f}"]
        cells += [f"{v[j]:.2f}" for v in PUBLISHED_OTHERS.values()]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return out


def _plot(tables, path):
    """Mean error against total run time per method, one series per table ('mean' rows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6))
    drawn = False
    for label, methods, rows in tables:
        means = [v for k, v in rows.items() if k.startswith("mean ")]
        if not means:
            continue
        marker = "o" if "all" in label else "s"
        ax.scatter([], [], color="grey", marker=marker, label=label)
        for j, method in enumerate(methods):
            err, secs = means[0][j][0], means[0][j][2]
            ax.scatter(secs, err, color=f"C{j}", marker=marker)
            ax.annotate(method, (secs, err), fontsize=7, xytext=(4, 2), textcoords="offset points")
            drawn = True
    if not drawn:
        plt.close(fig)
        return False
    ax.set_xscale("log")
    ax.legend(fontsize=7)
    ax.set_xlabel("run time over the objects (s)")
    ax.set_ylabel("mean angular error (°)")
    ax.set_title("DiLiGenT: error against run time", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return True


def _sections(text):
    """A benchmark's output cut at its '-- title' lines: [(title, lines)]."""
    sections, title, body = [], "", []
    for line in text.splitlines():
        if line.startswith("-- "):
            if any(b.strip() for b in body):
                sections.append((title, body))
            title, body = line[3:].strip(), []
        else:
            body.append(line)
    if any(b.strip() for b in body):
        sections.append((title, body))
    return sections


def render(outputs, when, where, image=None):
    """The page's Markdown. outputs: {bench name: (status, printed text, seconds)}."""
    out = ["# Benchmarks", "",
           f"Written by `make bench` (`facette bench all`) on {when:%Y-%m-%d %H:%M} UTC from the benchmarks' "
           "own output: run it again to measure this machine. Each benchmark prints error and run time "
           "side by side; its output follows, section by section, as printed.", "",
           "| machine | |", "| --- | --- |"]
    out += [f"| {k} | {v:.1f} (1-minute load average at the start)" + " |" if k == "load" else f"| {k} | {v} |"
            for k, v in where.items()]
    tables = diligent_tables(outputs.get("diligent", (0, "", 0))[1])
    if tables:
        out += ["", "## DiLiGenT beside the published methods", ""]
        best = next((t for t in tables if "all" in t[0]), tables[0])
        out += _paper_table(*best)
        if image:
            out += ["", f"![Mean error against run time on DiLiGenT]({image})"]
    out += ["", "## Each benchmark", "", "| benchmark | exit | run time |", "| --- | --- | --- |"]
    out += [f"| [`{name}`](#{name}) | {status} | {secs:.0f} s |" for name, (status, _, secs) in outputs.items()]
    for name, (status, text, secs) in outputs.items():
        out += ["", f"### {name}", "", f"`facette bench {name}`: exit {status}, {secs:.0f} s."]
        for title, body in _sections(text):
            if title:
                out += ["", f"**{title}**"]
            out += ["", "```text", *[b.rstrip() for b in body if b.strip() or True], "```"]
    return "\n".join(out).rstrip() + "\n"


def docs_dir():
    """docs/ of the source tree this package runs from, or the working directory."""
    here = Path(__file__).resolve().parents[3] / "docs"
    return here if here.is_dir() else Path.cwd()


def write_page(outputs, path=None):
    """Write the page (and its plot beside it, img/bench/); returns its path."""
    path = Path(path) if path else docs_dir() / "benchmarks.md"
    image = "img/bench/diligent-error-time.png"
    drawn = _plot(diligent_tables(outputs.get("diligent", (0, "", 0))[1]), path.parent / image)
    text = render(outputs, _dt.datetime.now(_dt.timezone.utc), machine(), image if drawn else None)
    path.write_text(text, encoding="utf-8")
    return path
