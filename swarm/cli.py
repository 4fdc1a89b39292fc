"""The `swarm` command line: small typer command groups, failures as one message and an exit code."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.contracts.scenario import Scenario, ScenarioError, load_scenario, scenario_json_schema

app = typer.Typer(
    help="swarm: an agent-per-process runtime for bearing-based circumnavigation over zenoh.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

ScenarioArg = Annotated[Path, typer.Argument(help="scenario file (TOML), e.g. scenarios/case2.toml",
                                             show_default=False)]


def fail(message: str, code: int = 2) -> "typer.Exit":
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def read_scenario(path: Path) -> Scenario:
    try:
        return load_scenario(path)
    except ScenarioError as e:
        raise fail(str(e), 2) from None


def default_out(scenario_path: Path, kind: str) -> Path:
    return Path("runs") / f"{scenario_path.stem}-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"


@app.command()
def check(scenario: ScenarioArg) -> None:
    """Validate a scenario file and print a short summary of it.

    Example: swarm check scenarios/case2.toml
    """
    s = read_scenario(scenario)
    r = s.run
    typer.echo(f"{scenario}: ok - {s.name or scenario.stem}")
    typer.echo(f"  run: dt={r.dt} s, duration={r.duration} s ({r.ticks} ticks), clock={r.clock}, "
               f"seed={r.seed}, on_dropout={r.on_dropout}")
    typer.echo(f"  target: ({s.target.x}, {s.target.y}) m; gains: law={s.gains.law}, "
               f"c1={s.gains.c1}, c2={s.gains.c2}")
    sens = s.sensing
    typer.echo(f"  sensing: range={'unlimited' if sens.range is None else f'{sens.range} m'}, "
               f"fov={'all round' if sens.fov is None else f'{sens.fov} rad'}, "
               f"selection={sens.selection}, hysteresis={sens.hysteresis}")
    for a in s.agents:
        extra = (f"R={a.orbit_radius} m {a.direction}" if a.role == "leader"
                 else f"follow={a.follow}" if a.follow is not None else f"out-neighbour: {sens.selection}")
        lim = "" if a.max_turn_rate is None else f", |u|<={a.max_turn_rate} rad/s"
        typer.echo(f"  agent {a.id:>3} {a.role:<8} at ({a.x:g}, {a.y:g}) heading {a.heading:g} rad, "
                   f"{a.speed:g} m/s, {extra}{lim}")
    for f in s.faults:
        who = "every agent" if f.agent is None else f"agent {f.agent}"
        more = ", ".join(f"{k}={v}" for k, v in (("duration", f.duration), ("probability", f.probability),
                                                  ("delay", f.delay), ("std", f.std)) if v is not None)
        typer.echo(f"  fault at {f.at:g} s: {f.kind} {who}" + (f" ({more})" if more else ""))
    _warn_nearest_graph(s)


def _warn_nearest_graph(s: Scenario) -> None:
    """Warn (exit 0) when the paper's nearest choice at t = 0 breaks Assumption 1."""
    from agents.selection import nearest
    from swarm.graph import analyse
    from world.core import WorldCore

    leaders = {a.id for a in s.agents if a.role == "leader"}
    out = {aid: (None if aid in leaders else (c.id if (c := nearest(f.contacts)) else None))
           for aid, f in WorldCore(s).frames().items()}
    g = analyse(out, leaders)
    problems = [f"follower-only cycle {' -> '.join(map(str, c + c[:1]))}" for c in g["cycles"]]
    lone = [i for i in g["unrooted"] if not any(i in c for c in g["cycles"])]
    if lone:
        problems.append(f"no path to a leader from {', '.join(map(str, lone))}")
    if not problems:
        return
    edges = ", ".join(f"{i}->{j}" for i, j in g["edges"])
    cure = {"nearest": "this run keeps re-choosing the nearest agent and may never converge; "
                       "selection = \"sticky\" (the default) keeps every follower rooted",
            "sticky": "selection = \"sticky\" roots these followers on the nearest agent that has a path",
            "rooted": "selection = \"rooted\" roots these followers on the nearest agent that has a path",
            "fixed": "this scenario pins its graph with `follow`"}[s.sensing.selection]
    typer.secho(f"  warning: nearest choice at t = 0 ({edges}) breaks the paper's Assumption 1: "
                f"{'; '.join(problems)}. {cure}.", fg=typer.colors.YELLOW)


@app.command()
def schema() -> None:
    """Print the JSON Schema of scenario files (for editors and tools).

    Example: swarm schema > scenario.schema.json
    """
    typer.echo(json.dumps(scenario_json_schema(), indent=2))


def _progress_bar(total: int, label: str):
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    prog = Progress(TextColumn(label), BarColumn(), TextColumn("{task.completed}/{task.total} ticks"),
                    TimeRemainingColumn(), transient=True, disable=not sys.stderr.isatty())
    return prog


def _print_summary(summary: dict, out: Path) -> None:
    typer.echo(f"converged: {summary['converged']}  ticks: {summary['ticks']}  "
               f"sim time: {summary['sim_time']:.2f} s  selection: {summary.get('selection', '-')}  "
               f"switches: {summary.get('switches', '-')}")
    typer.echo(f"  {'id':>3} {'role':<8} {'out':>4} {'root':>4} {'radius':>9} {'expected':>9} "
               f"{'error %':>8} {'rate':>8} {'settle s':>8} {'switches':>8}")
    for aid, a in summary["agents"].items():
        def f(v, fmt):
            return "-" if v is None else format(v, fmt)
        typer.echo(f"  {aid:>3} {a['role']:<8} {f(a['out_neighbour'], 'd'):>4} {f(a['root'], 'd'):>4} "
                   f"{a['final_radius']:9.3f} {f(a['expected_radius'], '9.3f'):>9} "
                   f"{f(None if a['relative_error'] is None else 100 * a['relative_error'], '8.3f'):>8} "
                   f"{f(a['angular_rate'], '8.4f'):>8} {f(a['settling_time'], '8.2f'):>8} "
                   f"{f(a.get('switches'), 'd'):>8}"
                   + ("" if a["alive"] else "  (dropped)"))
    typer.echo(f"results: {out}")


def _plots(out: Path) -> None:
    from swarm.plots import PlotError, render_plots

    try:
        files = render_plots(out)
    except PlotError as e:
        raise fail(str(e), 1) from None
    typer.echo("plots: " + ", ".join(p.name for p in files))


@app.command()
def sim(
    scenario: ScenarioArg,
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="output directory "
                                                "(default runs/<scenario>-sim-<time>)")] = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds (default: the "
                                                      "scenario's run.duration)", min=0.0)] = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots")] = True,
) -> None:
    """Run a scenario in one process (the reference engine) and write its results.

    Writes summary.json, trajectory.npz and PNG plots into --out.

    Example: swarm sim scenarios/case2.toml --out runs/case2
    """
    from world.recording import write_run
    from swarm.sim import run_sim

    s = read_scenario(scenario)
    if duration is not None and duration < s.run.dt:
        raise fail(f"--duration {duration} s is shorter than one step (dt = {s.run.dt} s)")
    out = out or default_out(scenario, "sim")
    total = int(round((duration or s.run.duration) / s.run.dt))
    t0 = time.perf_counter()
    with _progress_bar(total, f"sim {scenario.stem}") as prog:
        task = prog.add_task("sim", total=total)
        result = run_sim(s, duration, lambda k, n: prog.update(task, completed=k))
    wall = time.perf_counter() - t0
    result.extra["wall_time"] = wall
    result.extra["sim_seconds_per_wall_second"] = total * s.run.dt / wall if wall > 0 else None
    summary = write_run(result, out)
    _print_summary(summary, out)
    typer.echo(f"speed: {total * s.run.dt / wall:.1f} simulated s per wall s ({total / wall:.0f} ticks/s)")
    if plots:
        _plots(out)


@app.command()
def plot(run_dir: Annotated[Path, typer.Argument(help="a run directory written by swarm sim / swarm up")]) -> None:
    """Re-render the PNG plots of a run from its trajectory.npz and summary.json.

    Example: swarm plot runs/case2
    """
    if not run_dir.is_dir():
        raise fail(f"{run_dir}: not a directory", 2)
    _plots(run_dir)


def _new_run_id(scenario_path: Path) -> str:
    import re
    import secrets

    stem = re.sub(r"[^A-Za-z0-9_.-]", "-", scenario_path.stem)[:40] or "run"
    return f"{stem}-{secrets.token_hex(3)}"


@app.command()
def world(
    scenario: ScenarioArg,
    listen: Annotated[Optional[str], typer.Option(help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 "
                                                  "or unixsock-stream/PATH (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    run: Annotated[Optional[str], typer.Option(help="run id: the key prefix (default <scenario>-<random>)")] = None,
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="where to write the results")] = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds", min=0.0)] = None,
    clock: Annotated[Optional[str], typer.Option(help="lockstep | realtime (default: the scenario's)")] = None,
    time_scale: Annotated[float, typer.Option("--time-scale", "--speed", help="realtime clock: simulated "
                                              "seconds per wall second", min=1e-6)] = 1.0,
    join_timeout: Annotated[Optional[float], typer.Option(help="give up if not every agent joined "
                                                          "within this many s (default: wait)")] = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots at the end")] = True,
) -> None:
    """Run the world of a scenario by hand: the hub, physics, sensors and the recording.

    Agents join with `swarm agent --id N --connect ENDPOINT` from any terminal or machine.

    Example: swarm world scenarios/case2.toml --listen tcp/0.0.0.0:7447 --out runs/case2
    """
    from swarm.contracts.transport import default_endpoint
    from swarm.contracts.wire import WireError, check_run_id
    from world.process import WorldConfig, run_world

    s = read_scenario(scenario)
    run = run or _new_run_id(scenario)
    try:
        check_run_id(run)
    except WireError as e:
        raise fail(str(e)) from None
    clock = clock or s.run.clock
    if clock not in ("lockstep", "realtime"):
        raise fail(f"--clock must be lockstep or realtime, not {clock!r}")
    listen = listen or default_endpoint(run)
    out = out or default_out(scenario, "up")
    typer.echo(f"run {run} on {listen}; results in {out}", err=True)
    code = run_world(WorldConfig(s, run, listen, out, clock, time_scale, duration, join_timeout))
    if plots and code in (0, 130, 143) and (out / "trajectory.npz").exists():
        _plots(out)
    raise typer.Exit(code)


@app.command()
def up(
    scenario: ScenarioArg,
    out: Annotated[Optional[Path], typer.Option("--out", "-o", help="output directory "
                                                "(default runs/<scenario>-up-<time>)")] = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds (default: the "
                                                      "scenario's run.duration)", min=0.0)] = None,
    clock: Annotated[Optional[str], typer.Option(help="lockstep | realtime (default: the scenario's)")] = None,
    time_scale: Annotated[float, typer.Option("--time-scale", "--speed", help="realtime clock: simulated "
                                              "seconds per wall second", min=1e-6)] = 1.0,
    listen: Annotated[Optional[str], typer.Option(help="endpoint of the run (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots at the end")] = True,
) -> None:
    """Run a scenario as a distributed system: a world process and one OS process per agent.

    Prints the endpoint and run id (so another terminal can attach), live progress, and a
    summary; writes summary.json, trajectory.npz, plots and logs/ into --out. Ctrl-C stops
    cleanly: results written, no process left behind, exit 130 (143 for SIGTERM).

    Example: swarm up scenarios/case2.toml --out runs/case2
    """
    from swarm.launcher import Launcher, UpConfig

    s = read_scenario(scenario)
    if clock is not None and clock not in ("lockstep", "realtime"):
        raise fail(f"--clock must be lockstep or realtime, not {clock!r}")
    if duration is not None and duration < s.run.dt:
        raise fail(f"--duration {duration} s is shorter than one step (dt = {s.run.dt} s)")
    out = out or default_out(scenario, "up")
    run_id = _new_run_id(scenario)
    launcher = Launcher(UpConfig(scenario, s, out, run_id, listen, duration, clock, time_scale))
    typer.echo(f"run {run_id}  endpoint {launcher.endpoint}  agents {len(s.agents)}  "
               f"clock {clock or s.run.clock}")
    typer.echo(f"attach from another terminal: swarm agent --id N --connect {launcher.endpoint} --run {run_id}")
    total = int(round((duration or s.run.duration) / s.run.dt))
    tty = sys.stdout.isatty()
    state = {"last": 0.0, "tick": 0, "wall": 0.0}

    def show(p, wall):
        if p is None or (p["tick"] == state["tick"] and state["wall"] > 0):
            return
        now = time.monotonic()
        if not tty and now - state["last"] < 1.0 and p["tick"] < total - 1:
            return
        rate = (p["tick"] - state["tick"]) / max(wall - state["wall"], 1e-9)
        state.update(last=now, tick=p["tick"], wall=wall)
        errs = " ".join(f"{i}:{'-' if e is None else f'{100 * e:.1f}%'}" for i, e in sorted(p["errors"].items()))
        drop = f"  dropped {p['dropped']}" if p["dropped"] else ""
        line = (f"t={p['time']:7.2f}s tick {p['tick']}/{total} {rate:6.0f} ticks/s  "
                f"radial error {errs}{drop}")
        if tty:
            typer.echo("\r\033[K" + line[:200], nl=False)
        else:
            typer.echo(line)

    code = launcher.run(show)
    if tty:
        typer.echo("")
    summary_path = out / "summary.json"
    if launcher.stop_signal is not None:
        typer.echo(f"stopped by signal {launcher.stop_signal}; partial results in {out}")
        code = 128 + launcher.stop_signal
    elif code != 0:
        typer.secho(f"the world exited with code {code}; see {out / 'logs' / 'world.log'}", err=True,
                    fg=typer.colors.RED)
        code = 1
    if summary_path.exists():
        summary = json.loads(summary_path.read_text())
        _print_summary(summary, out)
        if plots:
            _plots(out)
    raise typer.Exit(code)


@app.command()
def agent(
    id: Annotated[int, typer.Option("--id", help="the agent's id in the scenario", min=0)],
    connect: Annotated[str, typer.Option(help="the world's endpoint, e.g. tcp/HOST:7447 or "
                                         "unixsock-stream/PATH")],
    run: Annotated[Optional[str], typer.Option(help="run id (default: the only run on the endpoint)")] = None,
    wait_world: Annotated[bool, typer.Option(help="keep waiting when the world vanishes")] = False,
) -> None:
    """Run one agent process; it takes its initial state from the world, so only its id is needed.

    Example: swarm agent --id 3 --connect tcp/127.0.0.1:7447
    """
    from agents.process import run_agent

    raise typer.Exit(run_agent(id, connect, run, wait_world))


from swarm.live_cli import register as _register_live  # noqa: E402

_register_live(app)

from swarm.study_cli import study_app  # noqa: E402

app.add_typer(study_app, name="study")


def main() -> None:
    app()


if __name__ == "__main__":
    main()
