"""`swarm.study`: the batch studies of `swarm study` as Python functions.

`run_swarms`, `run_gains` and `run_scenario` do what `swarm study swarms|gains|scenario` do
(the command line is a thin layer over them: swarm/cli/study.py) and write the same files into
`out`: runs.csv (a row per run, as it finishes), summary.csv (a line per setting) and the
figures; they return a `StudyResult` (rows, summary, paths). `plan_swarms`, `plan_gains` and
`plan_scenario` give the same study as a `StudyPlan` (independent jobs and the worker that runs
one) without running it; `execute` runs a plan with any executor (swarm/study/plan.py).
Bad arguments raise `swarm.UsageError` naming the argument, before anything runs or is written.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from swarm.contracts.errors import UsageError
from swarm.contracts.scenario import load_scenario
from swarm.study.batch import chunk_size, gain_chunks, run_gain_chunk, run_swarm_chunk, swarm_chunks
from swarm.study.gains import (
    gain_columns,
    gain_jobs,
    gain_key_columns,
    gain_stubs,
    gain_subset,
    run_gain,
    summarise_gains,
)
from swarm.study.plan import (
    Executor,
    StudyExecutor,
    StudyPlan,
    StudyResult,
    capped,
    default_out,
    execute,
    local_executor,
    workers_of,
)
from swarm.study.pool import cores
from swarm.study.scenario import (
    KEY_COLUMNS,
    Jitter,
    Template,
    columns,
    engine_for,
    jobs_of,
    run_chunk,
    run_one,
    settings_of,
    stubs,
    subset,
    summarise,
    varied,
)
from swarm.study.swarms import (
    SwarmSetting,
    run_swarm,
    summarise_swarms,
    swarm_columns,
    swarm_jobs,
    swarm_key_columns,
    swarm_stubs,
    swarm_subset,
)
from swarm.study.sweeps import grid_axes

SELECTIONS = ("sticky", "rooted", "nearest")


def _list(value: Any) -> list:
    return list(value) if isinstance(value, (list, tuple, range)) else [value]


def _run(
    make: Callable[[int], StudyPlan],
    out: Path | str | None,
    executor: Executor | None,
    workers: int,
    progress: bool,
    say: Callable[[str], None] | None,
    resume: Path | str | None = None,
    run_timeout: float | None = None,
    labels: Mapping[str, str] | None = None,
) -> tuple[StudyPlan, StudyResult]:
    """The plan (made for the workers there are: `make(workers)`) run with the executor (the
    local one by default), `workers` capped at what it has and at the jobs, with a line saying
    so; into `out`, or the study in `resume` finished."""
    labels = dict(labels or {})
    if workers < 0:
        raise UsageError(f"{labels.get('workers', 'workers')}: {workers} must be 0 (all there are) or more")
    if resume is not None:
        if out is not None and Path(out).resolve() != Path(resume).resolve():
            label = labels.get("resume", "resume")
            raise UsageError(f"{label}: give the study's directory once (resume or out, not both)")
        out = resume
    ex = executor if executor is not None else local_executor(workers)
    capacity, why = ex.capacity() if isinstance(ex, StudyExecutor) else (cores(), "this machine's cores")
    plan = make(min(workers or capacity, capacity))
    n, line = capped(workers, capacity, why, len(plan.jobs), labels.get("workers", "workers"))
    if isinstance(ex, StudyExecutor):
        ex.workers = n
    where = Path(out) if out is not None else default_out(plan.kind)
    if say is not None:
        if line:
            say(line)
        for note in plan.notes:
            say(note)
        on = f" {ex.where(n)}" if isinstance(ex, StudyExecutor) else ""
        say(f"{plan.describe}{on}; rows -> {where / 'runs.csv'}")
    result = execute(plan, where, ex, progress, resume is not None, run_timeout, say, labels)
    return plan, result


# -- swarms ------------------------------------------------------------------------------------


def plan_swarms(
    *,
    n: int | Sequence[int] = 10,
    leaders: int | Sequence[int] = 2,
    selection: str | Sequence[str] = "sticky",
    sensing_range: float | Sequence[float] = math.inf,
    fov: float | None = None,
    seeds: int = 50,
    area: float = 120.0,
    speeds: tuple[float, float] = (15.0, 40.0),
    omega: float = 1.0,
    c1: float = 1.0,
    c2: float = 0.5,
    duration: float = 500.0,
    dt: float = 0.05,
    safety_radius: float = 0.0,
    batch: bool = True,
    workers: int = 0,
) -> StudyPlan:
    """The swarms study (`run_swarms`) as a plan of jobs, not run."""

    rules = [str(r).strip() for r in _list(selection)]
    for r in rules:
        if r not in SELECTIONS:
            raise UsageError(f"selection: {r!r} is not one of {', '.join(SELECTIONS)}")
    vmin, vmax = (list(speeds) + [math.nan, math.nan])[:2]
    if len(speeds) != 2 or not vmin <= vmax:
        raise UsageError("speeds: give (MIN, MAX) with MIN <= MAX, e.g. (15, 40)")
    if seeds < 1:
        raise UsageError(f"seeds: {seeds} must be at least 1")
    settings = [
        SwarmSetting(
            n=a,
            leaders=b,
            selection=r,
            range=rg,
            fov=fov or 2 * math.pi,
            area=area,
            speed_min=vmin,
            speed_max=vmax,
            omega=omega,
            c1=c1,
            c2=c2,
            duration=duration,
            dt=dt,
            safety_radius=safety_radius,
        )
        for a in _list(n)
        for b in _list(leaders)
        for r in rules
        for rg in _list(sensing_range)
        if b < a
    ]
    if not settings:
        raise UsageError("leaders: every setting has as many leaders as agents; a swarm needs a follower")
    runs = len(settings) * seeds
    worker: Callable[[Any], Any]
    jobs: list[Any]
    if batch:
        worker, jobs = run_swarm_chunk, list(swarm_chunks(settings, range(seeds), workers_of(workers)))
    else:
        worker, jobs = run_swarm, list(swarm_jobs(settings, range(seeds)))
    describe = f"{len(settings)} setting(s) x {seeds} seeds = {runs} runs of {duration:g} s (dt {dt:g} s), " + (
        f"{len(jobs)} batches" if batch else "per-agent engine"
    )
    engine = "batch" if batch else "per-agent"
    plan = StudyPlan("swarms", worker, jobs, swarm_columns(), summarise_swarms, runs, engine, describe)
    plan.key_columns, plan.stubs, plan.subset = swarm_key_columns(), swarm_stubs, swarm_subset
    return plan


def run_swarms(
    *,
    out: Path | str | None = None,
    plot: bool = True,
    workers: int = 0,
    executor: Executor | None = None,
    progress: bool = True,
    say: Callable[[str], None] | None = None,
    resume: Path | str | None = None,
    run_timeout: float | None = None,
    labels: Mapping[str, str] | None = None,
    **options: Any,
) -> StudyResult:
    """Random swarms through the in-process engine (`swarm study swarms`): one setting per
    combination of `n`, `leaders`, `selection` and `sensing_range` (each a value or a list),
    `seeds` random swarms each. The other options: those of `plan_swarms`. Writes runs.csv,
    summary.csv and (`plot`) study.png into `out` (default runs/study-swarms-<time>).

        r = swarm.study.run_swarms(n=8, sensing_range=[math.inf, 60], seeds=20, duration=100)
        r.summary[0]["converged_fraction"]
    """
    _, result = _run(
        lambda w: plan_swarms(workers=w, **options),
        out,
        executor,
        workers,
        progress,
        say,
        resume,
        run_timeout,
        labels,
    )
    if plot and result.finished:
        from swarm.study.figures import plot_swarms  # lazy: matplotlib (~0.3 s), for the figure only

        result.plots.append(plot_swarms(result.summary, result.finished, result.out / "study.png"))
    return result


# -- gains -------------------------------------------------------------------------------------


def plan_gains(
    *,
    c1: Sequence[float] = (0.5, 1, 2),
    c2: Sequence[float] = (0.2, 0.3, 0.5, 1, 2),
    ratios: Sequence[float] = (0.4, 0.6, 0.8, 1, 1.25, 1.5, 2, 2.5, 3, 4),
    starts: int = 3,
    duration: float = 300.0,
    dt: float = 0.05,
    batch: bool = True,
    workers: int = 0,
) -> StudyPlan:
    """The gain map (`run_gains`) as a plan of jobs, not run."""

    for name, values in (("c1", c1), ("c2", c2), ("ratios", ratios)):
        for v in values:
            if not 0 < v < math.inf:
                raise UsageError(f"{name}: {v!r} must be a positive finite number")
    runs = gain_jobs(list(c1), list(c2), list(ratios), starts, duration, dt)
    worker: Callable[[Any], Any]
    jobs: list[Any]
    if batch:
        worker, jobs = run_gain_chunk, list(gain_chunks(runs, workers_of(workers)))
    else:
        worker, jobs = run_gain, list(runs)
    describe = f"{len(runs)} runs of {duration:g} s, " + (f"{len(jobs)} batches" if batch else "per-agent engine")
    engine = "batch" if batch else "per-agent"
    plan = StudyPlan("gains", worker, jobs, gain_columns(), summarise_gains, len(runs), engine, describe)
    plan.key_columns, plan.stubs, plan.subset = gain_key_columns(), gain_stubs, gain_subset
    return plan


def run_gains(
    *,
    out: Path | str | None = None,
    plot: bool = True,
    workers: int = 0,
    executor: Executor | None = None,
    progress: bool = True,
    say: Callable[[str], None] | None = None,
    resume: Path | str | None = None,
    run_timeout: float | None = None,
    labels: Mapping[str, str] | None = None,
    **options: Any,
) -> StudyResult:
    """Where does the follower law settle (`swarm study gains`): one follower behind a leader on
    its orbit (omega = 1 rad/s) for every (C1, C2, speed ratio), `starts` random starts each.
    Options: those of `plan_gains`. Writes runs.csv, summary.csv and (`plot`) gains.png."""
    _, result = _run(
        lambda w: plan_gains(workers=w, **options),
        out,
        executor,
        workers,
        progress,
        say,
        resume,
        run_timeout,
        labels,
    )
    if plot and result.summary:
        from swarm.study.figures import plot_gains  # lazy: matplotlib (~0.3 s), for the figure only

        duration = options.get("duration", 300.0)
        result.plots.append(plot_gains(result.summary, result.out / "gains.png", duration))
    return result


# -- one's own scenario ------------------------------------------------------------------------


def plan_scenario(
    path: Path | str,
    *,
    grid: Mapping[str, Sequence[float] | float] | None = None,
    seeds: int = 20,
    positions: float = 0.0,
    headings: float | str = 0.0,
    speeds: float = 0.0,
    duration: float | None = None,
    engine: str = "auto",
    workers: int = 0,
    labels: Mapping[str, str] | None = None,
) -> StudyPlan:
    """The study of a scenario (`run_scenario`) as a plan of jobs, not run. `labels` names
    the grid's keys in messages (the command line's options)."""

    path = Path(path)
    if engine not in ("auto", "batch", "per-agent"):
        raise UsageError(f"engine: {engine!r} is not one of auto, batch, per-agent")
    if seeds < 1:
        raise UsageError(f"seeds: {seeds} must be at least 1")
    spin = math.inf if headings == "uniform" else float(headings)
    if not (0 <= spin <= math.pi or math.isinf(spin)):
        raise UsageError(f"headings: {headings!r}: give an angle in [0, pi] (rad) or 'uniform'")
    if not (positions >= 0 and 0 <= speeds <= 0.9):
        raise UsageError("positions: a distance >= 0 (m); speeds: a fraction in [0, 0.9]")
    sweeps = grid_axes(grid or {}, labels)
    spec = load_scenario(path)
    for axis in ("safety", "gamma"):
        if axis in sweeps and spec.safety is None:
            label = (labels or {}).get(axis, f"grid[{axis!r}]")
            raise UsageError(f"{label}: {path} has no [safety] table (docs/guides/scenarios.md#safety)")
    template = Template(spec.model_dump(), str(path), (str(path.resolve().parent),), duration)
    jitter = Jitter(positions, spin, speeds)
    settings = settings_of(sweeps)
    firsts = [varied(template, st, jitter, 0) for st in settings]  # a setting the model refuses fails here
    batched, why = engine_for(firsts)
    if engine == "batch" and batched != "batch":
        label = (labels or {}).get("engine", "engine='batch'")
        raise UsageError(f"{label}: the batch engine does not run this study: {why}")
    use_batch = batched == "batch" and engine != "per-agent"
    run_s = firsts[0].run.duration
    worker: Callable[[Any], Any]
    if use_batch:
        per = chunk_size(seeds, workers_of(workers), len(firsts[0].agents), int(round(run_s / firsts[0].run.dt)))
        worker, note = run_chunk, f"engine: batch ({why}), {per} runs per batch"
    else:
        per, worker = 1, run_one
        note = "engine: per-agent (swarm sim's), one run per job" + (
            f": the batch engine refuses, {why}" if batched != "batch" else " (--engine per-agent)"
        )
    runs = len(settings) * seeds
    plan = StudyPlan(
        "scenario",
        worker,
        list(jobs_of(template, settings, jitter, seeds, per)),
        columns(settings),
        lambda rs: summarise(rs, settings),
        runs,
        "batch" if use_batch else "per-agent",
        f"{len(settings)} setting(s) x {seeds} seeds = {runs} runs of {run_s:g} s of {path.name}",
        [note],
    )
    varies = ", ".join(
        [f"positions +-{positions:g} m"] * bool(positions)
        + [f"headings {'uniform' if math.isinf(spin) else f'+-{spin:g} rad'}"] * bool(spin)
        + [f"speeds x(1+-{speeds:g})"] * bool(speeds)
    )
    plan.title = f"swarm study scenario {path.name}: {seeds} seeds" + (f" ({varies})" if varies else "")
    plan.swept = [k for k, v in sweeps.items() if len(v) > 1]
    plan.key_columns, plan.stubs, plan.subset = list(KEY_COLUMNS), stubs, subset
    return plan


def run_scenario(
    path: Path | str,
    *,
    grid: Mapping[str, Sequence[float] | float] | None = None,
    seeds: int = 20,
    out: Path | str | None = None,
    plot: bool = True,
    workers: int = 0,
    executor: Executor | None = None,
    progress: bool = True,
    say: Callable[[str], None] | None = None,
    resume: Path | str | None = None,
    run_timeout: float | None = None,
    labels: Mapping[str, str] | None = None,
    **options: Any,
) -> StudyResult:
    """Your scenario, your law, over seeds and settings (`swarm study scenario`).

    The scenario file is the template: every seed (0..seeds-1) draws its own jitter of
    `positions` (+-m), `headings` (+-rad or "uniform") and `speeds` (x U(1-F, 1+F)), and every
    combination of `grid`'s lists is one setting, run over the same seeds. `grid`'s keys: "c1",
    "c2", "range", "fov", "noise", "loss", "delay", "safety", "gamma", "param.NAME" (a law
    parameter) and "tuning.NAME" (a [sensing.tuning] field). Other options: `duration` (s, default
    the scenario's) and `engine` ("auto", "batch", "per-agent"). Writes runs.csv, summary.csv and
    (`plot`) study.png, and sweep.png when something is swept, into `out`.
    """
    plan, result = _run(
        lambda w: plan_scenario(path, grid=grid, seeds=seeds, workers=w, labels=labels, **options),
        out,
        executor,
        workers,
        progress,
        say,
        resume,
        run_timeout,
        labels,
    )
    if plot and result.finished:
        from swarm.study.figures import plot_scenario_study, plot_sweep  # lazy: matplotlib (~0.3 s), figures only

        rows = result.finished
        result.plots.append(plot_scenario_study(result.summary, rows, result.out / "study.png", plan.title))
        if plan.swept:
            result.plots.append(plot_sweep(rows, plan.swept, result.out / "sweep.png", plan.title))
    return result
