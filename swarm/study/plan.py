"""A study as a plan of independent jobs, run by an executor (swarm.study's entry points build
the plan: swarm/study/api.py).

A `StudyPlan` is everything a study runs: a list of jobs (picklable: a chunk of one setting's
seeds, or one run), the `worker` that turns one job into its rows (a module-level function, so a
spawned process can run it), the CSV columns and the summary of the rows. `execute` runs a plan
with an `Executor`, streaming every row to `<out>/runs.csv` as it arrives, and writes
`<out>/summary.csv`; Ctrl-C keeps every finished row.

An executor is any callable `executor(worker, jobs, on_row)` that runs `worker(job)` for every
job, in any order and anywhere, and calls `on_row(row)` in this process for each row as it comes
back (a worker returns a row or a list of rows). It raises KeyboardInterrupt on Ctrl-C once its
workers are ended. `local_executor(workers)` is the one built in: a pool of spawned processes on
this machine (swarm/study/pool.py). The jobs are independent, so another executor (a cluster, a
resumable queue) needs nothing else from the study.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarm.study.pool import CsvSink, run_rows, write_csv
from swarm.study.progress import RowProgress

Worker = Callable[[Any], "dict | list[dict]"]
Executor = Callable[[Worker, Sequence[Any], Callable[[dict], None]], None]


def workers_of(workers: int) -> int:
    """Worker processes for `workers` (0: one per core)."""
    return workers or os.cpu_count() or 1


def local_executor(workers: int = 0) -> Executor:
    """Run jobs on `workers` spawned processes of this machine (0: one per core; 1: in this
    process), rows handed on as they finish."""
    n = workers_of(workers)

    def run(worker: Worker, jobs: Sequence[Any], on_row: Callable[[dict], None]) -> None:
        run_rows(worker, list(jobs), n, on_row)

    return run


@dataclass
class StudyPlan:
    """A study's runs as independent jobs (see the module's docstring)."""

    kind: str  # "swarms", "gains", "scenario"
    worker: Worker
    jobs: list[Any]
    columns: list[str]
    summarise: Callable[[list[dict]], list[dict]]
    runs: int  # runs in all (a job may be a batch of them)
    engine: str  # "batch" or "per-agent"
    describe: str  # one line: what runs (settings x seeds, the engine's batches)
    notes: list[str] = field(default_factory=list)  # lines said before the runs (the engine chosen)
    title: str = ""  # the figures' title
    swept: list[str] = field(default_factory=list)  # the axes with more than one value (sweep.png)


@dataclass
class StudyResult:
    """What a study gives: its rows (one per finished run, in the order they finished), its
    summary (one per setting) and where the files are. `interrupted`: Ctrl-C stopped it; the rows
    are those finished before."""

    kind: str
    out: Path
    rows: list[dict]
    summary: list[dict]
    interrupted: bool
    engine: str
    wall_s: float  # running the jobs, s
    runs: int = 0  # runs planned (len(rows) when not interrupted)
    plots: list[Path] = field(default_factory=list)

    @property
    def runs_csv(self) -> Path:
        return self.out / "runs.csv"

    @property
    def summary_csv(self) -> Path:
        return self.out / "summary.csv"

    def converged_fraction(self) -> float:
        """The share of the finished runs that converged (nan without any)."""
        if not self.rows:
            return math.nan
        return sum(1 for r in self.rows if r.get("converged") in (True, "True")) / len(self.rows)


def default_out(kind: str) -> Path:
    return Path("runs") / f"study-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"


def execute(
    plan: StudyPlan,
    out: Path,
    executor: Executor,
    progress: bool = True,
) -> StudyResult:
    """Run `plan` with `executor` into out/runs.csv (a row as each run finishes) and
    out/summary.csv; Ctrl-C keeps every finished row (`interrupted`)."""
    rows: list[dict] = []
    sink = CsvSink(out / "runs.csv", plan.columns)
    label = f"study {plan.kind}"
    interrupted = False
    t0 = time.perf_counter()
    with RowProgress(label, plan.runs, enabled=progress) as bar:

        def on_row(row: dict) -> None:
            sink(row)
            rows.append(row)
            bar.advance(len(rows))

        try:
            executor(plan.worker, plan.jobs, on_row)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            sink.close()
    wall = time.perf_counter() - t0
    summary = plan.summarise(rows)
    write_csv(out / "summary.csv", summary)
    return StudyResult(plan.kind, out, rows, summary, interrupted, plan.engine, wall, plan.runs)
