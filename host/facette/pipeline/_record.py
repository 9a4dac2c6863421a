"""process.json: the record of the one run whose files a results folder holds.

It says which inputs (a digest of the scan's frames and their sha256, or of a DiLiGenT
folder's files) and which options made the files beside it. A second run into the same
folder with the same options redoes the files (and removes those of the earlier run that it
does not write again when the inputs changed: they no longer match); one with other options
is refused unless `overwrite`, so a folder never mixes the files of two runs unmarked.
"""
import datetime as _dt
import json
import os
from pathlib import Path

from facette.errors import BadInputError

__all__ = ["RECORD", "claim_results", "write_record", "read_record"]

RECORD = "process.json"
BESIDE = ("batch.json",)      # facette batch's own record of a scan's row, kept beside ours


def _plain(obj):
    return json.loads(json.dumps(obj, default=str))


def read_record(out):
    """The record in results folder `out` (dict) or None."""
    p = Path(out) / RECORD
    if not p.is_file():
        return None
    try:
        rec = json.loads(p.read_text())
    except ValueError as exc:
        raise BadInputError(f"{p} is damaged ({exc})",
                            hint="pass --overwrite to replace the results, or choose another -o folder") from exc
    if not isinstance(rec, dict):
        raise BadInputError(f"{p} is damaged (not a record)", hint="pass --overwrite or choose another -o folder")
    return rec


def claim_results(out, options, inp, overwrite=False):
    """Check, before any work, that this run may write into `out`; remove the earlier run's
    files that would otherwise stay beside this run's. Returns the earlier record or None."""
    out = Path(out)
    if not out.is_dir():
        return None
    rec = read_record(out)
    others = [p for p in out.iterdir() if p.name != RECORD and p.name not in BESIDE]
    if rec is None:
        if others and not overwrite:
            raise BadInputError(f"{out} already holds files that no facette process run recorded "
                                f"({', '.join(sorted(p.name for p in others)[:4])}...)",
                                hint="choose another -o folder, or pass --overwrite to write beside them")
        return None
    options = _plain(options)
    differ = sorted(k for k in set(options) | set(rec.get("options", {}))
                    if options.get(k) != rec.get("options", {}).get(k))
    same_source = rec.get("source") == str(Path(inp.source).resolve())
    if (differ or not same_source) and not overwrite:
        said = "; ".join(f"{k}: {rec.get('options', {}).get(k)} then, {options.get(k)} now" for k in differ[:4])
        if not same_source:
            said = "; ".join(filter(None, [f"source: {rec.get('source')} then, {inp.source} now", said]))
        raise BadInputError(f"{out} holds the results of another run ({said})",
                            hint="choose another -o folder, or pass --overwrite to replace them")
    if differ or not same_source or rec.get("inputs") != inp.digest:
        for name in rec.get("files", []):          # derived from other inputs or options
            p = out / name
            if p.is_file() and p.parent == out:
                p.unlink()
    return rec


def write_record(out, options, inp, res, previous=None):
    """Write `out`/process.json for the run whose result is `res` (atomically)."""
    out = Path(out)
    rec = {"software": "facette", "source": str(Path(inp.source).resolve()), "kind": inp.kind, "inputs": inp.digest,
           "scan_incomplete": inp.incomplete or None, "options": _plain(options),
           "outputs": list(res.options.get("outputs", [])),
           "files": sorted(Path(p).name for p in res.files.values()),
           "quality": _plain(res.quality), "notes": list(res.notes),
           "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    if previous and previous.get("inputs") == inp.digest and previous.get("options") == rec["options"]:
        # the same run with other outputs: its files stay valid beside these
        rec["files"] = sorted(set(rec["files"]) | {f for f in previous.get("files", []) if (out / f).is_file()})
        rec["outputs"] = sorted(set(rec["outputs"]) | set(previous.get("outputs", [])))
    tmp = out / f".{RECORD}.partial"
    tmp.write_text(json.dumps(rec, indent=1) + "\n")
    os.replace(tmp, out / RECORD)
    return rec
