"""Commands that run a scenario (`swarm sim / world / up / agent`): the options they share
are declared once, below, as `Annotated` types."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.offline_cli import ScenarioArg, fail, read_scenario, render_run_plots


def _out_option(help: str):
    return Annotated[Optional[Path], typer.Option("--out", "-o", help=help)]


SimOutOpt = _out_option("output directory (default runs/<scenario>-sim-<time>)")
UpOutOpt = _out_option("output directory (default runs/<scenario>-up-<time>)")
WorldOutOpt = _out_option("where to write the results")
DurationOpt = Annotated[Optional[float], typer.Option(help="simulated seconds (default: the "
                                                      "scenario's run.duration)", min=0.0)]
ClockOpt = Annotated[Optional[str], typer.Option(help="lockstep | realtime (default: the scenario's)")]
TimeScaleOpt = Annotated[float, typer.Option("--time-scale", "--speed", help="realtime clock: simulated "
                                             "seconds per wall second", min=1e-6)]
EndPlotsOpt = Annotated[bool, typer.Option(help="render PNG plots at the end")]


def default_out(scenario_path: Path, kind: str) -> Path:
    return Path("runs") / f"{scenario_path.stem}-{kind}-{time.strftime('%Y%m%d-%H%M%S')}"


def _check_duration(duration: float | None, dt: float) -> None:
    if duration is not None and duration < dt:
        raise fail(f"--duration {duration} s is shorter than one step (dt = {dt} s)")


def _check_clock(clock: str | None) -> None:
    if clock is not None and clock not in ("lockstep", "realtime"):
        raise fail(f"--clock must be lockstep or realtime, not {clock!r}")


def _new_run_id(scenario_path: Path) -> str:
    import re
    import secrets

    stem = re.sub(r"[^A-Za-z0-9_.-]", "-", scenario_path.stem)[:40] or "run"
    return f"{stem}-{secrets.token_hex(3)}"


def _progress_bar(label: str):
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn(label), BarColumn(), TextColumn("{task.completed}/{task.total} ticks"),
                    TimeRemainingColumn(), transient=True, disable=not sys.stderr.isatty())


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


def sim(
    scenario: ScenarioArg,
    out: SimOutOpt = None,
    duration: DurationOpt = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots")] = True,
) -> None:
    """Run a scenario in one process (the reference engine) and write its results.

    Writes summary.json, trajectory.npz and PNG plots into --out.

    Example: swarm sim scenarios/case2.toml --out runs/case2
    """
    from world.recording import write_run
    from swarm.sim import run_sim

    s = read_scenario(scenario)
    _check_duration(duration, s.run.dt)
    out = out or default_out(scenario, "sim")
    total = int(round((duration or s.run.duration) / s.run.dt))
    t0 = time.perf_counter()
    with _progress_bar(f"sim {scenario.stem}") as prog:
        task = prog.add_task("sim", total=total)
        result = run_sim(s, duration, lambda k, n: prog.update(task, completed=k))
    wall = time.perf_counter() - t0
    result.extra["wall_time"] = wall
    result.extra["sim_seconds_per_wall_second"] = total * s.run.dt / wall if wall > 0 else None
    summary = write_run(result, out)
    _print_summary(summary, out)
    typer.echo(f"speed: {total * s.run.dt / wall:.1f} simulated s per wall s ({total / wall:.0f} ticks/s)")
    if plots:
        render_run_plots(out)


def world(
    scenario: ScenarioArg,
    listen: Annotated[Optional[str], typer.Option(help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 "
                                                  "or unixsock-stream/PATH (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    run: Annotated[Optional[str], typer.Option(help="run id: the key prefix (default <scenario>-<random>)")] = None,
    out: WorldOutOpt = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds", min=0.0)] = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    join_timeout: Annotated[Optional[float], typer.Option(help="give up if not every agent joined "
                                                          "within this many s (default: wait)")] = None,
    plots: EndPlotsOpt = True,
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
    _check_clock(clock)
    listen = listen or default_endpoint(run)
    out = out or default_out(scenario, "up")
    typer.echo(f"run {run} on {listen}; results in {out}", err=True)
    code = run_world(WorldConfig(s, run, listen, out, clock, time_scale, duration, join_timeout))
    if plots and code in (0, 130, 143) and (out / "trajectory.npz").exists():
        render_run_plots(out)
    raise typer.Exit(code)


def up(
    scenario: ScenarioArg,
    out: UpOutOpt = None,
    duration: DurationOpt = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    listen: Annotated[Optional[str], typer.Option(help="endpoint of the run (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    plots: EndPlotsOpt = True,
) -> None:
    """Run a scenario as a distributed system: a world process and one OS process per agent.

    Prints the endpoint and run id (so another terminal can attach), live progress, and a
    summary; writes summary.json, trajectory.npz, plots and logs/ into --out. Ctrl-C stops
    cleanly: results written, no process left behind, exit 130 (143 for SIGTERM).

    Example: swarm up scenarios/case2.toml --out runs/case2
    """
    from swarm.launcher import Launcher, UpConfig

    s = read_scenario(scenario)
    _check_clock(clock)
    _check_duration(duration, s.run.dt)
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
            render_run_plots(out)
    raise typer.Exit(code)


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


def register(app: typer.Typer) -> None:
    """Add the run commands to the main app."""
    app.command("up")(up)
    app.command("sim")(sim)
    app.command("world")(world)
    app.command("agent")(agent)
