"""`swarm watch`: a live terminal view of a run, the top-down picture (swarm/live/watch.py) beside
the agents table (`watch_frame`, swarm/live/views.py), refreshed a few times a second. Its
options are swarm/cli/live.py's, its readings `swarm.connect(...)`'s (swarm/api/live.py); a
world that misses a read is read again until it has really ended (`Live.again`). With
`--foxglove`, no terminal view: the run is served to the Foxglove app (swarm/live/foxglove.py)."""

from __future__ import annotations

import sys
import time
from typing import Annotated

import typer

from swarm.api.live import connect as connect_run
from swarm.cli.errors import fail
from swarm.cli.options import ConnectOpt, CredentialsOpt, LiveRunOpt, console
from swarm.contracts.errors import NoRunError, StoppedAnswering
from swarm.contracts.vocabulary import ExitCode
from swarm.live.views import watch_frame
from swarm.world.live_view import DEFAULT_HOST, DEFAULT_PORT, LiveViewError

WORLD_GONE_EXIT = 3.0  # s: `watch` without a terminal exits this long after the world ended

WatchFoxgloveOpt = Annotated[
    bool,
    typer.Option(
        "--foxglove",
        help=f"instead of the terminal view, serve the run to the Foxglove app over its WebSocket "
        f"protocol, the topics of `swarm up --foxglove` (ws://{DEFAULT_HOST}:{DEFAULT_PORT}; `--foxglove PORT` for "
        "another port; docs/reference/outputs.md#foxglove); Ctrl-C exits 130",
    ),
]
WatchFoxglovePortOpt = Annotated[
    int,
    typer.Option("--foxglove-port", help="--foxglove: the port (`--foxglove PORT` says the same)", min=1, max=65535),
]
WatchFoxgloveHostOpt = Annotated[
    str,
    typer.Option(
        "--foxglove-host",
        help="--foxglove: the address to bind (0.0.0.0: every interface; anyone who can reach the port can watch)",
    ),
]


def watch(
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    rate: Annotated[float, typer.Option(help="refreshes per second (the terminal view)", min=0.2, max=30.0)] = 4.0,
    foxglove: WatchFoxgloveOpt = False,
    foxglove_port: WatchFoxglovePortOpt = DEFAULT_PORT,
    foxglove_host: WatchFoxgloveHostOpt = DEFAULT_HOST,
) -> None:
    """A live terminal view: a top-down picture of the run beside the agents table.

    The picture shows the target (+), the leaders' orbits and followers' expected orbits
    (dashed), the agents as arrows of their headings coloured by role (leader blue,
    follower yellow, unrooted red, dead grey x) with their ids, and out-neighbour edges.

    Ctrl-C exits (0). When the world ends the last picture stays, marked "world ended";
    without a terminal (stdout piped) a frame is printed per refresh and the command exits
    a few seconds after the world ended. A world that stops answering for 5 s without having
    ended (stalled, or cut off from this machine) is marked "world not answering", and the
    command exits 1 (at Ctrl-C on a terminal) with one line saying so.

    With --foxglove [PORT] it serves the run to the Foxglove app instead (the topics of
    `swarm up --foxglove`, built from what the world publishes) until Ctrl-C (exit 130) or the
    end of the run (exit 0), or until the world stops answering without ending (exit 1); a port
    in use is one line and exit 2.

    Example: swarm watch --rate 10;  swarm watch --foxglove 9000
    """
    if foxglove:
        raise typer.Exit(watch_foxglove(connect, run, credentials, foxglove_host, foxglove_port))
    period = 1.0 / rate
    tty = sys.stdout.isatty()
    con = console()
    with connect_run(run, connect, credentials) as live:
        snap = live.snapshot()
        ended_at: float | None = None
        silent: StoppedAnswering | None = None

        def refresh() -> None:
            """A new snapshot (the last one while the world does not answer), or note when the
            world ended or stopped answering (the last picture stays)."""
            nonlocal snap, ended_at, silent
            if ended_at is None:
                try:
                    snap = live.again(live.snapshot, snap)
                except StoppedAnswering as e:
                    silent, ended_at = e, time.monotonic()
                except NoRunError:
                    ended_at = time.monotonic()

        def over() -> bool | str:
            return "world not answering" if silent is not None else ended_at is not None

        try:
            if tty:
                from rich.live import Live  # lazy: rich (~15 ms), for a terminal only

                def frame():
                    w, h = con.size
                    return watch_frame(snap, over(), w, h - 1)

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
                    con.print(watch_frame(snap, over(), con.width, 30))
                    con.print()
                if ended_at is not None and time.monotonic() - ended_at > WORLD_GONE_EXIT:
                    break
                time.sleep(period)
                refresh()
        except KeyboardInterrupt:
            pass
        if silent is not None:
            typer.secho(str(silent), err=True)
            raise typer.Exit(ExitCode.FAILED)
        raise typer.Exit(ExitCode.OK)


def watch_foxglove(connect, run, credentials, host: str, port: int) -> int:
    """`swarm watch --foxglove`: serve the run until it ends (0), stops answering (StoppedAnswering,
    1) or Ctrl-C (130)."""
    from swarm.live.foxglove import serve_run  # lazy: numpy and the scene (~45 ms), for --foxglove only

    def say(line: str) -> None:
        print(line, flush=True)

    try:
        with connect_run(run, connect, credentials) as live:
            serve_run(live, host, port, say)
            return ExitCode.OK
    except LiveViewError as e:
        raise fail(str(e), ExitCode.USAGE) from None
    except KeyboardInterrupt:
        say("stopped (Ctrl-C); the live view is closed")
        return ExitCode.INTERRUPTED


def register(app: typer.Typer) -> None:
    """Add `swarm watch` to the main app."""
    app.command("watch")(watch)
