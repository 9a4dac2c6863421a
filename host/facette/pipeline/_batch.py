"""`batch`: many scans processed on a Dask cluster, with one summary table of every object.

Each scan is one task (`process_scan`) that writes OUT/<name>/ (the files of `process`)
and OUT/<name>/batch.json: the row of the summary and the fingerprint of its inputs. A scan
is done when that record says "ok" and its fingerprint matches the scan as it is now (the
sha256 of scan.json and of every file under hdr/, the outputs and options asked for, and
facette's version): a rerun skips it. A scan that fails is reported in its row and does not
stop the others; the next run tries it again.
"""
import csv
import html
import json
import math
import os
import time
import traceback
from pathlib import Path

import facette
from facette.io.checksum import sha256_file
from facette.pipeline._process import process

__all__ = ["batch", "process_scan", "input_fingerprint", "write_summary", "SUMMARY_COLUMNS",
           "RECORD"]

RECORD = "batch.json"
SUMMARY_COLUMNS = (
    "scan", "status", "error", "lights", "width", "height", "valid_pixels",
    "normal_median_deg", "normal_p95_deg", "height_rms_mm",
    "brdf_model", "kd_r", "kd_g", "kd_b", "sigma", "sigma_sd", "n_i", "n_i_sd", "brdf_relative_rms",
    "ptm_relative_rms", "hsh_relative_rms", "time_s", "results", "source")


def input_fingerprint(scan_dir, outputs, options):
    """What a scan's results depend on, as a dict that compares equal when nothing changed:
    sha256 of scan.json and of every file under hdr/, the outputs, the options and the
    facette version."""
    scan_dir = Path(scan_dir)
    if not (scan_dir / "scan.json").is_file():
        raise FileNotFoundError(f"{scan_dir} has no scan.json: not a facette scan directory")
    hdr = scan_dir / "hdr"
    files = sorted(p for p in hdr.rglob("*") if p.is_file()) if hdr.is_dir() else []
    return {"facette": facette.__version__, "scan.json": sha256_file(scan_dir / "scan.json"),
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


def process_scan(scan_dir, out_dir, outputs=None, options=None, force=False):
    """Process one scan into out_dir (a Dask task; also callable directly).

    Returns the summary row (dict with SUMMARY_COLUMNS keys that apply): status "ok",
    "skipped" (already done with the same inputs) or "failed" (error says why).
    """
    scan_dir, out_dir = Path(scan_dir), Path(out_dir)
    row = {"scan": out_dir.name, "source": str(scan_dir), "results": str(out_dir)}
    t0 = time.perf_counter()
    try:
        fingerprint = input_fingerprint(scan_dir, outputs, options)
        record = _read_record(out_dir / RECORD)
        if (not force and record and record.get("row", {}).get("status") == "ok"
                and record.get("inputs") == fingerprint):
            return {**record["row"], "status": "skipped"}
        # the batch decides itself when a scan's row is redone (its inputs or options changed)
        res = process(scan_dir, outputs=outputs, out_dir=out_dir, overwrite=True, **(options or {}))
        row.update(_figures(res), status="ok", error="")
    except Exception as exc:   # one bad scan must not stop a collection: report it in its row
        error = f"{type(exc).__name__}: {exc}"
        if not isinstance(exc, (ValueError, OSError)):     # not a reported bad input: say where
            last = traceback.extract_tb(exc.__traceback__)[-1]
            error += f" ({Path(last.filename).name}:{last.lineno})"
        row.update(status="failed", error=error)
        fingerprint = None
    row["time_s"] = time.perf_counter() - t0
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = out_dir / (RECORD + ".partial")
    tmp.write_text(json.dumps({"inputs": fingerprint, "row": row}, indent=1, default=str))
    tmp.replace(out_dir / RECORD)
    return row


def _names(scans):
    """One output folder name per scan: its directory name, made unique with -2, -3..."""
    seen, names = {}, []
    for s in scans:
        base = Path(s).resolve().name or "scan"
        seen[base] = seen.get(base, 0) + 1
        names.append(base if seen[base] == 1 else f"{base}-{seen[base]}")
    return names


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
    with open(csv_path.with_suffix(".csv.partial"), "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        wr.writeheader()
        for r in rows:
            wr.writerow({k: "" if r.get(k) is None else r.get(k) for k in cols})
    csv_path.with_suffix(".csv.partial").replace(csv_path)
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
    tmp = html_path.with_suffix(".html.partial")
    tmp.write_text(page)
    tmp.replace(html_path)
    return csv_path, html_path


def batch(scans, out_dir, workers=2, scheduler=None, outputs=None, options=None, force=False,
          progress=True):
    """Process many scans on Dask and write OUT/summary.csv and OUT/summary.html.

    scans : scan directories; out_dir : results go to out_dir/<scan name>/.
    workers : local worker processes (one thread each) when no scheduler is given.
    scheduler : address of a running dask.distributed scheduler ("tcp://host:8786"); its
        workers must have facette installed and see the same paths.
    outputs, options : as `process` (outputs list, keyword arguments).
    force : reprocess scans even when done. progress : a progress bar on stderr.
    Returns the rows (list of dicts, in the order of `scans`).
    """
    # a deliberate lazy load: dask.distributed takes ~1 s to import, and `facette process`
    # (which imports this package) never needs it
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm import tqdm

    scans = [Path(s) for s in scans]
    if not scans:
        raise ValueError("no scans given: pass one or more scan directories")
    if scheduler is None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = _names(scans)
    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
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
    write_summary(rows, out_dir)
    return rows
