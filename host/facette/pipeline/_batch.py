"""`batch`: many scans processed on a Dask cluster, with one summary table of every object.

Each scan is one task (`process_scan`) that writes OUT/<folder>/ (the files of `process`)
and OUT/<folder>/batch.json: the row of the summary, the fingerprint of its inputs and the
sha256 of every file it wrote. A scan's folder is its directory's name, or, when another scan
of that name already owns it (batch.json says whose), the name and a digest of the scan's
full path: unique, and the same on every run whatever the other scans. A scan is done when
its record says "ok", its fingerprint matches the scan as it is now (scan.json without the
HDR record processing adds, the sha256 of every file under hdr/, the RAW frames' sizes and
times, the outputs and options asked for, and facette's version; taken after processing, so
what processing itself writes never makes a scan look changed) and every file it wrote is
there with the same content: a rerun skips it. A scan that fails is reported in its row and
does not stop the others; the next run tries it again. The summary merges the rows of every
scan under OUT: a rerun on a subset keeps the others' rows.
"""
import csv
import hashlib
import html
import io
import json
import math
import os
import time
import traceback
from pathlib import Path

import facette
from facette.errors import BadInputError
from facette.io.atomic import write_text_atomic
from facette.io.checksum import sha256_file
from facette.pipeline._options import ProcessOptions
from facette.pipeline._process import process
from facette.pipeline._record import foreign_files, read_record
from facette.pipeline._scheduler import connect_scheduler

__all__ = ["batch", "process_scan", "input_fingerprint", "write_summary", "result_folders",
           "SUMMARY_COLUMNS", "RECORD"]

RECORD = "batch.json"
SUMMARY_COLUMNS = (
    "scan", "status", "error", "lights", "width", "height", "valid_pixels",
    "normal_median_deg", "normal_p95_deg", "height_rms_mm",
    "brdf_model", "kd_r", "kd_g", "kd_b", "sigma", "sigma_sd", "n_i", "n_i_sd", "brdf_relative_rms",
    "ptm_relative_rms", "hsh_relative_rms", "time_s", "results", "source")


def input_fingerprint(scan_dir, outputs, options):
    """What a scan's results depend on, as a dict that compares equal when nothing changed:
    scan.json without its "hdr" record (which processing writes), the sha256 of every file
    under hdr/, the RAW frames' (size, mtime), the outputs, the options and the facette version."""
    scan_dir = Path(scan_dir)
    if not (scan_dir / "scan.json").is_file():
        raise FileNotFoundError(f"{scan_dir} has no scan.json: not a facette scan directory")
    try:
        manifest = json.loads((scan_dir / "scan.json").read_text())
    except ValueError as exc:
        raise BadInputError(f"{scan_dir / 'scan.json'} is damaged ({exc})") from exc
    manifest.pop("hdr", None)
    hdr = scan_dir / "hdr"
    files = sorted(p for p in hdr.rglob("*") if p.is_file()) if hdr.is_dir() else []
    raw = []
    for f in manifest.get("frames", []):
        st = (scan_dir / f.get("file", "")).stat() if (scan_dir / f.get("file", "")).is_file() else None
        raw.append([f.get("file"), st.st_size if st else None, st.st_mtime_ns if st else None])
    return {"facette": facette.__version__,
            "scan.json": hashlib.sha256(json.dumps(manifest, sort_keys=True, default=str).encode()).hexdigest(),
            "raw": raw,
            "hdr": {str(p.relative_to(scan_dir)): sha256_file(p) for p in files},
            "outputs": list(outputs) if outputs is not None else None,
            "options": json.loads(json.dumps(options or {}, sort_keys=True, default=str))}


def _figures(res):
    """The summary row's figures of a ProcessResult."""
    h, w = res.normals.shape[:2]
    row = {"lights": len(res.inputs.light_dirs), "width": w, "height": h,
           "valid_pixels": int(res.mask.sum())}
    for k in ("normal_median_deg", "normal_p95_deg", "height_rms_mm"):
        row[k] = res.errors.get(k)
    fit = res.brdf
    if fit is not None:
        p, u = fit.params or {}, fit.uncertainties or {}
        row["brdf_model"] = fit.model if fit.success else f"{fit.model} (failed: {fit.message})"
        kd = list(p.get("kd", []))
        for c, v in zip(("kd_r", "kd_g", "kd_b"), kd):
            row[c] = v
        for k in ("sigma", "n_i"):
            if k in p:
                row[k] = p[k]
                row[f"{k}_sd"] = u.get(k)
        row["brdf_relative_rms"] = (fit.error or {}).get("relative_rms")
    row.update(res.fit_errors)
    return row


def _read_record(path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _written(out_dir):
    """{file name: sha256} of the files process.json says its run wrote into `out_dir`."""
    rec = read_record(out_dir) or {}
    return {name: sha256_file(out_dir / name) for name in rec.get("files", []) if (out_dir / name).is_file()}


def _intact(out_dir, record):
    """True when every file the recorded run wrote is in `out_dir` with the same content."""
    files = record.get("files")
    if not files:
        return False
    return all((out_dir / n).is_file() and sha256_file(out_dir / n) == h for n, h in files.items())


def process_scan(scan_dir, out_dir, outputs=None, options=None, force=False):
    """Process one scan into out_dir (a Dask task; also callable directly).

    Returns the summary row (dict with SUMMARY_COLUMNS keys that apply): status "ok",
    "skipped" (already done with the same inputs, its files intact) or "failed" (error says why).
    """
    scan_dir, out_dir = Path(scan_dir), Path(out_dir)
    row = {"scan": out_dir.name, "source": str(scan_dir), "results": str(out_dir)}
    t0 = time.perf_counter()
    files = {}
    try:
        fingerprint = input_fingerprint(scan_dir, outputs, options)
        record = _read_record(out_dir / RECORD)
        if (not force and record and record.get("row", {}).get("status") == "ok"
                and record.get("inputs") == fingerprint and _intact(out_dir, record)):
            return {**record["row"], "status": "skipped"}
        # the batch decides itself when a scan's row is redone (its inputs or options changed)
        res = process(scan_dir, outputs=outputs, out_dir=out_dir,
                      options=ProcessOptions(**{**(options or {}), "overwrite": True}))
        row.update(_figures(res), status="ok", error="")
        fingerprint = input_fingerprint(scan_dir, outputs, options)    # after what processing wrote
        files = _written(out_dir)
    except Exception as exc:   # one bad scan must not stop a collection: report it in its row
        error = f"{type(exc).__name__}: {exc}"
        if not isinstance(exc, (ValueError, OSError)):     # not a reported bad input: say where
            last = traceback.extract_tb(exc.__traceback__)[-1]
            error += f" ({Path(last.filename).name}:{last.lineno})"
        row.update(status="failed", error=error)
        fingerprint = None
    row["time_s"] = time.perf_counter() - t0
    out_dir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out_dir / RECORD, json.dumps({"inputs": fingerprint, "row": row, "files": files},
                                                   indent=1, default=str))
    return row


def _path_digest(path):
    return hashlib.sha256(str(Path(path).resolve()).encode()).hexdigest()[:8]


def result_folders(scans, out_dir):
    """One result folder name per scan, unique and stable: the scan directory's name when
    that folder under `out_dir` is free or already this scan's (its batch.json says so), else
    the name and a digest of the scan's full path ("object-1a2b3c4d")."""
    out_dir = Path(out_dir)
    taken, names = {}, []
    for s in scans:
        src = str(Path(s).resolve())
        base = Path(src).name or "scan"
        rec = _read_record(out_dir / base / RECORD) or {}
        owner = (rec.get("row") or {}).get("source")
        free = taken.get(base, src) == src and (owner is None or str(Path(owner).resolve()) == src)
        name = base if free else f"{base}-{_path_digest(src)}"
        if taken.get(name, src) != src:
            raise BadInputError(f"two scans would share the result folder {out_dir / name}: {taken[name]} and {src}",
                                hint="rename one of the scan folders")
        taken[name] = src
        names.append(name)
    return names


def _check_out(scans, out_dir, names):
    """Refuse an output folder inside a scan, or one whose result folders would be scans."""
    out = Path(out_dir).resolve()
    for s, n in zip(scans, names):
        src = Path(s).resolve()
        if out == src or src in out.parents:
            raise BadInputError(f"-o {out_dir} is inside the scan {s}: results would be written among its "
                                "files (facette never writes its inputs)",
                                hint="choose an output folder outside the scans")
        if (out / n).resolve() == src:
            raise BadInputError(f"-o {out_dir} would put {s}'s results into {s} itself (the scans' own folder)",
                                hint="choose an output folder beside the scans, e.g. "
                                     f"{src.parent.parent / 'results'}")


def _check_scans(scans):
    """Every scan given is a folder with scan.json (a pattern the shell found no match for comes
    as itself: 'scans/*'); BadInputError naming those that are not, before any folder is made."""
    bad = [s for s in scans if not (Path(s) / "scan.json").is_file()]
    if not bad:
        return
    globbed = [s for s in bad if any(c in str(s) for c in "*?[") and not Path(s).exists()]
    if globbed:
        raise BadInputError(f"no scan matches {globbed[0]} (the shell passed the pattern as it is)",
                            hint="check the pattern and the folder it looks in; give scan folders (scan.json, hdr/)")
    said = ", ".join(f"{s} ({'no such folder' if not Path(s).exists() else 'no scan.json'})" for s in bad[:4])
    raise BadInputError(f"{len(bad)} of {len(scans)} given are not facette scans: {said}",
                        hint="give scan folders (scan.json, hdr/); process a DiLiGenT folder or an RTI capture "
                             "with facette process")


def _check_foreign(out_dir, names, overwrite):
    """Refuse, unless `overwrite`, result folders holding files no facette run made (a user's
    normal.exr would be replaced), as `process` refuses such an -o folder (pipeline._record)."""
    if overwrite:
        return
    held = {n: foreign_files(Path(out_dir) / n) for n in names}
    held = {n: f for n, f in held.items() if f}
    if held:
        n, files = next(iter(held.items()))
        raise BadInputError(f"{Path(out_dir) / n} already holds files that no facette run recorded "
                            f"({', '.join(files[:4])}{'...' if len(files) > 4 else ''})"
                            + (f", and {len(held) - 1} other result folder(s)" if len(held) > 1 else ""),
                            hint="choose another -o folder, or pass --overwrite to write beside them")


def _merged_rows(out_dir, rows, names):
    """This run's rows, merged with those of the other scans under `out_dir` (their batch.json),
    in the previous summary's order, this run's new scans after."""
    out_dir = Path(out_dir)
    by_name = {}
    for rec_path in sorted(out_dir.glob(f"*/{RECORD}")):
        rec = _read_record(rec_path)
        if rec and isinstance(rec.get("row"), dict):
            by_name[rec_path.parent.name] = rec["row"]
    by_name.update(zip(names, rows))
    order = []
    if (out_dir / "summary.csv").is_file():
        with open(out_dir / "summary.csv", newline="") as fh:
            order = [r.get("scan") for r in csv.DictReader(fh)]
    order = [n for n in order if n in by_name]
    order += [n for n in names if n not in order] + sorted(n for n in by_name if n not in order and n not in names)
    return [by_name[n] for n in order]


def _fmt(v):
    """Numbers rounded for people: 3 significant digits, no exponent for ordinary sizes."""
    if isinstance(v, bool) or v is None:
        return "" if v is None else str(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return ""
        return f"{v:.3g}" if (v == 0 or 1e-3 <= abs(v) < 1e6) else f"{v:.2e}"
    return str(v)


def write_summary(rows, out_dir):
    """summary.csv (full precision) and summary.html (rounded) in out_dir. Returns both paths."""
    out_dir = Path(out_dir)
    cols = list(SUMMARY_COLUMNS) + sorted({k for r in rows for k in r} - set(SUMMARY_COLUMNS))
    csv_path, html_path = out_dir / "summary.csv", out_dir / "summary.html"
    text = io.StringIO(newline="")
    wr = csv.DictWriter(text, fieldnames=cols, extrasaction="ignore")
    wr.writeheader()
    for r in rows:
        wr.writerow({k: "" if r.get(k) is None else r.get(k) for k in cols})
    write_text_atomic(csv_path, text.getvalue())
    counts = {s: sum(r.get("status") == s for r in rows) for s in ("ok", "skipped", "failed")}
    head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = []
    for r in rows:
        cls = " class='failed'" if r.get("status") == "failed" else ""
        cells = []
        for c in cols:
            text = html.escape(_fmt(r.get(c)))
            if c == "results" and r.get("status") != "failed" and r.get(c):
                rel = os.path.relpath(Path(r[c]) / "report.html", out_dir)
                text = f"<a href='{html.escape(rel)}'>{text}</a>"
            cells.append(f"<td>{text}</td>")
        body.append(f"<tr{cls}>{''.join(cells)}</tr>")
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>facette batch summary</title>
<style>body{{font-family:sans-serif}} table{{border-collapse:collapse;font-size:13px}}
td,th{{border:1px solid #bbb;padding:3px 6px;text-align:right}} tr.failed{{background:#fdd}}
td:first-child,td:nth-child(2),td:nth-child(3){{text-align:left}}</style></head><body>
<h1>facette batch: {len(rows)} scans</h1>
<p>{counts['ok']} processed, {counts['skipped']} already done (inputs unchanged), {counts['failed']} failed.
Errors against truth are given where the scan carries truth (simulated scans); relative RMS values
are fractions.</p>
<table><tr>{head}</tr>
{chr(10).join(body)}
</table></body></html>
"""
    write_text_atomic(html_path, page)
    return csv_path, html_path


def batch(scans, out_dir, workers=2, scheduler=None, outputs=None, options=None, force=False,
          progress=True, overwrite=False):
    """Process many scans on Dask and write OUT/summary.csv and OUT/summary.html.

    scans : scan directories; out_dir : results go to out_dir/<folder>/ (`result_folders`);
        refused (BadInputError, before any task) when it is inside a scan or would be one.
    workers : local worker processes (one thread each) when no scheduler is given.
    scheduler : address of a running dask.distributed scheduler ("tcp://host:8786"); its
        workers must have facette installed and see the same paths.
    outputs, options : as `process` (outputs list; options: fields of ProcessOptions as a dict,
        which the rerun check fingerprints; checked here once, before any scan).
    force : reprocess scans even when done. progress : a progress bar on stderr.
    overwrite : write into result folders that hold files no facette run made (refused otherwise).
    Returns the rows (list of dicts, in the order of `scans`); summary.* holds them merged
    with the rows of the other scans under `out_dir`.
    """
    scans = [Path(s) for s in scans]
    if not scans:
        raise ValueError("no scans given: pass one or more scan directories")
    _check_scans(scans)
    if scheduler is None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if outputs is not None and not list(outputs):
        raise BadInputError("no outputs asked for (--outputs is empty): nothing would be written",
                            hint="name one or more outputs, or leave --outputs out for all")
    ProcessOptions(**(options or {}))        # a bad option fails here, not in every row
    out_dir = Path(out_dir)
    names = result_folders(scans, out_dir)
    _check_out(scans, out_dir, names)
    _check_foreign(out_dir, names, overwrite)
    # a deliberate lazy load: dask.distributed takes ~1 s to import, and `facette process`
    # (which imports this package) never needs it
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm import tqdm
    client = connect_scheduler(scheduler) if scheduler is not None else None     # within seconds, exit 2
    out_dir.mkdir(parents=True, exist_ok=True)
    cluster = None
    if scheduler is None:
        # the dashboard on any free port: two batches on one machine never collide on 8787
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0")
        client = Client(cluster)
    rows = [None] * len(scans)
    try:
        futures = {client.submit(process_scan, str(s.resolve()), str((out_dir / n).resolve()),
                                 outputs, options, force, key=f"facette-scan-{i}-{n}", pure=False): i
                   for i, (s, n) in enumerate(zip(scans, names))}
        bar = tqdm(total=len(futures), desc="scans", unit="scan", disable=not progress)
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                rows[i] = fut.result()
            except Exception as exc:      # the worker itself died (out of memory, crash)
                rows[i] = {"scan": names[i], "source": str(scans[i]), "status": "failed",
                           "error": f"worker lost: {type(exc).__name__}: {exc}"}
            bar.set_postfix_str(f"{names[i]}: {rows[i]['status']}")
            bar.update()
        bar.close()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    write_summary(_merged_rows(out_dir, rows, names), out_dir)
    return rows
