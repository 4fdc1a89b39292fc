"""Read-only live commands (`swarm runs / agents / graph`; `swarm watch` is swarm/watch_cli.py's),
and what every live command shares: the --connect/--run/--json options (defaults:
$SWARM_CONNECT, $SWARM_RUN), attaching to a run, failing with one line, and reading a run
again until it has really ended.

Every command talks to a running swarm over zenoh only (`swarm.live`), so it works the
same from another terminal or another machine (`--connect tcp/HOST:PORT`). A command
that finds no run (or not the one asked for) prints one line to stderr and exits 1.
The JSON shapes printed with `--json` are documented in docs/cli.md; keep them stable.
The data is in `swarm.live_data`, its looks in `swarm.live_views`; the commands that act
on a run (kill, spawn, pause, resume) in `swarm.control_cli`.
"""

from __future__ import annotations

import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Iterator, Optional

import typer

from swarm.live_data import graph_key, graph_of, snapshot
from swarm.live_views import agents_table, graph_dot, graph_renderable, header, runs_table

EXIT_NO_RUN = 1
EXIT_USAGE = 2

ENV_RUN = "SWARM_RUN"  # the live commands' default --run
ENV_CONNECT = "SWARM_CONNECT"  # the live commands' default --connect

ConnectOpt = Annotated[Optional[str], typer.Option(
    "--connect", envvar=ENV_CONNECT, help="endpoint of the run, e.g. tcp/HOST:7447 or unixsock-stream/PATH "
    "(default: $SWARM_CONNECT, else local runs in $SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)", show_default=False)]
LiveRunOpt = Annotated[Optional[str], typer.Option(
    "--run", envvar=ENV_RUN, help="run id (default: $SWARM_RUN, else the only live run found; several runs "
    "up: `export SWARM_RUN=ID` once)", show_default=False)]
RunOpt = Annotated[Optional[str], typer.Option(  # commands that are not live ones: no default from the environment
    "--run", help="run id (default: the only live run found)", show_default=False)]
JsonOpt = Annotated[bool, typer.Option("--json", help="machine-readable JSON (see docs/cli.md)")]
CredentialsOpt = Annotated[Optional[Path], typer.Option(
    "--credentials", metavar="FILE", help="the run's credentials (default: $SWARM_CREDENTIALS, else the "
    "local run's own file); for a run on another machine, a file from `swarm credentials`",
    show_default=False)]
TrustLawOpt = Annotated[Optional[list[str]], typer.Option(
    "--trust-law", metavar="MODULE:FUNCTION",
    help="a follower law of your own the agent may import if the run uses it (repeatable; built-in laws "
         "need nothing)")]


def fail(message: str, code: int = EXIT_NO_RUN) -> typer.Exit:
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def _one_line(e: BaseException | str) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


@contextmanager
def attached(connect: str | None, run: str | None, creds: Path | None = None) -> Iterator:
    """A LiveRun on the run picked by --connect/--run; any failure to reach it (or its world
    ending mid-command) becomes one line on stderr and exit 1."""
    from swarm.contracts.identities import CredentialsError
    from swarm.contracts.wire import WireError
    from swarm.live import LiveRun, NoRun, resolve

    try:
        with LiveRun(resolve(connect, run, creds)) as live:
            yield live
    except typer.Exit:
        raise
    except (NoRun, WireError, CredentialsError) as e:
        raise fail(_one_line(e)) from None
    except Exception as e:  # zenoh errors: a clear line, never a traceback
        raise fail(f"cannot talk to the run: {_one_line(e)}") from None


def read_again(patience, read):
    """`read()`, or None after a failure while the world has not ended (`swarm.live.Patience`:
    read again next time); NoRun once it has."""
    from swarm.live import NoRun

    try:
        value = read()
    except NoRun:
        if patience.ended():
            raise
        return None
    patience.answered()
    return value


def console(err: bool = False):
    from rich.console import Console

    stream = sys.stderr if err else sys.stdout
    return Console(file=stream, width=None if stream.isatty() else 160, highlight=False)


def _dumps(obj) -> str:
    return json.dumps(obj, indent=2, allow_nan=False)


def runs(
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """List the live runs reachable: id, endpoint, scenario, tick, clock, agents live/total.

    Without --connect, every local run in $SWARM_RUNTIME_DIR (or /tmp/swarm-<uid>). Exit 1
    when none is found.

    Example: swarm runs --connect tcp/10.0.0.5:7447 --json
    """
    from swarm.live import LiveRun, NoRun, find_runs, where_looked

    try:
        found = [r for r in find_runs(connect, credentials) if run is None or r.run == run]
    except NoRun as e:
        raise fail(_one_line(e)) from None
    docs = []
    for ref in found:
        doc = {"run": ref.run, "endpoint": ref.endpoint, "scenario": None, "clock": None, "paused": None,
               "tick": None, "ticks": None, "time": None, "agents_live": None, "agents_total": None,
               "host": None, "pid": None}
        try:
            with LiveRun(ref) as live:
                info = live.info()
            agents = info.get("agents", {})
            doc.update({k: info.get(k) for k in ("scenario", "clock", "paused", "tick", "ticks", "time",
                                                 "host", "pid")},
                       agents_live=sum(1 for a in agents.values() if a.get("alive")),
                       agents_total=len(agents))
        except Exception:
            pass  # it ended between the two questions (NoRun): listed with what is known
        docs.append(doc)
    if as_json:
        typer.echo(_dumps(docs))
    where = where_looked(connect, credentials)
    if not docs:
        raise fail(f"run {run!r} not found: looked at {where}" if run else
                   f"no swarm is running: looked at {where} (start one with `swarm up SCENARIO`, "
                   "or pass --connect ENDPOINT)")
    if not as_json:
        console().print(runs_table(docs))


def agents(
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """One row per agent: pid, host, alive, out-neighbour, hops, errors, command age, missed ticks.

    Columns: id, role, pid, host, alive, out-neighbour, hops to a leader, leader phase,
    distance from the target, radial error, turn rate, age of the last command, missed
    (lockstep) ticks. The world's view merged with each live agent's own status (its out-neighbour, hops and
    phase as it chose them); dropped agents as the world last saw them.

    Example: swarm agents --json
    """
    with attached(connect, run, credentials) as live:
        snap = snapshot(live)
    info = snap["info"]
    if as_json:
        typer.echo(_dumps({"run": info.get("run"), "scenario": info.get("scenario"), "clock": info.get("clock"),
                           "paused": info.get("paused"), "tick": info.get("tick"), "ticks": info.get("ticks"),
                           "time": info.get("time"), "agents": snap["agents"]}))
        return
    con = console()
    con.print(header(info), highlight=False)
    con.print(agents_table(snap["agents"]))


def graph(
    connect: ConnectOpt = None,
    run: LiveRunOpt = None,
    credentials: CredentialsOpt = None,
    as_json: JsonOpt = False,
    dot: Annotated[bool, typer.Option("--dot", help="Graphviz DOT (pipe into `dot -Tpng`)")] = False,
    watch: Annotated[bool, typer.Option("--watch", help="redraw whenever the graph changes, "
                                        "until Ctrl-C")] = False,
    sensing: Annotated[bool, typer.Option("--sensing", help="add who senses whom (dotted edges; "
                                          "a `sensing` list in JSON)")] = False,
) -> None:
    """The live communication graph as the agents chose it (i -> out-neighbour).

    Shows the leaders, the edges, connected components, followers with no path to a
    leader and follower-only cycles. Edges come from the agents' own statuses (from the
    world's info for an agent that did not answer). With --watch, --json prints one JSON
    object per line and --dot one graph per change.

    Example: swarm graph --dot | dot -Tpng > graph.png
    """
    if as_json and dot:
        raise fail("--json and --dot: pick one", EXIT_USAGE)

    def show(g: dict, first: bool) -> None:
        if as_json:
            typer.echo(json.dumps(g, allow_nan=False) if watch else _dumps(g))
        elif dot:
            typer.echo(("" if first else "\n") + graph_dot(g))
        else:
            con = console()
            if watch and not first:
                con.print()
            con.print(graph_renderable(g))

    with attached(connect, run, credentials) as live:
        g = graph_of(snapshot(live, sensing), sensing)
        if not watch:
            show(g, True)
            return
        from swarm.live import NoRun, Patience

        patience = Patience(live)

        def again(g: dict) -> dict:  # the graph now, or the last one while the world does not answer
            return read_again(patience, lambda: graph_of(snapshot(live, sensing), sensing)) or g

        tty = sys.stdout.isatty() and not (as_json or dot)
        key = None
        try:
            if tty:
                from rich.live import Live

                with Live(graph_renderable(g), console=console(), auto_refresh=False) as view:
                    key = graph_key(g)
                    while True:
                        time.sleep(0.25)
                        g = again(g)
                        if graph_key(g) != key:
                            key = graph_key(g)
                            view.update(graph_renderable(g), refresh=True)
            first = True
            while True:
                if graph_key(g) != key:
                    key = graph_key(g)
                    show(g, first)
                    first = False
                time.sleep(0.25)
                g = again(g)
        except KeyboardInterrupt:
            raise typer.Exit(0) from None
        except NoRun:
            typer.secho(f"the world of run {live.ref.run} ended", err=True)
            raise typer.Exit(0) from None


def register(app: typer.Typer) -> None:
    """Add the read-only live commands to the main app."""
    app.command("runs")(runs)
    app.command("agents")(agents)
    app.command("graph")(graph)
    from swarm import watch_cli  # (it builds on this module)

    app.command("watch")(watch_cli.watch)
