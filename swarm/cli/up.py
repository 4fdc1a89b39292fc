"""`swarm up`: a scenario as a distributed system, from the command line: it checks the
options, calls `swarm.launch` (swarm/api/launch.py: the launcher, swarm/runtime/launcher.py, in
this process; SIGINT and SIGTERM stop it) and renders what it reports: the run id and how
to attach, the progress line while it runs (swarm/runtime/progress.py), then one line on how it
ended, the summary, the plots, the agents that failed, and the exit code. The options it
shares with the other run commands are swarm/cli/run.py's."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.options import (
    ClockOpt,
    DurationOpt,
    EndPlotsOpt,
    ForceOpt,
    FoxgloveHostOpt,
    FoxgloveOpt,
    FoxglovePortOpt,
    ScenarioArg,
    TimeScaleOpt,
    check_clock,
    check_duration,
    check_foxglove,
    check_runtime_dir,
    read_scenario,
)
from swarm.cli.output import print_summary, render_run_plots
from swarm.cli.run import ROBOTS_LOCKSTEP, RobotsOpt
from swarm.contracts import credentials
from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.progress import Paused, ProgressLine
from swarm.world.live_view import live_url

UpOutOpt = Annotated[  # (options.out_option's shape, written out: mypy takes no call for a type)
    Optional[Path],
    typer.Option(
        "--out",
        "-o",
        help="output directory (default runs/<run id>); one that already holds results is refused unless --force",
    ),
]


def up(
    scenario: ScenarioArg,
    out: UpOutOpt = None,
    duration: DurationOpt = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    listen: Annotated[
        Optional[str],
        typer.Option(help="endpoint of the run (default: a Unix socket in $SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)"),
    ] = None,
    plots: EndPlotsOpt = True,
    force: ForceOpt = False,
    world_grace: Annotated[
        float,
        typer.Option(
            help="s the agents wait for a world that stopped answering (a stalled, not a vanished, world)", min=0.0
        ),
    ] = 10.0,
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
    robots: RobotsOpt = None,
) -> None:
    """Run a scenario as a distributed system: a world process and one OS process per agent.

    Prints the endpoint and run id (so another terminal can attach), live progress, and a
    summary; writes summary.json, trajectory.npz, plots and logs/ into --out. Ctrl-C stops
    cleanly: results written, no process left behind, exit 130 (143 for SIGTERM). With
    --robots FILE the agents drive ROS 2 robots (docs/guides/robots.md), on the realtime clock.

    Example: swarm up scenarios/case2.toml --out runs/case2
    """
    # lazy: the launcher and the API's run modules (numpy, the scenario model: ~0.17 s), not for `swarm --help`
    from swarm.api.launch import launch
    from swarm.robots.config import RobotsError

    s = read_scenario(scenario)
    check_clock(clock)
    if robots is not None:
        if clock == "lockstep":
            raise fail(f"swarm up: {ROBOTS_LOCKSTEP}", ExitCode.USAGE)
        clock = "realtime"
        from swarm.robots.plant import robot_scenario  # lazy: the robots' plant (swarm.ros2), for --robots only

        s = robot_scenario(s)  # as its world runs it (no agent added: the attach hints say so)
    check_duration(s, duration, scenario)
    check_runtime_dir()
    live = (foxglove_host, foxglove_port) if foxglove else None
    if live is not None:
        check_foxglove(*live)

    launched = []

    def started(run) -> None:  # checked, nothing started yet: what another terminal needs
        launched.append(run)
        typer.echo(f"run {run.run_id}  endpoint {run.endpoint}  agents {len(s.agents)}  clock {clock or s.run.clock}")
        for line in attach_hints(run.run_id, run.dial, s):
            typer.echo(line)
        if live is not None:
            typer.echo(f"live view: {live_url(*live)}  (Foxglove: Open connection > Foxglove WebSocket)")
            typer.echo(run_layout(s, run.out))

    line, paused = ProgressLine(sys.stdout.isatty()), Paused()

    def progress(p: dict) -> None:  # "paused" from the world's pause/resume events the launcher heard
        line.show({**p, "paused": paused(launched[0].launcher.events) if launched else False})

    try:
        o = launch(
            scenario,
            out,
            force=force,
            duration=duration,
            clock=clock,
            time_scale=time_scale,
            listen=listen,
            foxglove=live,
            world_grace=world_grace,
            robots=robots,
            progress=progress,
            on_start=started,
        )  # SIGINT/TERM: stop
    except RobotsError as e:  # checked before anything starts
        raise fail(f"swarm up: {e}", e.exit_code) from None
    line.end()
    err: dict[str, Any] = dict(err=True, fg=typer.colors.RED)
    if o.words is not None:
        typer.secho(o.words, **(err if o.failed else {}))
    if o.recovered is not None:  # a world that died before writing its results: rebuilt from its recording
        typer.echo(o.recovered.line())
    elif o.recovery_error is not None:  # said why in one line; the exit code stays the run's
        typer.secho(o.recovery_error, **err)
    if o.summary is not None:
        print_summary(o.summary.to_dict(), o.out)
        if plots:
            render_run_plots(o.out)
    for r in o.exits if o.failure is None else []:
        typer.echo(f"  {r.line()}" + ("" if r.sent else "  (not in summary.json: the world did not hear of it)"))
    if robots is not None:
        # Everything is written and every process reaped. The robots' zenoh sessions
        # (swarm/robots/halt.py) can leave native threads that call into Python, and at the
        # interpreter's finalization one aborted `swarm up` in some runs on a loaded machine
        # ("FATAL: exception not rethrown", exit -6) after its results were out: leave without
        # finalization, with the run's exit code. (A workaround: the thread is not found yet.)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(int(o.exit_code))
    raise typer.Exit(o.exit_code)


def run_layout(s, out: Path) -> str:
    """Write a Foxglove layout for the scenario's agents into `out`; the line that says where
    (or, when it cannot be written, why: the run goes on, the live view works without it)."""
    # lazy: numpy and the scenario model, loaded by `swarm up` by then, not by `swarm --help`
    from swarm.offline.layout import scenario_agents, write_layout

    agents, extent, centre = scenario_agents(s)
    try:
        path = write_layout(out, agents, extent, centre)
    except OSError as e:
        return f"layout: not written ({out}: {e.strerror or e}); docs/foxglove-layout.json is case 2's"
    return f"layout for its {len(agents)} agents: {path}  (Foxglove: Layouts > Import from file)"


def attach_hints(run_id: str, dial: str, s) -> list[str]:
    """What to type in another terminal: watch the run (with --run when other runs are up,
    so the command cannot pick the wrong one), and add an agent by hand."""
    try:
        others = any(c.run != run_id for c in credentials.local_runs())
    except Exception:  # an unreadable runtime dir: swarm up says so itself
        others = True
    pick = f" --run {run_id}" if others else ""
    ids = s.added_id_range
    lines = [
        f"watch it from another terminal: swarm watch{pick}  (table: swarm agents{pick}; graph: "
        f"swarm graph{pick}" + (f"; or export SWARM_RUN={run_id} once" if others else "") + ")",
        f"add an agent by hand: swarm spawn --id N{pick} (a new id, {ids.start}..{ids.stop - 1}, with "
        "--x --y --heading --speed)"
        if ids
        else f"add an agent by hand: no new id ({s.added_ids_text()}); a dropped agent rejoins with "
        f"swarm spawn --id N{pick}",
    ]
    if not dial.startswith("unixsock"):
        lines.append(
            f"from another machine: swarm credentials --agent N{pick}, there swarm agent --id N "
            f"--connect {dial} --credentials FILE (docs/guides/several-machines.md#remote-agent)"
        )
    return lines


def register(app: typer.Typer) -> None:
    """Add `swarm up` to the main app."""
    app.command("up")(up)
