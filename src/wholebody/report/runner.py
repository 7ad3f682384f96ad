"""``wholebody report``: re-run the papers' experiments and write one results table per paper.

The distinct runs of the selected claims (:mod:`wholebody.report.claims`) go through the sweep
machinery (:func:`wholebody.sweep.worker.run_one` on a :mod:`wholebody.sweep.executors` executor:
serial, a local process pool or Ray), each into ``OUT/runs/<run id>/`` (summary.json and
figures). Each claim's function then turns its run's summary into (our value, verdict); a run
that raised gives its claims the verdict ``error`` with the reason. Written: ``OUT/results-<paper>.md``
(claim | paper | ours | verdict | command) and ``OUT/report.json``; :func:`update_docs` puts a
paper's table between the ``<!-- report:PAPER:begin -->`` / ``<!-- report:PAPER:end -->``
markers of docs/results.md.
"""

from __future__ import annotations

import json
import logging
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..sweep.executors import Executor
from ..sweep.grid import SweepRun
from ..sweep.worker import run_one
from .claims import ERROR, MET, NOT_REPRODUCED, PAPERS, REPRODUCED, Claim, RunSpec, claims_for

log = logging.getLogger(__name__)

HEADER = ("| claim | paper | ours | verdict | command |\n"
          "|-------|-------|------|---------|---------|\n")


@dataclass
class Row:
    """One claim's line of the table."""

    claim: Claim
    ours: str
    verdict: str
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        c = self.claim
        return {"id": c.id, "paper": c.paper, "where": c.where, "claim": c.claim,
                "paper_value": c.paper_value, "ours": self.ours, "verdict": self.verdict,
                "error": self.error, "run": c.run.id, "command": c.run.command()}


def distinct_runs(claims: tuple[Claim, ...] | list[Claim]) -> list[RunSpec]:
    """The runs of ``claims``, each once, in the order of their first claim."""
    return list(dict.fromkeys(c.run for c in claims))


def sweep_runs(specs: list[RunSpec], out_dir: Path) -> list[SweepRun]:
    """The :class:`SweepRun` of each spec, writing into ``out_dir/runs/<id>`` (absolute)."""
    from ..scenarios import SCENARIOS

    runs = []
    for i, spec in enumerate(specs):
        scenario = SCENARIOS.get(spec.scenario)
        robot = spec.robot or (scenario.default_robot if scenario else "")
        controller = spec.controller or (scenario.controllers[0] if scenario else "")
        runs.append(SweepRun(i, spec.scenario, robot, controller, spec.overrides,
                             out_dir=str((out_dir / "runs" / spec.id).resolve())))
    return runs


def judge(claim: Claim, result: dict) -> Row:
    """The row of ``claim`` from its run's :func:`run_one` row."""
    if result.get("error") is not None:
        return Row(claim, f"run failed: {result['error']}", ERROR, result["error"])
    summary = result.get("summary")
    if summary is None:  # diverged: a run that ended in a failure, no metrics
        diverged = result["metrics"].get("diverged_at_s")
        return Row(claim, f"the simulation diverged at {diverged:.2f} s"
                   if diverged is not None else "no summary", NOT_REPRODUCED)
    try:
        ours, verdict = claim.evaluate(summary)
    except Exception as exc:  # noqa: BLE001 - a broken verdict function is one error row
        reason = f"verdict of {claim.id}: {type(exc).__name__}: {exc}"
        log.debug("%s", reason, exc_info=True)
        return Row(claim, reason, ERROR, reason)
    return Row(claim, ours, verdict)


@dataclass
class Report:
    """What :func:`run_report` produced."""

    rows: list[Row]
    runs: list[dict]  # per distinct run: id, command, success, error, wall_time_s
    executor: str
    wall_time_s: float

    @property
    def errors(self) -> int:
        """Runs that raised, plus claims whose verdict function raised on a completed run."""
        failed = {r["id"] for r in self.runs if r["error"] is not None}
        return len(failed) + sum(row.verdict == ERROR and row.claim.run.id not in failed
                                 for row in self.rows)

    def papers(self) -> list[str]:
        return list(dict.fromkeys(r.claim.paper for r in self.rows))


def run_report(claims: tuple[Claim, ...] | list[Claim], executor: Executor, out_dir: Path,
               progress: Callable[[str, dict], None] | None = None) -> Report:
    """Run the distinct runs of ``claims`` on ``executor`` into ``out_dir/runs/`` and judge every
    claim; ``progress(run id, result row)`` as each run completes."""
    specs = distinct_runs(claims)
    jobs = sweep_runs(specs, out_dir)
    results: list[dict | None] = [None] * len(jobs)
    start = time.perf_counter()
    with executor:
        for i, result in executor.map(run_one, jobs):
            results[i] = result
            _write_summary(Path(jobs[i].out_dir), result)
            if progress is not None:
                progress(specs[i].id, result)
    by_spec = dict(zip(specs, results))
    rows = [judge(c, by_spec[c.run]) for c in claims]
    runs = [{"id": s.id, "command": s.command(), "success": r["success"], "error": r["error"],
             "wall_time_s": round(r["wall_time_s"], 3)} for s, r in zip(specs, results)]
    return Report(rows, runs, executor.describe(), time.perf_counter() - start)


def _write_summary(out_dir: Path, result: dict) -> None:
    """``out_dir/summary.json`` from the result (the run wrote it where it ran: on a Ray cluster
    that may be another machine), or ``error.txt`` for a run that raised."""
    out_dir.mkdir(parents=True, exist_ok=True)
    if result.get("summary") is not None:
        (out_dir / "summary.json").write_text(json.dumps(result["summary"], indent=2) + "\n")
    elif result.get("error") is not None:
        (out_dir / "error.txt").write_text(result["error"] + "\n")


# ---------------------------------------------------------------------------- the table
def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def table(rows: list[Row]) -> str:
    """The markdown table of ``rows``: claim (with its id and where in the paper) | paper | ours
    | verdict | command; claims placed in a table by robot (``Claim.cell``) as :func:`grid`."""
    if rows and all(r.claim.cell is not None for r in rows):
        return grid({r.claim.cell: grid_cell(r) for r in rows},
                    {r.claim.cell[0]: r.claim.run.command() for r in rows})
    lines = [HEADER]
    for row in rows:
        c = row.claim
        lines.append(f"| `{c.id}` {_cell(c.claim)} ({_cell(c.where)}) | {_cell(c.paper_value)} | "
                     f"{_cell(row.ours)} | {row.verdict} | `{c.run.command()}` |\n")
    return "".join(lines)


def grid_cell(row: Row) -> str:
    """One cell of a table by robot: the verdict (a miss in bold) and our value."""
    verdict = f"**{row.verdict}**" if row.verdict not in (REPRODUCED, MET) else row.verdict
    return f"{verdict}: {_cell(row.ours)}"


def grid(cells: dict[tuple[str, str], str], commands: dict[str, str]) -> str:
    """A table by robot: one line per row label (the order of first appearance), one column per
    column label, then the row's command; a missing cell is empty."""
    rows = list(dict.fromkeys(r for r, _ in cells))
    columns = list(dict.fromkeys(c for _, c in cells))
    lines = ["| robot | " + " | ".join(columns) + " | command |\n",
             "|---" * (len(columns) + 2) + "|\n"]
    for r in rows:
        lines.append(f"| {r} | " + " | ".join(cells.get((r, c), "") for c in columns)
                     + f" | `{commands.get(r, '')}` |\n")
    return "".join(lines)


def _grid_cells(text: str) -> tuple[dict[tuple[str, str], str], dict[str, str]]:
    """The cells and commands of a table written by :func:`grid` (nothing if ``text`` has none)."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    if len(lines) < 2 or not lines[0].startswith("| robot |"):
        return {}, {}
    columns = [c.strip() for c in lines[0].strip().strip("|").split(" | ")][1:-1]
    cells, commands = {}, {}
    for line in lines[2:]:
        values = [c.strip() for c in line.strip()[1:-1].split(" | ")]
        if len(values) != len(columns) + 2:
            continue
        commands[values[0]] = values[-1].strip("`")
        cells.update({(values[0], c): v for c, v in zip(columns, values[1:-1]) if v})
    return cells, commands


def write_outputs(report: Report, out_dir: Path, realism: str = "exact") -> list[Path]:
    """``out_dir/results-<paper>.md`` per paper (``results-<paper>-<realism>.md`` under real-robot
    conditions) and ``out_dir/report.json``."""
    paths = []
    for paper in report.papers():
        rows = [r for r in report.rows if r.claim.paper == paper]
        path = out_dir / f"results-{table_key(paper, realism)}.md"
        conditions = "" if realism == "exact" else f" under '{realism}' conditions"
        path.write_text(f"# {PAPERS[paper]}: generated results{conditions}\n\n" + table(rows),
                        encoding="utf-8")
        paths.append(path)
    path = out_dir / "report.json"
    path.write_text(json.dumps({"papers": report.papers(), "executor": report.executor,
                                "wall_time_s": round(report.wall_time_s, 3), "runs": report.runs,
                                "rows": [r.as_dict() for r in report.rows]}, indent=2) + "\n",
                    encoding="utf-8")
    paths.append(path)
    return paths


# ---------------------------------------------------------------------------- docs/results.md
def table_key(paper: str, realism: str = "exact") -> str:
    """A table's name: the paper's, with the realism level unless ``exact``
    (``herzog2016-robot``; its docs markers ``<!-- report:herzog2016-robot:begin -->``...)."""
    return paper if realism == "exact" else f"{paper}-{realism}"


def markers(paper: str) -> tuple[str, str]:
    return f"<!-- report:{paper}:begin -->", f"<!-- report:{paper}:end -->"


def check_markers(text: str, paper: str) -> None:
    """ValueError unless ``text`` has the paper's begin marker once, followed by its end marker."""
    begin, end = markers(paper)
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        raise ValueError(f"--update-docs: expected one '{begin}' followed by one '{end}'")


_ROW_ID = re.compile(r"^\| `([^`]+)`")


def update_docs(path: Path, paper: str, rows: list[Row], order: list[str],
                realism: str = "exact") -> None:
    """Replace the table between ``paper``'s markers in ``path`` by the generated one; rows of
    claims not in ``rows`` (a run with ``--only``) are kept from the old table if their id is in
    ``order`` (the paper's claim ids, the table's order). Nothing outside the markers changes."""
    text = path.read_text(encoding="utf-8")
    check_markers(text, table_key(paper, realism))
    begin, end = markers(table_key(paper, realism))
    head, rest = text.split(begin, 1)
    old, tail = rest.split(end, 1)
    placed = [r for r in rows if r.claim.paper == paper and r.claim.cell is not None]
    if placed:  # a table by robot: the new cells over the old ones
        cells, commands = _grid_cells(old)
        cells.update({r.claim.cell: grid_cell(r) for r in placed})
        commands.update({r.claim.cell[0]: r.claim.run.command() for r in placed})
        layout = [c.cell for c in claims_for(paper) if c.cell is not None]
        ordered = {cell: cells[cell] for cell in layout if cell in cells}
        path.write_text(f"{head}{begin}\n{grid(ordered, commands)}{end}{tail}", encoding="utf-8")
        return
    kept = {}
    for line in old.splitlines(keepends=True):
        match = _ROW_ID.match(line)
        if match:
            kept[match.group(1)] = line if line.endswith("\n") else line + "\n"
    new = {r.claim.id: table([r])[len(HEADER):] for r in rows if r.claim.paper == paper}
    lines = [new.get(i) or kept.get(i) for i in order]
    body = HEADER + "".join(line for line in lines if line)
    path.write_text(f"{head}{begin}\n{body}{end}{tail}", encoding="utf-8")
