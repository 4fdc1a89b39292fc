"""Commands that run a scenario (`swarm sim / world / agent`, and `swarm up` in
swarm/cli/up.py): the options they share are declared once, below, as `Annotated` types."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.options import (
    ClockOpt,
    CredentialsOpt,
    DurationOpt,
    EndPlotsOpt,
    ForceOpt,
    FoxgloveHostOpt,
    FoxgloveOpt,
    FoxglovePortOpt,
    ScenarioArg,
    SimOutOpt,
    TimeScaleOpt,
    TrustLawOpt,
    WorldOutOpt,
    check_clock,
    check_duration,
    check_foxglove,
    check_runtime_dir,
    claim_out,
    default_out,
    read_scenario,
)
from swarm.cli.output import _progress_bar, print_summary, render_run_plots
from swarm.contracts import credentials as C
from swarm.contracts.identities import CredentialsError
from swarm.contracts.lifeline import LAUNCHER_PID_ENV
from swarm.contracts.stop_signals import signal_name
from swarm.contracts.transport import default_endpoint
from swarm.contracts.vocabulary import EventKind, ExitCode
from swarm.contracts.wire import MAX_AGENT_ID, WireError, check_run_id

log = logging.getLogger(__name__)

ROBOTS_LOCKSTEP = "--robots runs the realtime clock only (robots do not wait for a lockstep): drop --clock lockstep"
RobotsOpt = Annotated[
    Optional[Path],
    typer.Option(
        "--robots",
        help="drive ROS 2 robots through rmw_zenoh instead of simulating the agents: the robots file "
        "(which robot each agent drives; docs/guides/robots.md); realtime clock only",
    ),
]


def sim(
    scenario: ScenarioArg,
    out: SimOutOpt = None,
    duration: DurationOpt = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots")] = True,
    force: ForceOpt = False,
    batch: Annotated[
        bool,
        typer.Option(
            "--batch",
            help="step all agents as arrays (the batch engine: the "
            "same results, faster for many agents); refuses scenarios with "
            "faults or a law of one's own (follower or leader)",
        ),
    ] = False,
) -> None:
    """Run a scenario in one process (the reference engine) and write its results.

    Streams recording.mcap into --out as it runs, then writes trajectory.npz, summary.json
    and PNG plots. With --batch the batch engine runs it (summary.json says
    "engine": "sim-batch"; everything else is the same).

    Example: swarm sim scenarios/case2.toml --out runs/case2
    """
    # lazy: the engine's modules (numpy, the scenario model, the recording: ~0.3 s), not for `swarm --help`
    from swarm.api.runs import simulate
    from swarm.world.recording import RecordingError

    s = read_scenario(scenario)
    check_duration(s, duration, scenario)
    if batch:
        from swarm.offline.batch import refusal  # lazy: the batch engine's modules (~16 ms), for --batch only

        why = refusal(s)
        if why is not None:
            raise fail(f"swarm sim --batch: {scenario}: {why}; run it without --batch", ExitCode.USAGE)
    out = out or default_out(scenario, "sim")
    total = int(round((duration or s.run.duration) / s.run.dt))
    try:
        with _progress_bar(f"sim {scenario.stem}") as prog:
            task = prog.add_task("sim", total=total)
            results = simulate(
                s, duration, out, force=force, batch=batch, progress=lambda k, n: prog.update(task, completed=k)
            )
    except RecordingError as e:
        raise fail(f"swarm sim: {e}", ExitCode.NO_SPACE) from None
    summary, wall = results.summary.to_dict(), results.summary["wall_time"]
    print_summary(summary, out)
    typer.echo(f"speed: {total * s.run.dt / wall:.1f} simulated s per wall s ({total / wall:.0f} ticks/s)")
    if plots:
        render_run_plots(out)
    crashes = [ev for ev in summary["events"] if ev["kind"] == EventKind.CRASH]
    if crashes:  # as swarm up: results written, one line, exit 4
        first = crashes[0]
        raise fail(
            f"swarm sim: {len(crashes)} agent(s) failed: agent {first['agent']} at t = {first['time']:g} s: "
            f"its law raised {first['cause']} (results in {out})",
            ExitCode.AGENT_FAILED,
        )


def world(
    scenario: ScenarioArg,
    listen: Annotated[
        Optional[str],
        typer.Option(
            help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 "
            "or unixsock-stream/PATH (default: a Unix socket in "
            "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)"
        ),
    ] = None,
    run: Annotated[Optional[str], typer.Option(help="run id: the key prefix (default <scenario>-<random>)")] = None,
    out: WorldOutOpt = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds")] = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    join_timeout: Annotated[
        Optional[float], typer.Option(help="give up if not every agent joined within this many s (default: wait)")
    ] = None,
    plots: EndPlotsOpt = True,
    force: ForceOpt = False,
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
    robots: RobotsOpt = None,
) -> None:
    """Run the world of a scenario by hand: the hub, physics, sensors and the recording.

    Agents join with `swarm agent --id N --connect ENDPOINT` from any terminal or machine.
    With --out, the end prints the summary table `swarm up` prints. With --robots FILE the
    agents drive ROS 2 robots (their poses make the frames, their commands go to the robots).

    Example: swarm world scenarios/case2.toml --listen tcp/0.0.0.0:7447 --out runs/case2
    """
    # lazy: the world process's modules (numpy, the scenario model, the engine: ~0.3 s), not for `swarm --help`
    from swarm.world.main import run_world
    from swarm.world.process import WorldConfig

    s = read_scenario(scenario)
    check_duration(s, duration, scenario)
    check_runtime_dir()
    if not run:
        from swarm.api.launch import new_run_id  # lazy: the API's run modules, only when no --run is given

        run = new_run_id(scenario)
    try:
        check_run_id(run)
    except WireError as e:
        raise fail(str(e), ExitCode.USAGE) from None
    check_clock(clock)
    launched = bool(os.environ.get(LAUNCHER_PID_ENV))  # started by `swarm up`, which said what is to say
    plant = None
    if robots is not None:
        s, plant = _robot_world(s, robots, clock, time_scale, launched)
    clock = clock or s.run.clock
    listen = listen or default_endpoint(run)
    if foxglove:
        if out is None:
            raise fail(
                "--foxglove needs --out: the live view serves the run's recording as it is written", ExitCode.USAGE
            )
        check_foxglove(foxglove_host, foxglove_port)
    if out is not None:
        claim_out(out, force)
    log.info("run %s on %s; %s", run, listen, f"results in {out}" if out else "no results kept (no --out)")
    code = run_world(
        WorldConfig(
            s,
            run,
            listen,
            out,
            clock,
            time_scale,
            duration,
            join_timeout,
            foxglove=(foxglove_host, foxglove_port) if foxglove else None,
            plant=plant,
        )
    )
    if code in (ExitCode.INTERRUPTED, ExitCode.TERMINATED):  # (its results, if it listened, are written)
        typer.echo(f"swarm world: stopped by {signal_name(code - 128)}", err=True)
    summary = out / "summary.json" if out is not None else None
    # the table `swarm up` prints; not when the launcher runs us (it prints its own, and reads a
    # world's failure from the last line of its log)
    ended = (ExitCode.OK, ExitCode.INTERRUPTED, ExitCode.TERMINATED)
    if summary is not None and not launched and code in (*ended, ExitCode.DESERTED) and summary.exists():
        print_summary(json.loads(summary.read_text()), out)  # the table `swarm up` prints
    if plots and out is not None and code in ended and (out / "trajectory.npz").exists():
        render_run_plots(out)
    raise typer.Exit(code)


def _robot_world(s, robots: Path, clock: str | None, time_scale: float, launched: bool):
    """The scenario as the robot world runs it (realtime, no agent added) and its plant
    (swarm/robots/plant.py); one line and exit 2 for a robots file that does not fit the
    scenario or an explicit lockstep clock. The warnings of the robots file are printed here
    unless `swarm up` started us (it printed them)."""
    # lazy: the robots' plant (swarm.ros2, the robots file model), for --robots only
    from swarm.robots.config import RobotsError, check_against, load_robots
    from swarm.robots.plant import RobotPlant, robot_scenario

    if clock == "lockstep":
        raise fail(f"swarm world: {ROBOTS_LOCKSTEP}", ExitCode.USAGE)
    try:
        file = load_robots(robots)
        warnings = check_against(file, s, str(robots))
    except RobotsError as e:
        raise fail(f"swarm world: {e}", e.exit_code) from None
    if not launched:
        if s.run.clock != "realtime" and clock is None:
            typer.echo(f"robots: the realtime clock (the scenario says {s.run.clock})", err=True)
        for w in warnings:
            typer.echo(f"warning: robots: {w}", err=True)

    s = robot_scenario(s, file)  # the plant's notes: "[world] robots: ..." lines (the world's log)
    return s, RobotPlant(file, s, str(robots), time_scale=time_scale, say=log.info)


def agent(
    id: Annotated[int, typer.Option("--id", help="the agent's id in the scenario", min=0, max=MAX_AGENT_ID)],
    connect: Annotated[str, typer.Option(help="the world's endpoint, e.g. tcp/HOST:7447 or unixsock-stream/PATH")],
    run: Annotated[Optional[str], typer.Option(help="run id (default: the only run on the endpoint)")] = None,
    wait_world: Annotated[
        bool,
        typer.Option(help="keep waiting when the world vanishes (for a new world of the run) instead of exiting 4"),
    ] = False,
    world_grace: Annotated[
        float,
        typer.Option(
            help="s to wait for a world that stopped answering (a frozen or cut-off world; exit 5 after that)", min=0.0
        ),
    ] = 10.0,
    connect_timeout: Annotated[
        float, typer.Option(help="s to wait for a world to listen on --connect before giving up (exit 6)", min=0.0)
    ] = 10.0,
    world_wait: Annotated[
        Optional[float],
        typer.Option("--world-wait", hidden=True, min=0.0, help="the old name of --connect-timeout (deprecated)"),
    ] = None,
    credentials: CredentialsOpt = None,
    trust_law: TrustLawOpt = None,
) -> None:
    """Run one agent process; it takes its initial state from the world, so only its id is needed.

    It connects as agent-ID with the run's credentials: --credentials FILE, else
    $SWARM_CREDENTIALS, else the local run's file in the runtime directory. On another
    machine, use a file from `swarm credentials --agent ID` (see
    docs/guides/several-machines.md#remote-agent).

    Exit codes: 0 the run ended, 1 crashed (e.g. an exception in its law), 3 refused,
    4 the world vanished (unless --wait-world), 5 the world did not answer within
    --world-grace, 6 no world to join (nothing listened on --connect for --connect-timeout
    s), 130/143 stopped.

    Example: swarm agent --id 3 --connect tcp/10.0.0.5:7447 --credentials agent-3.cred
    """
    from swarm.agents.process import run_agent  # lazy: the agent process's modules (~6 ms), not for `swarm --help`

    if credentials is not None:  # a file that cannot be used: said now, not after waiting for the world
        try:
            C.read(credentials)
        except CredentialsError as e:
            raise fail(f"swarm agent {id}: {e}", ExitCode.REFUSED) from None
    wait = connect_timeout if world_wait is None else world_wait
    raise typer.Exit(
        run_agent(
            id,
            connect,
            run,
            wait_world,
            world_grace=world_grace,
            creds_file=credentials,
            trust=tuple(trust_law or ()),
            world_wait=wait,
        )
    )


def register(app: typer.Typer) -> None:
    """Add the run commands to the main app (`swarm up`: swarm/cli/up.py)."""
    app.command("sim")(sim)
    app.command("world")(world)
    app.command("agent")(agent)
