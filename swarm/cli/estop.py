"""`swarm estop`: every robot of a run zero-twisted straight onto the robots' network, then the
run ended through its world; with the world running, stalled or gone (swarm/api/estop.py,
docs/guides/robots.md#estop)."""

from __future__ import annotations

import sys
import time
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
    ready: Annotated[
        bool,
        typer.Option(
            "--ready",
            help="connect to the robots' router now and wait: Enter stops every robot (an e-stop kept ready "
            "in a terminal: no start-up time when it counts)",
        ),
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
    With --ready it connects first and waits: Enter stops them (keep it open in a terminal
    during a hardware run).

    Exit codes: 0 every robot sent a zero twist, 1 the robots' router cannot be reached (the
    run is still ended), 2 no robots file known (give --robots FILE).

    Example: swarm estop
    """
    from swarm.api.estop import estop as do_estop  # lazy: zenoh and the robots' protocol, for this command only
    from swarm.cli.estop_first import taken  # lazy: as above

    sent = taken()  # the zero twists sent before the command line loaded (swarm/cli/__init__.py)
    if ready:
        sent = _when_asked(run, robots)

    done = do_estop(run, robots, connect, credentials, end=not robots_only, say=_out, sent_first=sent)
    for line in done.lines()[1:]:
        _out(line)


def _when_asked(run: str | None, robots: Path | None):
    """--ready: the session open, one line, then the zero twists as soon as Enter comes (or
    stdin ends): (record, Halt, robots, s taken)."""
    from swarm.api.estop import arm  # lazy: as in `estop`
    from swarm.robots.halt import HaltError  # lazy: as in `estop`

    try:
        record, halt = arm(run, robots)
    except HaltError as e:
        from swarm.cli.errors import fail  # lazy: an error's path

        raise fail(f"swarm estop: {e}") from None
    where = f"run {record.run}'s " if record is not None else ""
    _out(f"estop ready: {where}{halt.robots} robots via {halt.plan.connect}; Enter stops them all (Ctrl-C leaves)")
    try:
        sys.stdin.readline()
    except BaseException:  # Ctrl-C: nothing sent, the session closed
        halt.close()
        raise
    t0 = time.monotonic()
    sent = halt.zero()
    return record, halt, sent, (halt.first_sent or time.monotonic()) - t0


def register(app: typer.Typer) -> None:
    """Add `swarm estop` to the main app."""
    app.command("estop")(estop)
