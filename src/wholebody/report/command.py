"""``wholebody report --paper herzog2016|fahmi2019|all``: re-run the claims' experiments and
write the results tables (:mod:`wholebody.report.runner`).

Exit codes: 0 every run ran (whatever the verdicts); 1 at least one run raised (its claims have
the verdict ``error``) or a verdict could not be computed; 2 bad usage (unknown paper or claim
id, an output directory that cannot be written, docs without the report markers, Ray missing or
unreachable), found before anything runs; 130 interrupted (Ctrl-C; nothing is written but the
runs' own directories).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..sweep.executors import add_executor_options

EXIT_OK, EXIT_RUN_RAISED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130
DEFAULT_DOCS = Path("docs") / "results.md"


def add_parser(sub) -> argparse.ArgumentParser:
    """The ``report`` subcommand on the CLI's subparsers."""
    p = sub.add_parser("report", help="re-run the papers' experiments and write one results "
                                      "table per paper (claim, paper, ours, verdict, command)",
                       description="Run every distinct run of the selected claims and write "
                                   "OUT/results-PAPER.md, OUT/report.json and OUT/runs/*/.")
    p.add_argument("--paper", required=True, help="herzog2016, fahmi2019 or all")
    p.add_argument("--only", metavar="ID[,ID...]", help="only these claims (ids as in the table)")
    p.add_argument("--out", default="results/report",
                   help="output directory (default: results/report)")
    add_executor_options(p)
    p.add_argument("--realism", default="exact",
                   help="run every claim under real-robot conditions: exact (default), sensors "
                        "or robot (--set realism on each run; tables results-PAPER-LEVEL.md)")
    p.add_argument("--update-docs", action="store_true",
                   help="also rewrite the generated table of each paper in the docs file "
                        "(between its <!-- report:PAPER:begin/end --> markers)")
    p.add_argument("--docs", default=str(DEFAULT_DOCS),
                   help=f"the docs file --update-docs rewrites (default: {DEFAULT_DOCS})")
    p.set_defaults(func=command)
    return p


def _usage_error(message) -> int:
    print(f"wholebody: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def command(args) -> int:
    from ..outputs import prepare_output
    from ..sweep.executors import make_executor
    from . import runner
    from .claims import PAPERS, claims_for, select, under_conditions

    try:  # every usage error before anything runs
        only = [i.strip() for i in args.only.split(",") if i.strip()] if args.only else None
        if args.only is not None and not only:
            raise ValueError("--only: no claim id given")
        claims = under_conditions(select(args.paper, only), args.realism)
        docs = Path(args.docs)
        if args.update_docs:
            text = docs.read_text(encoding="utf-8")
            for paper in dict.fromkeys(c.paper for c in claims):
                runner.check_markers(text, runner.table_key(paper, args.realism))
    except (ValueError, OSError) as exc:
        return _usage_error(exc)
    out_dir = Path(args.out)
    try:
        prepare_output(out_dir)
    except OSError as exc:
        return _usage_error(f"--out {out_dir}: cannot write there ({exc.strerror or exc})")
    try:
        executor = make_executor(args.serial, args.workers, args.ray)
    except (ImportError, ConnectionError, ValueError) as exc:
        return _usage_error(exc)

    specs = runner.distinct_runs(claims)
    print(f"report: {len(claims)} claims, {len(specs)} runs ({executor.describe()}) into "
          f"{out_dir}", flush=True)
    done = []

    def progress(run_id: str, result: dict) -> None:
        done.append(run_id)
        state = ("raised: " + result["error"] if result["error"] is not None else
                 "success" if result["success"] else "criterion not met")
        print(f"  [{len(done)}/{len(specs)}] {run_id}: {state} ({result['wall_time_s']:.0f} s)",
              flush=True)

    try:
        report = runner.run_report(claims, executor, out_dir, progress)
    except KeyboardInterrupt:
        print(f"wholebody: report interrupted after {len(done)} of {len(specs)} runs",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    paths = runner.write_outputs(report, out_dir, args.realism)
    for row in report.rows:
        print(f"  {row.claim.id}: {row.verdict} — {row.ours}")
    if args.update_docs:
        for paper in report.papers():
            order = [c.id for c in claims_for(paper)]
            runner.update_docs(docs, paper, report.rows, order, args.realism)
        print(f"updated {docs} ({', '.join(PAPERS[p] for p in report.papers())})")
    print(f"report: {len(specs)} runs in {report.wall_time_s:.0f} s, {report.errors} errors; "
          f"wrote {', '.join(str(p) for p in paths)}")
    return EXIT_RUN_RAISED if report.errors else EXIT_OK
