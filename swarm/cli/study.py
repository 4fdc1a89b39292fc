"""`swarm study swarms|gains|scenario`: the batch studies of swarm.study (swarm/study/api.py) as
commands: the options parsed (swarm/cli/study_args.py), a progress bar, a printed table, CSV
files and plots; Ctrl-C keeps every finished row (exit 130)."""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer

from swarm.cli.errors import stop_code
from swarm.cli.study_args import fail, floats, gain_table, ints, num, params, safety_table, state_table, sweep, table

if TYPE_CHECKING:
    from swarm.study.plan import StudyResult

study_app = typer.Typer(
    help="Batch studies with the in-process engine: does the law converge for my kind of swarm?",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _done(result: StudyResult) -> None:
    """The plots' lines and the last line; exit 130 when Ctrl-C cut the study short (143: SIGTERM)."""
    for p in result.plots:
        typer.echo(f"plot: {p}")
    typer.echo(f"results: {result.out}")
    if result.interrupted:
        raise typer.Exit(stop_code())


def _progress(quiet: bool) -> bool:
    """Progress on stderr unless -q here, or `swarm -q` before the command (it sets
    $SWARM_LOG_LEVEL to WARNING: warnings and errors only)."""
    level = os.environ.get("SWARM_LOG_LEVEL", "").strip().upper()
    return not (quiet or level in ("WARNING", "ERROR") or (level.isdigit() and int(level) >= 30))


def _stopped(result: StudyResult) -> None:
    if result.timeouts:
        typer.echo(f"timeout: {result.timeouts} run(s) ended at --run-timeout (rows with status timeout)", err=True)
    if result.interrupted:
        typer.echo(
            f"stopped: {len(result.rows)} of {result.runs} runs finished, kept in {result.runs_csv} "
            f"(--resume {result.out} runs the rest)",
            err=True,
        )


LABELS = {"workers": "--workers", "resume": "--resume", "run_timeout": "--run-timeout"}


def _executor(scheduler: Optional[str]):
    """The executor of --scheduler (a Dask cluster), or None: this machine's processes."""
    if scheduler is None:
        return None
    from swarm.study.cluster import dask_executor  # lazy: a cluster's executor, only with --scheduler

    return dask_executor(scheduler)


@contextlib.contextmanager
def _running(
    scheduler: Optional[str],
    jobs: int,
    out: Optional[Path],
    plot: bool,
    quiet: bool,
    resume: Optional[Path],
    run_timeout: Optional[float],
    labels: dict[str, str] = LABELS,
) -> Iterator[dict[str, Any]]:
    """The keyword arguments every `swarm.study.run_*` takes from the options every study command
    has (where it runs, its output, resume, run timeout), the cluster's client closed at the end."""
    executor = _executor(scheduler)
    try:
        yield dict(
            workers=jobs,
            out=out,
            plot=plot,
            say=typer.echo,
            progress=_progress(quiet),
            resume=resume,
            run_timeout=run_timeout,
            executor=executor,
            labels=labels,
        )
    finally:
        if executor is not None:
            executor.close()


DtOpt = Annotated[float, typer.Option(help="step (s)", min=1e-4)]
JobsOpt = Annotated[
    int,
    typer.Option(
        "--workers",
        "--jobs",
        "-j",
        min=0,
        help="worker processes, or tasks at a time on a cluster (0: one per core / worker thread; "
        "capped at that and at the study's jobs)",
    ),
]
ResumeOpt = Annotated[
    Optional[Path],
    typer.Option(
        help="finish the study in DIR (run with the same options): runs already in DIR/runs.csv "
        "are not run again, the others' rows appended; summary and figures of all"
    ),
]
TimeoutOpt = Annotated[
    Optional[float],
    typer.Option(
        help="end a run past S s of wall time (its process killed and replaced): its row says "
        "status timeout, the study goes on",
        min=1e-3,
    ),
]
SchedulerOpt = Annotated[
    Optional[str],
    typer.Option(
        help="run on the Dask cluster whose scheduler is at tcp://HOST:8786 (`dask scheduler`, "
        "`dask worker`; the extra swarm-circumnav[cluster])"
    ),
]
OutOpt = Annotated[
    Optional[Path], typer.Option("--out", "-o", help="output directory (default runs/study-<kind>-<time>)")
]
QuietOpt = Annotated[
    bool, typer.Option("--quiet", "-q", help="no progress on stderr (a bar on a terminal, else a line every 10 s)")
]
BatchOpt = Annotated[
    bool,
    typer.Option(
        "--batch/--per-agent",
        help="run many runs per worker as arrays (the "
        "batch engine, same rows) or each run through swarm sim's per-agent "
        "engine",
    ),
]


@study_app.command()
def swarms(
    n: Annotated[str, typer.Option(help="agents per swarm (a comma-separated list: one setting each)")] = "10",
    leaders: Annotated[str, typer.Option(help="leaders per swarm (list)")] = "2",
    selection: Annotated[str, typer.Option(help="selection rules (list of sticky, rooted, nearest)")] = "sticky",
    sensing_range: Annotated[str, typer.Option("--range", help="sensing ranges in m, inf = unlimited (list)")] = "inf",
    fov: Annotated[
        Optional[float], typer.Option(help="field of view (rad, default all round)", min=0.01, max=2 * math.pi)
    ] = None,
    seeds: Annotated[int, typer.Option(help="random swarms per setting (seeds 0..N-1)", min=1)] = 50,
    area: Annotated[float, typer.Option(help="side of the square the agents start in (m)", min=1.0)] = 120.0,
    speeds: Annotated[str, typer.Option(help="speed range MIN,MAX (m/s)")] = "15,40",
    omega: Annotated[
        float, typer.Option(help="leaders' angular rate on their orbits (rad/s): R_L = v_L/omega", min=1e-6)
    ] = 1.0,
    c1: Annotated[float, typer.Option(help="gain C1", min=1e-9)] = 1.0,
    c2: Annotated[float, typer.Option(help="gain C2", min=1e-9)] = 0.5,
    duration: Annotated[float, typer.Option(help="simulated s per run: converged means by then", min=0.1)] = 500.0,
    dt: DtOpt = 0.05,
    safety_radius: Annotated[
        float,
        typer.Option(
            help="measure collisions at this radius (m; a [safety] table with enabled = false: "
            "collisions, least distance, saturations in every row); 0: not measured",
            min=0.0,
        ),
    ] = 0.0,
    jobs: JobsOpt = 0,
    out: OutOpt = None,
    plot: Annotated[bool, typer.Option(help="write study.png")] = True,
    batch: BatchOpt = True,
    quiet: QuietOpt = False,
    resume: ResumeOpt = None,
    run_timeout: TimeoutOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Random swarms through the in-process engine: converged fraction, settling, switches.

    One setting per combination of the list options (--n, --leaders, --selection, --range).

    Every run counts in the converged share. Swarms whose followers cannot all reach a
    leader in the sensing graph at t = 0 (a range or field of view cuts them off) are
    also shown apart (`cut off`, and how many of those converged). Writes runs.csv (one
    row per run, as it finishes), summary.csv and study.png.

    By default each worker runs a batch of seeds at once as arrays (the batch engine,
    equal to swarm sim's per-agent engine: the same rows); --per-agent runs them one by one.

    Example: swarm study swarms --selection sticky,rooted,nearest --seeds 200
    """
    from swarm.study.api import run_swarms  # lazy: numpy, the scenario model, the pool; not for `swarm --help`

    rules = [r.strip() for r in selection.split(",")]
    for r in rules:
        if r not in ("sticky", "rooted", "nearest"):
            raise fail(f"--selection: {r!r} is not one of sticky, rooted, nearest")
    vmin, vmax = (floats("--speeds", speeds) + [math.nan])[:2]
    if not (len(speeds.split(",")) == 2 and vmin <= vmax):
        raise fail("--speeds: give MIN,MAX with MIN <= MAX, e.g. 15,40")
    ns, ls = ints("--n", n, 2), ints("--leaders", leaders, 1)
    ranges = floats("--range", sensing_range, allow_inf=True)
    pairs = sum(b < a for a in ns for b in ls)
    if not pairs:
        raise fail("--leaders: every setting has as many leaders as agents; a swarm needs a follower")
    with _running(scheduler, jobs, out, plot, quiet, resume, run_timeout) as common:
        result = run_swarms(
            n=ns,
            leaders=ls,
            selection=rules,
            sensing_range=ranges,
            fov=fov,
            seeds=seeds,
            area=area,
            speeds=(vmin, vmax),
            omega=omega,
            c1=c1,
            c2=c2,
            duration=duration,
            dt=dt,
            safety_radius=safety_radius,
            batch=batch,
            **common,
        )
    _stopped(result)
    summary = result.summary
    table(
        summary,
        [
            ("setting", "setting", str),
            ("runs", "runs", str),
            *([("timeouts", "timeouts", str)] if result.timeouts or any(r.get("timeouts") for r in summary) else []),
            ("converged", "converged_fraction", num(".1%")),
            ("cut off (conv.)", "cut_off", str),
            ("", "cut_off_converged", lambda v: f"({v})"),
            ("settle med s", "settling_median_s", num(".0f")),
            ("settle p90 s", "settling_p90_s", num(".0f")),
            ("switches med", "switches_median", num("g")),
            ("p90", "switches_p90", num("g")),
            ("max", "switches_max", num("g")),
            ("search med s", "searching_median_s", num(".1f")),
            ("per loss max", "loss_switches_max", num("g")),
        ],
    )
    safety_table(summary)
    state_table(summary)
    typer.echo(
        "converged: share of all runs in which every agent ends within 1% of its expected radius; "
        "cut off: runs with a follower that has no sensing path to a leader at t = 0; switches: "
        "per follower; search: s a follower spends with nobody to steer by (median over runs of "
        "the mean per follower); per loss: the most switches one loss of an out-neighbour cost"
    )
    _done(result)


@study_app.command()
def gains(
    c1: Annotated[str, typer.Option(help="values of C1 / omega (list)")] = "0.5,1,2",
    c2: Annotated[str, typer.Option(help="values of C2 / omega (list)")] = "0.2,0.3,0.5,1,2",
    ratios: Annotated[
        str, typer.Option(help="follower / out-neighbour speed ratios (list)")
    ] = "0.4,0.6,0.8,1,1.25,1.5,2,2.5,3,4",
    starts: Annotated[int, typer.Option(help="random starts per cell (the worst counts)", min=1)] = 3,
    duration: Annotated[float, typer.Option(help="simulated s per run, in units of 1/omega", min=1.0)] = 300.0,
    dt: DtOpt = 0.05,
    jobs: JobsOpt = 0,
    out: OutOpt = None,
    plot: Annotated[bool, typer.Option(help="write gains.png")] = True,
    batch: BatchOpt = True,
    quiet: QuietOpt = False,
    resume: ResumeOpt = None,
    run_timeout: TimeoutOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Where does the follower law settle? A map of (C1, C2) against speed ratio.

    One follower behind a leader already on its orbit (omega = 1 rad/s), for every
    (C1, C2, speed ratio), from a few random starts: the worst time into the 2% band, or
    never. Writes runs.csv, summary.csv, gains.png.

    Example: swarm study gains --c1 0.5,1,2 --c2 0.2,0.5,1 --starts 3
    """
    from swarm.study.api import run_gains  # lazy: numpy, the scenario model, the pool; not for `swarm --help`

    c1s, c2s, qs = floats("--c1", c1), floats("--c2", c2), floats("--ratios", ratios)
    with _running(scheduler, jobs, out, plot, quiet, resume, run_timeout) as common:
        result = run_gains(
            c1=c1s,
            c2=c2s,
            ratios=qs,
            starts=starts,
            duration=duration,
            dt=dt,
            batch=batch,
            **common,
        )
    _stopped(result)
    gain_table(result.summary)
    _done(result)


@study_app.command()
def scenario(
    path: Annotated[Path, typer.Argument(help="the scenario file: the template every run varies")],
    seeds: Annotated[int, typer.Option(help="runs per setting (seeds 0..N-1: each draws its own jitter)", min=1)] = 20,
    positions: Annotated[float, typer.Option(help="jitter of every agent's x and y: +-M m, uniform", min=0.0)] = 0.0,
    headings: Annotated[
        str, typer.Option(help="jitter of every heading: +-RAD uniform, or 'uniform' (anywhere on the circle)")
    ] = "0",
    speeds: Annotated[
        float,
        typer.Option(
            help="jitter of every speed: x U(1-F, 1+F) (a leader's orbit radius scales with it)", min=0, max=0.9
        ),
    ] = 0.0,
    c1: Annotated[Optional[str], typer.Option(help="values of C1 (list: one setting each)")] = None,
    c2: Annotated[Optional[str], typer.Option(help="values of C2 (list)")] = None,
    param: Annotated[
        Optional[list[str]],
        typer.Option(
            help="a law parameter (law.params) NAME=V1,V2,..., or a field of the selection tuning "
            "([sensing.tuning]) tuning.FIELD=V1,V2,... (repeat for more)"
        ),
    ] = None,
    sensing_range: Annotated[
        Optional[str], typer.Option("--range", help="sensing ranges in m, inf = unlimited (list)")
    ] = None,
    fov: Annotated[Optional[str], typer.Option(help="fields of view in rad, 6.283 = all round (list)")] = None,
    noise: Annotated[
        Optional[str],
        typer.Option(
            help="sensing noise std in rad (list): the std of the scenario's noise faults, "
            "or one on every agent for the whole run; 0 = none"
        ),
    ] = None,
    loss: Annotated[Optional[str], typer.Option(help="message loss probability (list), as --noise")] = None,
    delay: Annotated[Optional[str], typer.Option(help="sensor-frame delay in s (list), as --noise")] = None,
    safety: Annotated[
        Optional[str],
        typer.Option(
            help="the scenario's [safety] filter: 1 = on, 0 = off, measuring only (list, e.g. 0,1: what safety costs)"
        ),
    ] = None,
    gamma: Annotated[Optional[str], typer.Option(help="the [safety] filter's gamma in 1/s (list)")] = None,
    duration: Annotated[
        Optional[float], typer.Option(help="simulated s per run (default: the scenario's)", min=0.1)
    ] = None,
    engine: Annotated[
        str, typer.Option(help="auto (the batch engine where it runs every setting, else per-agent), batch, per-agent")
    ] = "auto",
    jobs: JobsOpt = 0,
    out: OutOpt = None,
    plot: Annotated[bool, typer.Option(help="write study.png and sweep.png")] = True,
    quiet: QuietOpt = False,
    resume: ResumeOpt = None,
    run_timeout: TimeoutOpt = None,
    scheduler: SchedulerOpt = None,
) -> None:
    """Your scenario, your law: vary it over seeds and settings; where does it converge?

    The scenario file is the template. Every seed draws its own jitter of positions,
    headings and speeds (and is the run's seed, run.seed, which drives loss and noise); every
    combination of the lists (--c1, --c2, --param (law parameters, tuning.FIELD), --range, --fov, --noise, --loss,
    --delay, --safety, --gamma) is one setting, run over the same seeds. Any law runs: a follower law that
    declares itself vectorised goes through the batch engine, any other through swarm
    sim's per-agent engine on every core (the engine used is printed; docs/design/studies.md).

    Writes runs.csv (one row per run, as it finishes), summary.csv, study.png, and
    sweep.png (converged share and settling time against each swept parameter).

    Example: swarm study scenario scenarios/case2.toml --seeds 100 --positions 10 --headings uniform --noise 0,0.02,0.05
    """
    from swarm.study.api import run_scenario  # lazy: numpy, the scenario model, the engines; not for `swarm --help`

    if engine not in ("auto", "batch", "per-agent"):
        raise fail(f"--engine: {engine!r} is not one of auto, batch, per-agent")
    if headings.strip() == "uniform":
        spin = math.inf
    else:
        (spin,) = sweep("--headings", headings, lo=0.0, hi=math.pi) if "," not in headings else [math.nan]
        if math.isnan(spin):
            raise fail("--headings: give one number (rad) or 'uniform'")
    swept, labels = params(param or [])
    grid: dict[str, list[float]] = {
        "c1": floats("--c1", c1) if c1 else [],
        "c2": floats("--c2", c2) if c2 else [],
        **swept,
        "range": sweep("--range", sensing_range, lo=1e-9, hi=math.inf, inf=True),
        "fov": sweep("--fov", fov, lo=1e-3, hi=2 * math.pi),
        "noise": sweep("--noise", noise, lo=0.0, hi=math.pi),
        "loss": sweep("--loss", loss, lo=0.0, hi=1.0),
        "delay": sweep("--delay", delay, lo=0.0, hi=math.inf),
        "safety": sweep("--safety", safety, lo=0.0, hi=1.0),
        "gamma": sweep("--gamma", gamma, lo=1e-9, hi=1e6),
    }
    labels.update({k: f"--{k}" for k in grid if k not in labels})
    labels["engine"] = "--engine batch"
    with _running(scheduler, jobs, out, plot, quiet, resume, run_timeout, {**labels, **LABELS}) as common:
        result = run_scenario(
            path,
            grid=grid,
            seeds=seeds,
            positions=positions,
            headings=spin,
            speeds=speeds,
            duration=duration,
            engine=engine,
            **common,
        )
    _stopped(result)
    table(
        result.summary,
        [
            ("setting", "setting", str),
            ("runs", "runs", str),
            *([("timeouts", "timeouts", str)] if any(r.get("timeouts") for r in result.summary) else []),
            ("converged", "converged_fraction", num(".1%")),
            ("settle med s", "settling_median_s", num(".1f")),
            ("settle p90 s", "settling_p90_s", num(".1f")),
            ("switches med", "switches_median", num("g")),
            ("max", "switches_max", num("g")),
            ("crashes", "crashes", str),
        ],
    )
    safety_table(result.summary)
    state_table(result.summary)
    typer.echo(
        f"wall time {result.wall_s:.1f} s. converged: every agent ends within 1% of its expected radius; settle: "
        "the last agent into the 2% band, over the converged runs; switches: per follower"
    )
    _done(result)
