"""Read-only live commands (`swarm runs / agents / graph`; `swarm watch` is swarm/cli/watch.py's).
The options every live command shares (--connect, --run, --json; defaults $SWARM_CONNECT,
$SWARM_RUN) and the console are swarm/cli/options.py's.

Each command parses its options, calls the Python API (`swarm.connect`, `swarm.runs`:
swarm/api/live.py) and renders what it returns; the API's errors (no run, the world ended
mid-command...) become one line on stderr and exit 1 in swarm/cli/errors.py. Everything goes
over zenoh, so it works the same from another terminal or another machine (`--connect
tcp/HOST:PORT`). The JSON shapes printed with `--json` are documented in
docs/reference/cli.md#live; keep them stable. Their looks are in `swarm.live.views`; the
commands that act on a run (kill, spawn, pause, resume) in `swarm.cli.control`.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Annotated

import typer

from swarm.api.live import connect as connect_run
from swarm.api.live import runs as live_runs
from swarm.cli.errors import fail
from swarm.cli.options import ConnectOpt, CredentialsOpt, JsonOpt, LiveRunOpt, console
from swarm.contracts.errors import NoRunError, StoppedAnswering
from swarm.contracts.vocabulary import ExitCode
from swarm.live.client import where_looked
from swarm.live.data import graph_key
from swarm.live.views import agents_table, graph_dot, graph_renderable, header, runs_table


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
    docs = live_runs(run, connect, credentials)
    if as_json:
        typer.echo(_dumps(docs))
    where = where_looked(connect, credentials)
    if not docs:
        raise fail(
            f"run {run!r} not found: looked at {where}"
            if run
            else f"no swarm is running: looked at {where} (start one with `swarm up SCENARIO`, "
            "or pass --connect ENDPOINT)"
        )
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
    follow state (sticky followers: acquire, keep, hold, coast, shadow, search, lost, late; - for
    leaders and the other rules), distance from the target, radial error, turn rate, age of the last command, missed
    (lockstep) ticks. The world's view merged with each live agent's own status (its out-neighbour, hops,
    phase and state as it chose them); dropped agents as the world last saw them.

    Example: swarm agents --json
    """
    with connect_run(run, connect, credentials) as live:
        snap = live.snapshot()
    info = snap["info"]
    if as_json:
        typer.echo(
            _dumps(
                {
                    "run": info.get("run"),
                    "scenario": info.get("scenario"),
                    "clock": info.get("clock"),
                    "paused": info.get("paused"),
                    "tick": info.get("tick"),
                    "ticks": info.get("ticks"),
                    "time": info.get("time"),
                    "agents": snap["agents"],
                }
            )
        )
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
    watch: Annotated[bool, typer.Option("--watch", help="redraw whenever the graph changes, until Ctrl-C")] = False,
    sensing: Annotated[
        bool, typer.Option("--sensing", help="add who senses whom (dotted edges; a `sensing` list in JSON)")
    ] = False,
) -> None:
    """The live communication graph as the agents chose it (i -> out-neighbour).

    Shows the leaders, the edges, connected components, followers with no path to a
    leader and follower-only cycles. Edges come from the agents' own statuses (from the
    world's info for an agent that did not answer). With --watch, --json prints one JSON
    object per line and --dot one graph per change; it exits 0 when the world ends, 1 when
    it stops answering for 5 s without having ended.

    Example: swarm graph --dot | dot -Tpng > graph.png
    """
    if as_json and dot:
        raise fail("--json and --dot: pick one", ExitCode.USAGE)

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

    with connect_run(run, connect, credentials) as live:
        g = live.graph(sensing)
        if not watch:
            show(g, True)
            return

        def again(g: dict) -> dict:  # the graph now, or the last one while the world does not answer
            return live.again(lambda: live.graph(sensing), g)

        tty = sys.stdout.isatty() and not (as_json or dot)
        key = None
        try:
            if tty:
                from rich.live import Live  # lazy: rich (~15 ms), for a terminal only

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
            raise typer.Exit(ExitCode.OK) from None
        except StoppedAnswering as e:
            typer.secho(str(e), err=True)
            raise typer.Exit(ExitCode.FAILED) from None
        except NoRunError:
            typer.secho(f"the world of run {live.run} ended", err=True)
            raise typer.Exit(ExitCode.OK) from None


def register(app: typer.Typer) -> None:
    """Add the read-only live commands to the main app."""
    app.command("runs")(runs)
    app.command("agents")(agents)
    app.command("graph")(graph)
