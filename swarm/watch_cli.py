"""`swarm watch`: a live terminal view of a run, the top-down picture (swarm/watch.py) beside
the agents table (`watch_frame`, swarm/live_views.py), refreshed a few times a second. Its
options are swarm/live_cli.py's, its readings `swarm.connect(...)`'s (swarm/api_live.py); a
world that misses a read is read again until it has really ended (`Live.again`)."""

from __future__ import annotations

import sys
import time
from typing import Annotated

import typer

from swarm.api_live import connect as connect_run
from swarm.errors import NoRunError
from swarm.live_cli import ConnectOpt, CredentialsOpt, LiveRunOpt, console
from swarm.live_views import watch_frame

WORLD_GONE_EXIT = 3.0  # s: `watch` without a terminal exits this long after the world ended


def watch(
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    rate: Annotated[float, typer.Option(help="refreshes per second", min=0.2, max=30.0)] = 4.0,
) -> None:
    """A live terminal view: a top-down picture of the run beside the agents table.

    The picture shows the target (+), the leaders' orbits and followers' expected orbits
    (dashed), the agents as arrows of their headings coloured by role (leader blue,
    follower yellow, unrooted red, dead grey x) with their ids, and out-neighbour edges.

    Ctrl-C exits (0). When the world ends the last picture stays, marked "world ended";
    without a terminal (stdout piped) a frame is printed per refresh and the command exits
    a few seconds after the world ended.

    Example: swarm watch --rate 10
    """
    period = 1.0 / rate
    tty = sys.stdout.isatty()
    con = console()
    with connect_run(run, connect, credentials) as live:
        snap = live.snapshot()
        ended_at: float | None = None

        def refresh() -> None:
            """A new snapshot (the last one while the world does not answer), or note when the
            world ended (the last picture stays)."""
            nonlocal snap, ended_at
            if ended_at is None:
                try:
                    snap = live.again(live.snapshot, snap)
                except NoRunError:
                    ended_at = time.monotonic()

        try:
            if tty:
                from rich.live import Live

                def frame():
                    w, h = con.size
                    return watch_frame(snap, ended_at is not None, w, h - 1)

                with Live(frame(), console=con, auto_refresh=False, redirect_stderr=False) as view:
                    while True:
                        time.sleep(period)
                        refresh()
                        view.update(frame(), refresh=True)
            shown = None
            while True:
                now = (snap["info"].get("tick"), ended_at is not None)
                if now != shown:  # a new frame only when something moved (not while paused)
                    shown = now
                    con.print(watch_frame(snap, ended_at is not None, con.width, 30))
                    con.print()
                if ended_at is not None and time.monotonic() - ended_at > WORLD_GONE_EXIT:
                    return
                time.sleep(period)
                refresh()
        except KeyboardInterrupt:
            raise typer.Exit(0) from None
