"""The everyday live commands: `swarm logs` (a run's process output), `swarm stop` (end a run
from any terminal) and `swarm echo` (tap one of its streams). Like the other live commands
(swarm/cli/live.py, whose options they share) each parses its options, calls the Python API
(`swarm.connect(...)`: swarm/api/live.py; the work itself is swarm/live/logs.py, stop.py and
tap.py) and prints what it returns; the API's errors are one line and an exit code
(swarm/cli/errors.py). docs/reference/cli.md has their sections.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.api.live import connect as connect_run
from swarm.cli.options import ConnectOpt, CredentialsOpt, JsonOpt, LiveRunOpt
from swarm.contracts.errors import NoRunError
from swarm.contracts.freetext import printable
from swarm.contracts.vocabulary import ExitCode


def _out(line: str) -> None:
    """One line on stdout, at once (a pipe or a file sees each line as it comes)."""
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def logs(
    source: Annotated[
        Optional[str],
        typer.Argument(
            metavar="[ID|world]", help="an agent's id, or `world` (none: list the logs)", show_default=False
        ),
    ] = None,
    follow: Annotated[
        bool, typer.Option("--follow", "-f", help="print lines as they are written, until the run ends (or Ctrl-C)")
    ] = False,
    lines: Annotated[
        Optional[int],
        typer.Option("--tail", "-n", help="only the last N lines first (default: all)", min=0, show_default=False),
    ] = None,
    out: Annotated[
        Optional[Path],
        typer.Option("--out", "-o", help="a run's output directory: read its logs/ (a finished run too)"),
    ] = None,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
) -> None:
    """Print the output of a run's process: an agent's (ID) or the world's.

    `swarm up` writes each process's output to <out>/logs/ (world.log, agent-ID.log); a live
    run says where, and its logs are read there, on the run's machine. Without ID|world, the
    logs there are listed. With --follow, new lines are printed as they are written and the
    command ends (exit 0) when the run ends, or on Ctrl-C. With --out DIR, the logs of the
    run in DIR, live or finished (--follow then ends on Ctrl-C only).

    Example: swarm logs 3 --follow
    """
    # lazy: swarm.live.logs is for this command only; every other command starts without it
    from swarm.live import logs as L

    src = L.parse_source(source)  # a bad name: exit 2 before looking for a run
    if out is not None:
        run_logs = L.logs_of_out(out)
        _show_logs(run_logs, src, follow, lines, lambda: False)
        return
    with connect_run(run, connect, credentials) as live:
        run_logs = live.logs()
        live.gone()  # from now on, the world's end notice is heard
        _show_logs(run_logs, src, follow, lines, live.gone)


def _show_logs(run_logs, src: str | None, follow: bool, lines: int | None, ended) -> None:
    from swarm.live import logs as L  # lazy: as in `logs`

    if src is None:
        files = run_logs.files()
        if not files:
            _out(f"no logs in {run_logs.dir}")
        for name, path in files.items():
            _out(f"{name:>6}  {path}")
        return
    path = run_logs.path(src)
    text, offset = L.tail(path, lines)
    for line in text:
        _out(printable(line, None, keep="\t"))  # a process's own output: no escape sequence reaches the terminal
    if not follow:
        return
    try:
        for line in L.follow(path, offset, ended):
            _out(printable(line, None, keep="\t"))
    except KeyboardInterrupt:
        raise typer.Exit(ExitCode.OK) from None


def stop(
    no_wait: Annotated[
        bool, typer.Option("--no-wait", help="return once the world has taken the stop, without waiting for the end")
    ] = False,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
) -> None:
    """End a live run as Ctrl-C in its `swarm up` terminal does, from any terminal.

    The world records a `stop` event (who asked) and stops as on SIGINT: its results are
    written (summary.json: completed false, stopped_by_signal 2) and its `swarm up` exits
    130, as on Ctrl-C. Waits until the run has ended (exit 1 if it has not within 60 s) and
    prints the tick it stopped at. Needs the run's operator credentials (its own file on its
    machine, or one from `swarm credentials`).

    Example: swarm stop --run case2-1a2b3c
    """
    with connect_run(run, connect, credentials) as live:
        typer.echo(live.stop(wait=not no_wait).line())


def echo(
    key: Annotated[
        str,
        typer.Argument(
            metavar="KEY",
            help="truth | events | world/control | agent/ID/sense | agent/ID/cmd | agent/ID/status | "
            "agent/ID/ctl (ID: an agent id, or * for every agent)",
            show_default=False,
        ),
    ],
    count: Annotated[
        Optional[int],
        typer.Option("--count", "-c", help="stop after N messages (default: until the run ends, or Ctrl-C)", min=1),
    ] = None,
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Print the messages of one of a live run's streams, decoded, one line each.

    KEY is a key of the run without its swarm/<run>/ prefix: the world's ground truth
    (`truth`: a sample, at most one message per 20 ms of wall time, and the final state),
    its events (`events`), its notices (`world/control`), an agent's sensor frames
    (`agent/3/sense`), its commands (`agent/3/cmd`, without the claim key), its status
    (`agent/3/status`) or the signals sent to it (`agent/3/ctl`). With --json, one JSON
    object per line ({"key": ..., then the fields}; docs/reference/cli.md#echo). A
    malformed message is said in its own line (`malformed message on KEY: ...`, on stderr;
    {"key", "error"} with --json). Messages that were lost (the world numbers truth and
    events; this command holds at most 64 MB it has not printed yet) are counted: a line
    `dropped N messages` on stderr ("dropped": N in the next JSON object) and the total at
    the end. An agent the run does not have: one line, exit 1 (one it may still add with
    `swarm spawn --id`: a line on stderr, and the tap waits). Ends (exit 0) when the run
    ends, after --count messages, or on Ctrl-C.

    Example: swarm echo agent/3/cmd --json
    """
    # lazy: swarm.live.tap is for this command only
    from swarm.live.tap import dropped_line, parse_topic

    parse_topic(key)  # an unknown key: exit 2 before looking for a run
    dropped = 0
    with connect_run(run, connect, credentials) as live:
        try:
            for m in live.echo(key, count):
                dropped += m.dropped
                if m.note is not None:  # the tap's own word, never on stdout
                    typer.echo(m.line(), err=True)
                elif as_json:
                    _out(m.json())
                else:
                    if m.dropped:
                        typer.echo(dropped_line(m.dropped), err=True)
                    if m.data is None and m.error is not None:
                        typer.echo(m.line(), err=True)
                    elif m.data is not None:
                        _out(m.line())
        except KeyboardInterrupt:
            raise typer.Exit(ExitCode.OK) from None
        except NoRunError as e:  # the session went with the run: what came was all there was
            typer.echo(f"the world of run {live.run} ended ({e})", err=True)
        finally:
            if dropped:
                typer.echo(f"{dropped_line(dropped)} in all", err=True)


def register(app: typer.Typer) -> None:
    """Add `swarm logs`, `swarm stop` and `swarm echo` to the main app."""
    app.command("logs")(logs)
    app.command("stop")(stop)
    app.command("echo")(echo)
