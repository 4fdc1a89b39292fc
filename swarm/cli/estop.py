"""`swarm estop`: every robot of a run zero-twisted straight onto the robots' network, then the
run ended through its world; with the world running, stalled or gone (swarm/api/estop.py,
docs/guides/robots.md#estop)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.options import ConnectOpt, CredentialsOpt, LiveRunOpt


def _out(line: str) -> None:
    typer.echo(line)


def estop(
    robots: Annotated[
        Optional[Path],
        typer.Option(
            "--robots",
            metavar="FILE",
            help="the robots file (default: the one of the run's swarm up on this machine, from its record in "
            "the runtime dir)",
            show_default=False,
        ),
    ] = None,
    robots_only: Annotated[
        bool, typer.Option("--robots-only", help="zero-twist the robots and leave the run alone")
    ] = False,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
) -> None:
    """Stop every robot now: zero twists straight onto the robots' network, then end the run.

    The robots first: a zenoh client of the robots' router (the robots file's [ros2] connect
    and credentials) sends every robot a zero twist, three times, and goes on sending one
    every 50 ms until the run has ended. The robots file is --robots FILE, or the one of the
    run's `swarm up --robots` on this machine (its record in the runtime dir, while it runs;
    --run picks one of several). Then the run: a world that answers is asked to stop, as
    `swarm stop` does (the run's operator credentials); a world stopped with SIGSTOP is
    killed (SIGKILL), and its swarm up ends the run; a world that is gone: its swarm up ends
    the run by itself. The first line comes as soon as the robots were sent their zero twist.

    Exit codes: 0 every robot sent a zero twist, 1 the robots' router cannot be reached (the
    run is still ended), 2 no robots file known (give --robots FILE).

    Example: swarm estop
    """
    from swarm.api.estop import estop as do_estop  # lazy: zenoh and the robots' protocol, for this command only

    done = do_estop(run, robots, connect, credentials, end=not robots_only, say=_out)
    for line in done.lines()[1:]:
        _out(line)


def register(app: typer.Typer) -> None:
    """Add `swarm estop` to the main app."""
    app.command("estop")(estop)
