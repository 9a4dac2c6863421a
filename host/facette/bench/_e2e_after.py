"""Where the seconds after the last frame go, in one run of the one-button scan (`bench e2e`).

From what the run leaves behind, no wrapper and no second run: the journal (the last frame, the last
light's merge stored), the stage times the scan command prints (`times: load 0.53 s, ...`: each
stage's wall seconds in `process`) and process.json's `written` (when each result file was last
written). `timeline(scan_dir, stdout)` gives the events in the order they happened, in wall seconds
after the last frame; `timeline_line` prints them as one line per run, beside the run's table row.
On a loaded machine wall seconds stretch with the load (the CPU seconds after the last frame do
not): read this line for the order and the shares, the table's CPU column for the cost.
"""
import datetime as _dt
import json
import re

__all__ = ["timeline", "timeline_line", "stage_times"]

# process's timings that say where the time went, in the order they happen (others are printed after)
ORDER = ("load", "light_gains", "shadows", "ps", "uncertainty", "after_ps", "total_compute", "write")


def stage_times(stdout):
    """{stage: wall s} of the `times:` line `facette process` (and the scan command) prints; {} if none."""
    m = re.search(r"times: (.*)", stdout or "")
    return {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+) s", m.group(1))} if m else {}


def _journal(scan_dir):
    out = []
    for line in (scan_dir / "journal.jsonl").read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:          # a line cut by a crash
            continue
    return out


def timeline(scan_dir, stdout, results="results"):
    """{"merged": s, "stages": {stage: wall s}, "written": [(file, s)]}: seconds after the scan's last
    frame when its last light's merge was stored (NaN when the journal has none after it), each
    stage's wall seconds as printed, and when each result file was written (process.json's
    `written`, in order)."""
    journal = _journal(scan_dir)
    frames = [e for e in journal if e.get("step") == "captured"]
    last = _dt.datetime.fromisoformat(frames[-1]["t"]) if frames else None
    merged = [e for e in journal if e.get("step") == "hdr_light"]

    def after(iso):
        return (_dt.datetime.fromisoformat(iso) - last).total_seconds() if last else float("nan")
    merged_s = after(merged[-1]["t"]) if merged else float("nan")
    record = scan_dir / results / "process.json"
    written = json.loads(record.read_text()).get("written", {}) if record.is_file() else {}
    files = sorted(((name, after(t)) for name, t in written.items()), key=lambda kv: kv[1])
    if record.is_file() and last is not None:
        files.append(("process.json", record.stat().st_mtime - last.timestamp()))
    return {"merged": merged_s, "stages": stage_times(stdout), "written": files}


def timeline_line(t):
    """One line: the last light's merge, the stages' wall seconds, the files' times, after the last frame."""
    stages = t["stages"]
    named = [k for k in ORDER if k in stages] + sorted(k for k in stages if k not in ORDER)
    return ("after the last frame (wall s): last light's merge stored +{:.2f}; stages: {}; files written: {}".format(
        t["merged"], ", ".join(f"{k} {stages[k]:.2f}" for k in named) or "-",
        ", ".join(f"{name} +{s:.2f}" for name, s in t["written"]) or "-"))
