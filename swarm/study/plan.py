"""A study as a plan of independent jobs, run by an executor (swarm.study's entry points build
the plan: swarm/study/api.py).

A `StudyPlan` is everything a study runs: a list of jobs (picklable: a chunk of one setting's
seeds, or one run), the `worker` that turns one job into its rows (a module-level function, so
another process can run it), the CSV columns and the summary of the rows. Every row is keyed by
its setting and seed (`key_columns`); `stubs(job)` gives the key columns of each run of a job
and `subset(job, indices)` the job with only those runs, so a study can skip what is done and
split what timed out. `execute` runs a plan with an executor, streaming every row to
`<out>/runs.csv` as it arrives (a row whose key is already there is dropped: a job run twice
writes no duplicate), and writes `<out>/summary.csv`; Ctrl-C keeps every finished row;
`resume=True` finishes the study already in `<out>`, running only the runs not in its runs.csv.

An executor is any callable `executor(worker, jobs, on_row)` that runs `worker(job)` for every
job, in any order and anywhere, and calls `on_row(row)` in this process for each row as it comes
back (a worker returns a row or a list of rows). It raises KeyboardInterrupt on Ctrl-C once its
workers are ended. The built-in ones are `StudyExecutor`s, which also say what they have (cores,
a cluster's threads: `capacity`) and time runs out: `local_executor(workers)`, processes of this
machine (swarm/study/pool.py), and `dask_executor(address)`, a Dask cluster
(swarm/study/cluster.py).
"""

from __future__ import annotations

import csv
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarm.contracts.errors import UsageError
from swarm.study.pool import CsvSink, Timeouts, cores, run_jobs, write_csv
from swarm.study.progress import RowProgress

Worker = Callable[[Any], "dict | list[dict]"]
Executor = Callable[[Worker, Sequence[Any], Callable[[dict], None]], None]

OK, TIMEOUT = "ok", "timeout"  # a row's `status`: the run finished / it ran past --run-timeout and was ended


def workers_of(workers: int) -> int:
    """Worker processes for `workers` (0: one per core), at most one per core."""
    return min(workers or cores(), cores())


class StudyExecutor:
    """An executor that says what it has (`capacity`) and can end a run past its time
    (`timeouts`, swarm/study/pool.py `Timeouts`)."""

    workers: int = 0  # at most this many jobs at a time (0: as many as it has)

    def capacity(self) -> tuple[int, str]:
        """(jobs it can run at once, the reason in words: "this machine has 2 cores")."""
        n = cores()
        return n, f"this machine has {n} core{'s' * (n != 1)}"

    def __call__(
        self,
        worker: Worker,
        jobs: Sequence[Any],
        on_row: Callable[[dict], None],
        timeouts: Timeouts | None = None,
    ) -> None:
        raise NotImplementedError

    def where(self, n: int) -> str:
        """Where the jobs run, for the line said before them."""
        return f"on {n} process{'es' * (n != 1)}"

    def close(self) -> None:
        """Let go of what it holds (a cluster's connection)."""


class LocalExecutor(StudyExecutor):
    """Jobs on processes of this machine (swarm/study/pool.py `run_jobs`)."""

    def __init__(self, workers: int = 0):
        self.workers = workers

    def __call__(
        self,
        worker: Worker,
        jobs: Sequence[Any],
        on_row: Callable[[dict], None],
        timeouts: Timeouts | None = None,
    ) -> None:
        n = min(workers_of(self.workers), len(jobs))

        def on_rows(_job: Any, rows: list[dict]) -> None:
            for r in rows:
                on_row(r)

        run_jobs(worker, list(jobs), n, on_rows, timeouts)


def local_executor(workers: int = 0) -> StudyExecutor:
    """Run jobs on `workers` processes of this machine (0: one per core; at most one per core
    and one per job; 1: in this process, unless runs have a timeout), rows handed on as they
    finish."""
    return LocalExecutor(workers)


def capped(asked: int, capacity: int, why: str, jobs: int, label: str = "workers") -> tuple[int, str | None]:
    """(workers to use, the line saying it was capped, or None): `asked` (0: all there are) at
    most `capacity` and `jobs`."""
    n = max(1, min(asked or capacity, capacity, jobs))
    if not asked or asked <= n:
        return n, None
    reason = why if n == capacity else f"the study has {jobs} job{'s' * (jobs != 1)}"
    return n, f"{label} {asked} capped at {n}: {reason}"


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
    key_columns: list[str] = field(default_factory=list)  # what names a run: its setting's columns and seed
    stubs: Callable[[Any], list[dict]] | None = None  # a job's runs: their key columns (and setting's)
    subset: Callable[[Any, list[int]], Any] | None = None  # the job with only these runs (indices into stubs)

    def key(self, row: dict) -> tuple[str, ...]:
        return tuple(cell(row.get(c)) for c in self.key_columns)


@dataclass
class StudyResult:
    """What a study gives: its rows (one per finished run: those already in runs.csv when
    resumed, then the new ones in the order they finished), its summary (one per setting) and
    where the files are. `interrupted`: Ctrl-C stopped it; the rows are those finished before.
    `resumed`: rows that were in runs.csv before (not run again); `timeouts`: runs ended past
    the run timeout (rows with status "timeout"); `duplicates`: rows dropped because their run
    was already there (a job run twice)."""

    kind: str
    out: Path
    rows: list[dict]
    summary: list[dict]
    interrupted: bool
    engine: str
    wall_s: float  # running the jobs, s
    runs: int = 0  # runs planned (len(rows) when not interrupted)
    plots: list[Path] = field(default_factory=list)
    resumed: int = 0
    timeouts: int = 0
    duplicates: int = 0

    @property
    def runs_csv(self) -> Path:
        return self.out / "runs.csv"

    @property
    def summary_csv(self) -> Path:
        return self.out / "summary.csv"

    @property
    def finished(self) -> list[dict]:
        """The rows of runs that finished (status ok: not timed out)."""
        return [r for r in self.rows if r.get("status", OK) == OK]

    def converged_fraction(self) -> float:
        """The share of the runs (timed out ones too) that converged (nan without any)."""
        if not self.rows:
            return math.nan
        return sum(1 for r in self.rows if r.get("converged") in (True, "True")) / len(self.rows)


def default_out(kind: str) -> Path:
    return Path("runs") / f"study-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"


def cell(v: Any) -> str:
    """A value as a key part, the same from a fresh row and from its CSV text: numbers by
    their float value (10, 10.0 and "10" alike), booleans and text as written, None as ""."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, (int, float)):
        return repr(float(v))
    s = str(v)
    try:
        return repr(float(s)) if s not in ("True", "False") else s
    except ValueError:
        return s


def typed(v: str) -> Any:
    """A CSV cell back to a value: "" None, "True"/"False" bool, a number int or float, else text."""
    if v == "":
        return None
    if v in ("True", "False"):
        return v == "True"
    try:
        return int(v)
    except ValueError:
        pass
    try:
        return float(v)
    except ValueError:
        return v


def with_status(columns: list[str]) -> list[str]:
    """The columns with `status` before `wall_s` (at the end without one)."""
    cols = [c for c in columns if c != "status"]
    at = cols.index("wall_s") if "wall_s" in cols else len(cols)
    return cols[:at] + ["status"] + cols[at:]


def read_done(plan: StudyPlan, path: Path, label: str) -> list[dict]:
    """The rows of a study's runs.csv to resume (typed back), each key once; the file rewritten
    with just them, so a line cut short by a kill is gone and rows are appended after whole
    lines. UsageError naming `label` when there is no runs.csv or it is another study's."""
    if not path.is_file():
        raise UsageError(f"{label}: no {path.name} in {path.parent}: nothing to resume")
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        header = reader.fieldnames or []
        text_rows = list(reader)
    if header != plan.columns:
        raise UsageError(
            f"{label}: {path} has the columns of another study ({', '.join(header[:4])}, ...), "
            f"not this {plan.kind} study's ({', '.join(plan.columns[:4])}, ...): "
            "resume it with the options it was run with"
        )
    keep, seen = [], set()
    for r in text_rows:
        if None in r or any(v is None for v in r.values()):  # cut short (or longer than the header)
            continue
        k = plan.key(r)
        if k in seen:
            continue
        seen.add(k)
        keep.append(r)
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=plan.columns)
        w.writeheader()
        w.writerows(keep)
    os.replace(tmp, path)
    return [{k: typed(v) for k, v in r.items()} for r in keep]


def remaining(plan: StudyPlan, done: set[tuple[str, ...]]) -> list[Any]:
    """The plan's jobs with the runs in `done` taken out (jobs with none left dropped)."""
    if not done:
        return list(plan.jobs)
    assert plan.stubs is not None and plan.subset is not None
    out = []
    for job in plan.jobs:
        stubs = plan.stubs(job)
        left = [i for i, s in enumerate(stubs) if plan.key(s) not in done]
        if len(left) == len(stubs):
            out.append(job)
        elif left:
            out.append(plan.subset(job, left))
    return out


def execute(
    plan: StudyPlan,
    out: Path,
    executor: Executor,
    progress: bool = True,
    resume: bool = False,
    run_timeout: float | None = None,
    say: Callable[[str], None] | None = None,
    labels: dict[str, str] | None = None,
) -> StudyResult:
    """Run `plan` with `executor` into out/runs.csv (a row as each run finishes, each run once)
    and out/summary.csv; Ctrl-C keeps every finished row (`interrupted`). `resume`: out/runs.csv
    holds rows of this study already; only the other runs are run, their rows appended, and the
    summary is of all. `run_timeout` (s, a built-in executor): a run past it is ended and its row
    says status "timeout"; a batch past its runs' time is run again one run per job."""
    labels = labels or {}
    if run_timeout is not None:
        label = labels.get("run_timeout", "run_timeout")
        if not (run_timeout > 0 and math.isfinite(run_timeout)):
            raise UsageError(f"{label}: {run_timeout!r} must be a positive number of s")
        if not isinstance(executor, StudyExecutor):
            raise UsageError(f"{label}: this executor cannot end a run (a built-in one can)")
    columns = with_status(plan.columns) if plan.key_columns else plan.columns
    plan.columns = columns
    path = out / "runs.csv"
    before = read_done(plan, path, labels.get("resume", "resume")) if resume else []
    done = {plan.key(r) for r in before}
    jobs = remaining(plan, done)
    todo = plan.runs - len(done) if plan.key_columns else plan.runs
    if resume and say is not None:
        say(f"resume: {len(done)} of {plan.runs} runs already in {path}, {max(0, todo)} to run")
    rows: list[dict] = []
    counts = {"timeouts": 0, "duplicates": 0}
    sink = CsvSink(path, columns, append=resume)
    label = f"study {plan.kind}"
    interrupted = False
    t0 = time.perf_counter()
    with RowProgress(label, max(0, todo), enabled=progress) as bar:

        def on_row(row: dict) -> None:
            if plan.key_columns:
                k = plan.key(row)
                if k in done:
                    counts["duplicates"] += 1
                    return
                done.add(k)
                row.setdefault("status", OK)
            sink(row)
            rows.append(row)
            bar.advance(len(rows))

        def timed_out(job: Any, elapsed: float) -> list:
            """A job past its budget: a batch again one run per job, a single run a row."""
            assert plan.stubs is not None and plan.subset is not None
            stubs = plan.stubs(job)
            left = [i for i, s in enumerate(stubs) if plan.key(s) not in done]
            if len(stubs) > 1:
                return [plan.subset(job, [i]) for i in left]
            for i in left:
                counts["timeouts"] += 1
                on_row({**stubs[i], "status": TIMEOUT, "wall_s": elapsed})
            return []

        try:
            if isinstance(executor, StudyExecutor):
                timeouts = None
                if run_timeout is not None:
                    assert plan.stubs is not None
                    stubs = plan.stubs
                    timeouts = Timeouts(run_timeout, lambda j: len(stubs(j)), timed_out)
                executor(plan.worker, jobs, on_row, timeouts)
            else:
                executor(plan.worker, jobs, on_row)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            sink.close()
    wall = time.perf_counter() - t0
    every = before + rows
    summary = plan.summarise(every)
    write_csv(out / "summary.csv", summary)
    return StudyResult(
        plan.kind,
        out,
        every,
        summary,
        interrupted,
        plan.engine,
        wall,
        plan.runs,
        resumed=len(before),
        timeouts=counts["timeouts"],
        duplicates=counts["duplicates"],
    )
