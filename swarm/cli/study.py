"""`swarm study swarms|gains`: the batch studies of swarm/study/swarms.py and swarm/study/gains.py
as commands, with a progress bar, a printed table, CSV files and a plot; Ctrl-C keeps
every finished row."""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from swarm.cli.errors import stop_code
from swarm.contracts.vocabulary import ExitCode

study_app = typer.Typer(
    help="Batch studies with the in-process engine: does the law converge for my kind of swarm?",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _fail(message: str, code: int = ExitCode.USAGE) -> typer.Exit:
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def _floats(option: str, text: str, *, positive: bool = True, allow_inf: bool = False) -> list[float]:
    """'1,2.5' -> [1.0, 2.5]; 'inf' where allowed; a clear message naming the option."""
    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            v = float(part)
        except ValueError:
            raise _fail(f"{option}: {part!r} is not a number (give a comma-separated list, e.g. 1,2.5)") from None
        if math.isnan(v) or (math.isinf(v) and not allow_inf) or (positive and v <= 0):
            raise _fail(
                f"{option}: {part!r} must be a {'positive ' if positive else ''}finite number"
                + (" or inf" if allow_inf else "")
            )
        out.append(v)
    return out


def _ints(option: str, text: str, minimum: int) -> list[int]:
    out = []
    for part in text.split(","):
        try:
            v = int(part.strip())
        except ValueError:
            raise _fail(f"{option}: {part.strip()!r} is not a whole number") from None
        if v < minimum:
            raise _fail(f"{option}: {v} must be at least {minimum}")
        out.append(v)
    return out


def _run(
    worker, jobs: list, jobs_n: int, csv_path: Path, columns: list[str], label: str, total: int
) -> tuple[list[dict], bool]:
    """Run jobs (`total` runs: a job may be a batch of them) with a progress bar, streaming
    rows to csv_path; (rows, interrupted)."""
    # lazy: rich.progress (~20 ms with rich), which `swarm --help` must not pay
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from swarm.study.pool import CsvSink, run_rows  # lazy: the worker pool (multiprocessing), not for `swarm --help`

    rows: list[dict] = []
    sink = CsvSink(csv_path, columns)
    tty = sys.stderr.isatty()
    last = [time.monotonic()]
    prog = Progress(
        TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), transient=True, disable=not tty
    )

    def on_row(row: dict) -> None:
        sink(row)
        rows.append(row)
        prog.update(task, completed=len(rows))
        if not tty and (time.monotonic() - last[0] > 10 or len(rows) == total):
            last[0] = time.monotonic()
            typer.echo(f"{label}: {len(rows)}/{total} runs", err=True)

    interrupted = False
    with prog:
        task = prog.add_task(label, total=total)
        try:
            run_rows(worker, jobs, jobs_n, on_row)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            sink.close()
    if interrupted:
        typer.echo(f"stopped: {len(rows)} of {total} runs finished, kept in {csv_path}", err=True)
    return rows, interrupted


def _study(
    kind: str,
    worker,
    job_list: list,
    columns: list[str],
    summarise: Callable,
    jobs: int,
    out: Optional[Path],
    what: str,
    total: int,
) -> tuple[Path, list[dict], list[dict], bool]:
    """Run a study's jobs (`total` runs) into out/runs.csv and its summary into
    out/summary.csv; (out, rows, summary, interrupted)."""
    from swarm.study.pool import write_csv  # lazy: the worker pool (multiprocessing), not for `swarm --help`

    out = out or Path("runs") / f"study-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"
    typer.echo(f"{what} on {jobs or os.cpu_count()} process(es); rows -> {out / 'runs.csv'}")
    rows, stopped = _run(
        worker, job_list, jobs or os.cpu_count() or 1, out / "runs.csv", columns, f"study {kind}", total
    )
    summary = summarise(rows)
    write_csv(out / "summary.csv", summary)
    return out, rows, summary, stopped


def _done(out: Path, stopped: bool) -> None:
    """The last line; exit 130 when Ctrl-C cut the study short (143: SIGTERM)."""
    typer.echo(f"results: {out}")
    if stopped:
        raise typer.Exit(stop_code())


def _table(rows: list[dict], columns: list[tuple[str, str, Callable]]) -> None:
    widths = [max(len(h), *(len(fmt(r[k])) for r in rows)) if rows else len(h) for h, k, fmt in columns]
    typer.echo("  ".join(h.rjust(w) for (h, _, _), w in zip(columns, widths)))
    for r in rows:
        typer.echo("  ".join(fmt(r[k]).rjust(w) for (_, k, fmt), w in zip(columns, widths)))


def _safety_table(summary: list[dict]) -> None:
    """The safety figures per setting, when the runs measured them (a [safety] table)."""
    if not any("collisions" in r for r in summary):
        return
    _table(
        summary,
        [
            ("setting", "setting", str),
            ("safe runs", "safe_runs", str),
            ("collisions", "collisions", str),
            ("exits", "boundary_exits", str),
            ("saturations", "saturations", str),
            ("min dist m", "min_distance", _num(".3g")),
            ("interventions", "interventions", str),
            ("no safe cmd", "infeasible", str),
        ],
    )


def _num(fmt: str) -> Callable:
    return lambda v: "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


DtOpt = Annotated[float, typer.Option(help="step (s)", min=1e-4)]
JobsOpt = Annotated[int, typer.Option("--jobs", "-j", min=0, help="worker processes (0: one per core)")]
OutOpt = Annotated[
    Optional[Path], typer.Option("--out", "-o", help="output directory (default runs/study-<kind>-<time>)")
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
    # lazy: numpy and the scenario model (~0.18 s), not for `swarm --help`
    from swarm.study.swarms import SwarmSetting, run_swarm, summarise_swarms, swarm_columns, swarm_jobs

    rules = [r.strip() for r in selection.split(",")]
    for r in rules:
        if r not in ("sticky", "rooted", "nearest"):
            raise _fail(f"--selection: {r!r} is not one of sticky, rooted, nearest")
    vmin, vmax = (_floats("--speeds", speeds) + [math.nan])[:2]
    if not (len(speeds.split(",")) == 2 and vmin <= vmax):
        raise _fail("--speeds: give MIN,MAX with MIN <= MAX, e.g. 15,40")
    ns, ls = _ints("--n", n, 2), _ints("--leaders", leaders, 1)
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
        for a in ns
        for b in ls
        for r in rules
        for rg in _floats("--range", sensing_range, allow_inf=True)
        if b < a
    ]
    if not settings:
        raise _fail("--leaders: every setting has as many leaders as agents; a swarm needs a follower")
    runs = len(settings) * seeds
    worker: Callable[[Any], Any]  # a run, or a batch of runs (the batch engine)
    job_list: list[Any]
    if batch:
        from swarm.study.batch import run_swarm_chunk, swarm_chunks  # lazy: as swarm.study.swarms

        worker, job_list = run_swarm_chunk, swarm_chunks(settings, range(seeds), jobs or os.cpu_count() or 1)
    else:
        worker, job_list = run_swarm, swarm_jobs(settings, range(seeds))
    out, rows, summary, stopped = _study(
        "swarms",
        worker,
        job_list,
        swarm_columns(),
        summarise_swarms,
        jobs,
        out,
        f"{len(settings)} setting(s) x {seeds} seeds = {runs} runs of {duration:g} s (dt {dt:g} s), "
        + (f"{len(job_list)} batches" if batch else "per-agent engine"),
        runs,
    )
    _table(
        summary,
        [
            ("setting", "setting", str),
            ("runs", "runs", str),
            ("converged", "converged_fraction", _num(".1%")),
            ("cut off (conv.)", "cut_off", str),
            ("", "cut_off_converged", lambda v: f"({v})"),
            ("settle med s", "settling_median_s", _num(".0f")),
            ("settle p90 s", "settling_p90_s", _num(".0f")),
            ("switches med", "switches_median", _num("g")),
            ("p90", "switches_p90", _num("g")),
            ("max", "switches_max", _num("g")),
            ("search med s", "searching_median_s", _num(".1f")),
            ("per loss max", "loss_switches_max", _num("g")),
        ],
    )
    _safety_table(summary)
    typer.echo(
        "converged: share of all runs in which every agent ends within 1% of its expected radius; "
        "cut off: runs with a follower that has no sensing path to a leader at t = 0; switches: "
        "per follower; search: s a follower spends with nobody to steer by (median over runs of "
        "the mean per follower); per loss: the most switches one loss of an out-neighbour cost"
    )
    if plot and summary:
        from swarm.study.figures import plot_swarms  # lazy: matplotlib (~0.3 s), for the figure only

        typer.echo(f"plot: {plot_swarms(summary, rows, out / 'study.png')}")
    _done(out, stopped)


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
) -> None:
    """Where does the follower law settle? A map of (C1, C2) against speed ratio.

    One follower behind a leader already on its orbit (omega = 1 rad/s), for every
    (C1, C2, speed ratio), from a few random starts: the worst time into the 2% band, or
    never. Writes runs.csv, summary.csv, gains.png.

    Example: swarm study gains --c1 0.5,1,2 --c2 0.2,0.5,1 --starts 3
    """
    # lazy: numpy and the scenario model (~0.18 s), not for `swarm --help`
    from swarm.study.gains import gain_columns, gain_jobs, run_gain, summarise_gains

    runs = gain_jobs(_floats("--c1", c1), _floats("--c2", c2), _floats("--ratios", ratios), starts, duration, dt)
    worker: Callable[[Any], Any]  # a run, or a batch of runs (the batch engine)
    job_list: list[Any]
    if batch:
        from swarm.study.batch import gain_chunks, run_gain_chunk  # lazy: as swarm.study.gains

        worker, job_list = run_gain_chunk, gain_chunks(runs, jobs or os.cpu_count() or 1)
    else:
        worker, job_list = run_gain, runs
    out, rows, summary, stopped = _study(
        "gains",
        worker,
        job_list,
        gain_columns(),
        summarise_gains,
        jobs,
        out,
        f"{len(runs)} runs of {duration:g} s, " + (f"{len(job_list)} batches" if batch else "per-agent engine"),
        len(runs),
    )
    _gain_table(summary)
    if plot and summary:
        from swarm.study.figures import plot_gains  # lazy: matplotlib (~0.3 s), for the figure only

        typer.echo(f"plot: {plot_gains(summary, out / 'gains.png', duration)}")
    _done(out, stopped)


def _gain_table(summary: list[dict]) -> None:
    """Rows (C1, C2), columns speed ratio: worst settling time (s), '-' for never."""
    ratios = sorted({r["ratio"] for r in summary})
    cells = {(r["c1"], r["c2"], r["ratio"]): r["worst_settling_s"] for r in summary}
    pairs = sorted({(r["c1"], r["c2"]) for r in summary})
    typer.echo("worst time into the 2% band (s; '-': never), rows C1, C2; columns follower/leader speed ratio")
    typer.echo(f"{'C1':>5} {'C2':>5} " + " ".join(f"{q:>6g}" for q in ratios))
    for a, b in pairs:
        vals = [cells.get((a, b, q), math.nan) for q in ratios]
        typer.echo(f"{a:>5g} {b:>5g} " + " ".join(f"{v:>6.0f}" if math.isfinite(v) else f"{'-':>6}" for v in vals))


def _sweep(option: str, text: Optional[str], *, lo: float, hi: float, inf: bool = False) -> list[float]:
    """A swept list option: numbers in [lo, hi] (inf too where allowed)."""
    if text is None:
        return []
    out = []
    for v in _floats(option, text, positive=False, allow_inf=inf):
        if not (lo <= v <= hi or (inf and math.isinf(v) and v > 0)):
            raise _fail(f"{option}: {v:g} is out of range [{lo:g}, {hi:g}]" + (" (or inf)" if inf else ""))
        out.append(v)
    return out


def _params(texts: list[str]) -> dict[str, list[float]]:
    out = {}
    for t in texts:
        name, eq, values = t.partition("=")
        if not eq or not name.strip().isidentifier():
            raise _fail(f"--param: {t!r}: give NAME=V1,V2,... (e.g. k=0.1,0.2)")
        out[f"param.{name.strip()}"] = _floats(f"--param {name.strip()}", values, positive=False)
    return out


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
        Optional[list[str]], typer.Option(help="a law parameter (law.params) NAME=V1,V2,... (repeat for more)")
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
    jobs: Annotated[
        int, typer.Option("--jobs", "-j", "--workers", min=0, help="worker processes (0: one per core)")
    ] = 0,
    out: OutOpt = None,
    plot: Annotated[bool, typer.Option(help="write study.png and sweep.png")] = True,
) -> None:
    """Your scenario, your law: vary it over seeds and settings; where does it converge?

    The scenario file is the template. Every seed draws its own jitter of positions,
    headings and speeds (and is the run's seed, run.seed, which drives loss and noise); every
    combination of the lists (--c1, --c2, --param, --range, --fov, --noise, --loss,
    --delay, --safety, --gamma) is one setting, run over the same seeds. Any law runs: a follower law that
    declares itself vectorised goes through the batch engine, any other through swarm
    sim's per-agent engine on every core (the engine used is printed; docs/design/studies.md).

    Writes runs.csv (one row per run, as it finishes), summary.csv, study.png, and
    sweep.png (converged share and settling time against each swept parameter).

    Example: swarm study scenario scenarios/case2.toml --seeds 100 --positions 10 --headings uniform --noise 0,0.02,0.05
    """
    # lazy: numpy, the scenario model and the engines (~0.3 s), not for `swarm --help`
    from swarm.contracts.scenario import load_scenario
    from swarm.study.batch import chunk_size
    from swarm.study.scenario import (
        Jitter,
        Template,
        columns,
        engine_for,
        jobs_of,
        run_chunk,
        run_one,
        settings_of,
        summarise,
        varied,
    )

    if engine not in ("auto", "batch", "per-agent"):
        raise _fail(f"--engine: {engine!r} is not one of auto, batch, per-agent")
    if headings.strip() == "uniform":
        spin = math.inf
    else:
        (spin,) = _sweep("--headings", headings, lo=0.0, hi=math.pi) if "," not in headings else [math.nan]
        if math.isnan(spin):
            raise _fail("--headings: give one number (rad) or 'uniform'")
    sweeps: dict[str, list[float]] = {
        "c1": _floats("--c1", c1) if c1 else [],
        "c2": _floats("--c2", c2) if c2 else [],
        **_params(param or []),
        "range": _sweep("--range", sensing_range, lo=1e-9, hi=math.inf, inf=True),
        "fov": _sweep("--fov", fov, lo=1e-3, hi=2 * math.pi),
        "noise": _sweep("--noise", noise, lo=0.0, hi=math.pi),
        "loss": _sweep("--loss", loss, lo=0.0, hi=1.0),
        "delay": _sweep("--delay", delay, lo=0.0, hi=math.inf),
        "safety": _sweep("--safety", safety, lo=0.0, hi=1.0),
        "gamma": _sweep("--gamma", gamma, lo=1e-9, hi=1e6),
    }
    sweeps = {k: v for k, v in sweeps.items() if v}
    if any(v not in (0.0, 1.0) for v in sweeps.get("safety", [])):
        raise _fail("--safety: 0 (off, measuring only) or 1 (on)")
    spec = load_scenario(path)
    for opt in ("safety", "gamma"):
        if opt in sweeps and spec.safety is None:
            raise _fail(f"--{opt}: {path} has no [safety] table (docs/guides/scenarios.md#safety)")
    template = Template(spec.model_dump(), str(path), (str(path.resolve().parent),), duration)
    jitter = Jitter(positions, spin, speeds)
    settings = settings_of(sweeps)
    firsts = [varied(template, st, jitter, 0) for st in settings]  # a setting the model refuses fails here
    batched, why = engine_for(firsts)
    if engine == "batch" and batched != "batch":
        raise _fail(f"--engine batch: the batch engine does not run this study: {why}")
    use_batch = batched == "batch" and engine != "per-agent"
    workers = jobs or os.cpu_count() or 1
    run_s = firsts[0].run.duration
    if use_batch:
        per = chunk_size(seeds, workers, len(firsts[0].agents), int(round(run_s / firsts[0].run.dt)))
        worker: Callable[[Any], Any] = run_chunk
        line = f"engine: batch ({why}), {per} runs per batch"
    else:
        per = 1
        worker = run_one
        line = "engine: per-agent (swarm sim's), one run per job" + (
            f": the batch engine refuses, {why}" if batched != "batch" else " (--engine per-agent)"
        )
    job_list = jobs_of(template, settings, jitter, seeds, per)
    runs = len(settings) * seeds
    typer.echo(line)
    t0 = time.perf_counter()
    out, rows, summary, stopped = _study(
        "scenario",
        worker,
        job_list,
        columns(settings),
        lambda rs: summarise(rs, settings),
        jobs,
        out,
        f"{len(settings)} setting(s) x {seeds} seeds = {runs} runs of {run_s:g} s of {path.name}",
        runs,
    )
    wall = time.perf_counter() - t0
    _table(
        summary,
        [
            ("setting", "setting", str),
            ("runs", "runs", str),
            ("converged", "converged_fraction", _num(".1%")),
            ("settle med s", "settling_median_s", _num(".1f")),
            ("settle p90 s", "settling_p90_s", _num(".1f")),
            ("switches med", "switches_median", _num("g")),
            ("max", "switches_max", _num("g")),
            ("crashes", "crashes", str),
        ],
    )
    _safety_table(summary)
    typer.echo(
        f"wall time {wall:.1f} s. converged: every agent ends within 1% of its expected radius; settle: the "
        "last agent into the 2% band, over the converged runs; switches: per follower"
    )
    if plot and summary:
        # lazy: matplotlib (~0.3 s), for the figures only
        from swarm.study.figures import plot_scenario_study, plot_sweep

        varies = ", ".join(
            [f"positions +-{positions:g} m"] * bool(positions)
            + [f"headings {'uniform' if math.isinf(spin) else f'+-{spin:g} rad'}"] * bool(spin)
            + [f"speeds x(1+-{speeds:g})"] * bool(speeds)
        )
        title = f"swarm study scenario {path.name}: {seeds} seeds" + (f" ({varies})" if varies else "")
        typer.echo(f"plot: {plot_scenario_study(summary, rows, out / 'study.png', title)}")
        swept = [k for k, v in sweeps.items() if len(v) > 1]
        if swept:
            typer.echo(f"plot: {plot_sweep(rows, swept, out / 'sweep.png', title)}")
    _done(out, stopped)
