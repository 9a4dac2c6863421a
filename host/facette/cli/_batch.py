"""`facette batch SCAN... -o OUT`: process a collection of scans on Dask, one summary table.

    facette batch scans/* -o out/collection                 # a local cluster, 2 workers
    facette batch scans/* -o out/collection --workers 8
    facette batch scans/* -o out/collection --scheduler tcp://10.0.0.5:8786

A rerun skips the scans whose results were made from the same inputs (and options) and are
still intact; a scan that fails is reported in its row (OUT/summary.csv, OUT/summary.html) and
tried again next time. The options are checked as `facette process` checks them, before any
worker starts (exit 2).
"""
import argparse
import sys


def register(sub):
    from facette.cli._process import PROCESS_FIT_OPTIONS, _number, _outputs, _scheduler, brdf_model_choices
    from facette.pipeline import OUTPUTS
    p = sub.add_parser("batch", help="process many scans on Dask, with one summary table",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scans", nargs="+", help="scan directories (scan.json, hdr/)")
    p.add_argument("-o", "--out", required=True, help="output directory: OUT/<scan>/ and OUT/summary.*")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_number(int, 1, 256, what="--workers"), default=2,
                       help="local worker processes, 1-256 (default 2)")
    where.add_argument("--scheduler", metavar="ADDRESS", type=_scheduler,
                       help="a running dask.distributed scheduler, e.g. tcp://host:8786 (its workers "
                            "need facette installed and the same paths)")
    p.add_argument("--outputs", type=_outputs, default=list(OUTPUTS),
                   help=f"comma-separated subset of {','.join(OUTPUTS)} (default: all)")
    p.add_argument("--brdf-model", default=PROCESS_FIT_OPTIONS["model"], choices=brdf_model_choices(),
                   help="model fitted for brdf.json (see facette process)")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="process scans that are not complete (every output then says so)")
    p.add_argument("--force", action="store_true", help="reprocess scans that are already done")
    p.add_argument("--overwrite", action="store_true",
                   help="write into result folders OUT/<scan> that hold files no facette run made")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def run(args):
    from facette.cli._process import _check_out
    from facette.errors import FacetteError
    from facette.pipeline import batch
    _check_out(args.out)
    options = {"fit_options": {"model": args.brdf_model}}
    if args.allow_incomplete:
        options["allow_incomplete"] = True
    try:
        rows = batch(args.scans, args.out, workers=args.workers, scheduler=args.scheduler,
                     outputs=args.outputs, options=options, force=args.force, progress=not args.quiet,
                     overwrite=args.overwrite)
    except FacetteError:
        raise                     # its message and hint, with its exit code (facette.cli.main)
    except (ValueError, OSError) as exc:
        print(f"facette batch: {exc}", file=sys.stderr)
        return 2
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "skipped", "failed")}
    print(f"{len(rows)} scans: {counts['ok']} processed, {counts['skipped']} already done, "
          f"{counts['failed']} failed")
    for r in rows:
        if r["status"] == "failed":
            print(f"  failed: {r['scan']}: {r['error']}", file=sys.stderr)
    print(f"summary: {args.out}/summary.csv, {args.out}/summary.html")
    return 1 if counts["failed"] else 0
