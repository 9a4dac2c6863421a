"""process.json: the record of the one run whose files a results folder holds.

It says which inputs (a digest of the scan's frames and their sha256, or of a DiLiGenT
folder's files) and which options made the files beside it. A second run into the same
folder with the same options redoes the files (and removes those of the earlier run that it
does not write again when the inputs changed: they no longer match); one with other options
is refused unless `overwrite`, so a folder never mixes the files of two runs unmarked.

The record is written twice: when the run claims the folder (``"state": "running"``, before
any file) and when it is done (``"state": "done"``). A folder whose record still says
"running" holds what an interrupted run left: a run of the same source replaces it without
`overwrite`, so an interrupted processing (a scan's own, Ctrl-C, a full disk) is redone by
the same command; a run of another source is refused as before. A run's inputs are never
written: an output folder that is the input folder is refused, whatever the options.

The same rule for every command (one owner, here): no command writes its input or a file it did
not make. `claim_results` is it for a results folder (`process`, and `batch` for each scan's
folder through `foreign_files`); `claim_file` for a single file (`relight`'s picture): never an
input, and an existing file only when facette made it (`made_by_facette`) or with --overwrite.
"""
import datetime as _dt
import json
from pathlib import Path

from facette.errors import BadInputError
from facette.io.atomic import PARTIAL_SUFFIX, write_text_atomic
from facette.io.png import read_png_text

__all__ = ["RECORD", "SOFTWARE", "claim_results", "claim_file", "foreign_files", "made_by_facette", "mark_running",
           "write_record", "read_record"]

RECORD = "process.json"
BESIDE = ("batch.json",)      # facette batch's own record of a scan's row, kept beside ours
SOFTWARE = "facette"          # the PNG text key "Software" of the pictures facette writes


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


def _results_beside(inp):
    """Where results of `inp` may go: a scan's own results folder (SCAN/results, as its own
    processing writes), beside any other input (a folder's files are left as they were)."""
    src = Path(inp.source)
    if inp.kind == "scan":
        return src / "results"
    folder = src.parent if src.is_file() else src
    return folder.parent / f"{folder.name}-results"


def _refuse_inputs(out, inp, mask=None):
    """An output folder must not be the input folder (a DiLiGenT folder's mask.png, a scan's
    scan.json would be replaced) nor hold the --mask file."""
    source = Path(inp.source).resolve()
    where = Path(out).resolve()
    if where == source or (source.is_file() and where == source.parent):
        raise BadInputError(f"-o {out} is the input folder {inp.source}: its files would be replaced by the "
                            "results (facette never writes its inputs)",
                            hint=f"choose another -o folder, e.g. {_results_beside(inp)}")
    if isinstance(mask, (str, Path)) and Path(mask).resolve().parent == where:
        raise BadInputError(f"-o {out} holds the --mask file {mask}, which the results' mask.png could replace",
                            hint="choose another -o folder, or keep the mask elsewhere")


def _interrupted(rec, out, same_source):
    """True when `rec` is the record of a run that never finished and its files may go."""
    if rec.get("state") != "running":
        return False
    return same_source or not any((out / f).is_file() for f in rec.get("files", []))


def _remove(out, names):
    for name in names:
        p = out / name
        if p.is_file() and p.parent == out:
            p.unlink()


def foreign_files(out):
    """The files in folder `out` that no facette run recorded (sorted names): all of them when it
    has no process.json, none when it has one (`claim_results` sorts those) or is absent."""
    out = Path(out)
    if not out.is_dir() or (out / RECORD).is_file():
        return []
    return sorted(p.name for p in out.iterdir()
                  if p.name not in BESIDE and not (p.name.startswith(".") and p.name.endswith(PARTIAL_SUFFIX)))


def made_by_facette(path):
    """True when `path` is a PNG that facette wrote (its "Software" text says so)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(8) != b"\x89PNG\r\n\x1a\n":
                return False
        return str(read_png_text(path).get("Software", "")).startswith(SOFTWARE)
    except (OSError, ValueError):
        return False


def claim_file(out, inputs, overwrite=False, flag="-o"):
    """Check, before any work, that a command may write the single file `out`: never one of
    `inputs` (whatever `overwrite`), never a folder, and a file that exists only when facette
    made it (`made_by_facette`) or with `overwrite`. BadInputError otherwise."""
    out = Path(out)
    for src in inputs:
        if out.resolve() == Path(src).resolve() or (out.exists() and out.samefile(src)):
            raise BadInputError(f"{flag} {out} is the input {src}: it would be replaced (facette never writes its inputs)",
                                hint=f"choose another {flag} file, e.g. {Path(src).with_suffix('.png')}")
    if out.is_dir():
        raise BadInputError(f"{flag} {out} is a folder", hint=f"give a file name for {flag}, e.g. {out / 'picture.png'}")
    if out.exists() and not overwrite and not made_by_facette(out):
        raise BadInputError(f"{flag} {out} already exists and facette did not make it",
                            hint=f"choose another {flag} file, or pass --overwrite to replace it")


def claim_results(out, options, inp, overwrite=False, names=(), mask=None):
    """Check, before any work, that this run may write into `out`; remove the earlier run's
    files that would otherwise stay beside this run's, and those of an interrupted run of the
    same source (`mark_running` then records this run, before its first file). Returns the
    earlier record or None.

    names : the file names a facette process run may write (what an interrupted run of the
        scan's own results folder may have left before records were written first).
    mask : the --mask path, refused as an output folder's file.
    """
    out = Path(out)
    _refuse_inputs(out, inp, mask)
    if not out.is_dir():
        return None
    try:
        rec = read_record(out)
    except BadInputError:
        if not overwrite:
            raise
        rec = None                   # --overwrite, as the hint says: the damaged record is replaced
    for p in out.glob(f".*{PARTIAL_SUFFIX}"):          # temporaries of an interrupted write
        if p.is_file():
            p.unlink()
    source = str(Path(inp.source).resolve())
    others = [p for p in out.iterdir() if p.name != RECORD and p.name not in BESIDE]
    if rec is None:
        own = out.resolve() == Path(source) / "results"
        if others and own and set(p.name for p in others) <= set(names):
            _remove(out, [p.name for p in others])    # the scan's own processing, interrupted
            return None
        if others and not overwrite:
            raise BadInputError(f"{out} already holds files that no facette process run recorded "
                                f"({', '.join(sorted(p.name for p in others)[:4])}...)",
                                hint="choose another -o folder, or pass --overwrite to write beside them")
        return None
    same_source = rec.get("source") == source
    if _interrupted(rec, out, same_source):
        _remove(out, set(rec.get("files", [])) | set(names))
        return None
    options = _plain(options)
    differ = sorted(k for k in set(options) | set(rec.get("options", {}))
                    if options.get(k) != rec.get("options", {}).get(k))
    if (differ or not same_source) and not overwrite:
        said = "; ".join(f"{k}: {rec.get('options', {}).get(k)} then, {options.get(k)} now" for k in differ[:4])
        if not same_source:
            said = "; ".join(filter(None, [f"source: {rec.get('source')} then, {inp.source} now", said]))
        raise BadInputError(f"{out} holds the results of another run ({said})",
                            hint="choose another -o folder, or pass --overwrite to replace them")
    if differ or not same_source or rec.get("inputs") != inp.digest:
        _remove(out, rec.get("files", []))             # derived from other inputs or options
    return rec


def mark_running(out, options, inp, names=()):
    """Record in `out` that a run of `inp` with `options` is writing `names` (before any file):
    if it is interrupted, the next run of the same source knows whose files these are."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rec = {"software": "facette", "state": "running", "source": str(Path(inp.source).resolve()),
           "kind": inp.kind, "inputs": inp.digest, "options": _plain(options), "files": sorted(set(names)),
           "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    write_text_atomic(out / RECORD, json.dumps(rec, indent=1) + "\n")
    return rec


def _written(out, names):
    """{file: when it was last written (UTC, ms)}: the maps come seconds before the report and model.glb."""
    return {name: _dt.datetime.fromtimestamp((out / name).stat().st_mtime, _dt.timezone.utc)
            .isoformat(timespec="milliseconds") for name in names if (out / name).exists()}


def write_record(out, options, inp, res, previous=None):
    """Write `out`/process.json for the run whose result is `res` (atomically)."""
    out = Path(out)
    rec = {"software": "facette", "state": "done", "source": str(Path(inp.source).resolve()), "kind": inp.kind,
           "inputs": inp.digest, "scan_incomplete": inp.incomplete or None, "options": _plain(options),
           "outputs": list(res.options.get("outputs", [])),
           "files": sorted(Path(p).name for p in res.files.values()),
           "quality": _plain(res.quality), "notes": list(res.notes),
           "ps_channels": _plain(res.ps.info.get("channels") if res.ps is not None else None),
           "light_gains": _plain(res.light_gains),
           "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    if previous and previous.get("inputs") == inp.digest and previous.get("options") == rec["options"]:
        # the same run with other outputs: its files stay valid beside these
        rec["files"] = sorted(set(rec["files"]) | {f for f in previous.get("files", []) if (out / f).is_file()})
        rec["outputs"] = sorted(set(rec["outputs"]) | set(previous.get("outputs", [])))
    rec["written"] = _written(out, rec["files"])
    write_text_atomic(out / RECORD, json.dumps(rec, indent=1) + "\n")
    return rec
