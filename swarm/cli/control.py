"""Live commands that act on a run (`swarm kill / spawn / pause / resume`). Like the read-only
ones (swarm/cli/live.py, whose options they share), each parses its options, calls the Python
API (`swarm.connect(...)`: swarm/api/live.py; the acting itself is swarm/live/control.py) and
prints what it returns; the API's errors are mapped to one line and an exit code in
swarm/cli/errors.py. `kill` signals a process of this machine directly, and `spawn` starts one here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.api.live import connect as connect_run
from swarm.cli.options import ConnectOpt, CredentialsOpt, LiveRunOpt, TrustLawOpt
from swarm.contracts.wire import MAX_AGENT_ID


def kill(
    agent_id: Annotated[
        int, typer.Argument(metavar="ID", help="the agent's id", min=0, max=MAX_AGENT_ID, show_default=False)
    ],
    signal: Annotated[str, typer.Option("--signal", "-s", help="KILL | TERM | STOP | CONT")] = "KILL",
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    timeout: Annotated[
        Optional[float],
        typer.Option(help="s to wait for the world to drop the agent [default: 3]", min=0.0, show_default=False),
    ] = None,
) -> None:
    """Send a signal (default KILL) to an agent's process.

    On this machine it is os.kill; an agent on another host is asked over zenoh to
    signal itself (so SIGCONT cannot be delivered that way). Waits until the world drops
    the agent (KILL, TERM, STOP) and prints the tick.

    Example: swarm kill 3 --signal STOP
    """
    # lazy: swarm.live.control brings swarm.runtime.procs (~4 ms); pause, resume and spawn start without it
    from swarm.live.control import signal_name

    name = signal_name(signal)  # a bad name: exit 2 before looking for a run
    with connect_run(run, connect, credentials) as live:
        done = live.signal(agent_id, name)
        typer.echo(done.line())
        if done.drops:
            typer.echo(f"agent {agent_id} dropped at tick {live.wait_dropped(done, timeout)}")


def spawn(
    agent_id: Annotated[
        int,
        typer.Option(
            "--id",
            help="the agent's id: a dropped one rejoins from "
            "where it dropped; a new one needs --x --y --heading --speed",
            min=0,
            max=MAX_AGENT_ID,
            show_default=False,
        ),
    ],
    x: Annotated[Optional[float], typer.Option(help="new agent: x (m)", show_default=False)] = None,
    y: Annotated[Optional[float], typer.Option(help="new agent: y (m)", show_default=False)] = None,
    heading: Annotated[Optional[float], typer.Option(help="new agent: heading (rad)", show_default=False)] = None,
    speed: Annotated[Optional[float], typer.Option(help="new agent: speed (m/s)", show_default=False)] = None,
    role: Annotated[
        Optional[str], typer.Option(help="new agent: leader | follower [default: follower]", show_default=False)
    ] = None,
    orbit_radius: Annotated[
        Optional[float], typer.Option(help="new leader: orbit radius (m)", show_default=False)
    ] = None,
    direction: Annotated[
        Optional[str], typer.Option(help="new leader: ccw | cw [default: ccw]", show_default=False)
    ] = None,
    follow: Annotated[
        Optional[int], typer.Option(help="new follower: fixed out-neighbour id", show_default=False)
    ] = None,
    max_turn_rate: Annotated[
        Optional[float], typer.Option(help="new agent: turn-rate limit (rad/s)", show_default=False)
    ] = None,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    trust_law: TrustLawOpt = None,
    timeout: Annotated[
        Optional[float],
        typer.Option(help="s to wait for the agent to be live in the world [default: 10]", min=0.0, show_default=False),
    ] = None,
) -> None:
    """Start an agent process on this machine (detached) and wait until it is live.

    A dropped id rejoins from the pose it had; a new id joins the run with the given spec
    (new ids: the range `swarm check` shows for the scenario, up to run.max_added_agents).
    Its output goes to a log file in the runtime dir.

    Example: swarm spawn --id 7 --x 10 --y -5 --heading 0 --speed 20 --follow 1
    """
    spec = dict(
        x=x,
        y=y,
        heading=heading,
        speed=speed,
        role=role,
        orbit_radius=orbit_radius,
        direction=direction,
        follow=follow,
        max_turn_rate=max_turn_rate,
    )
    with connect_run(run, connect, credentials) as live:
        typer.echo(live.spawn(agent_id, trust_law or (), timeout, **spec).line())


def _clock(connect: str | None, run: str | None, credentials: Path | None, cmd: str, done: str) -> None:
    with connect_run(run, connect, credentials) as live:
        tick = live.pause() if cmd == "pause" else live.resume()
        typer.echo(f"run {live.run} {done} at tick {tick}")


def pause(connect: ConnectOpt = None, run: LiveRunOpt = None, credentials: CredentialsOpt = None) -> None:
    """Pause the world's clock and print the tick it stopped at.

    Agents stay connected; no tick happens until `swarm resume`.

    Example: swarm pause --run case2-1a2b3c
    """
    _clock(connect, run, credentials, "pause", "paused")


def resume(connect: ConnectOpt = None, run: LiveRunOpt = None, credentials: CredentialsOpt = None) -> None:
    """Resume the world's clock after `swarm pause` and print the tick.

    Example: swarm resume --run case2-1a2b3c
    """
    _clock(connect, run, credentials, "resume", "resumed")


def register(app: typer.Typer) -> None:
    """Add the acting live commands to the main app."""
    app.command("kill")(kill)
    app.command("spawn")(spawn)
    app.command("pause")(pause)
    app.command("resume")(resume)
