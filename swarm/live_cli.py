"""Live inspection and control commands (`swarm runs/agents/graph/kill/spawn/pause/resume/watch`).

Every command talks to a running swarm over zenoh only (`swarm.live`), so it works the
same from another terminal or another machine (`--connect tcp/HOST:PORT`). A command
that finds no run (or not the one asked for) prints one line to stderr and exits 1.
The JSON shapes printed with `--json` are documented in docs/cli.md; keep them stable.
"""

from __future__ import annotations

import io
import json
import math
import os
import signal as sig
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Iterator, Optional

import typer

from swarm.graph import analyse

EXIT_NO_RUN = 1
EXIT_USAGE = 2
SPAWN_DEADLINE = 10.0  # s for a spawned agent to show up alive in the world's info
DROP_DEADLINE = 3.0  # s for a signalled agent to be dropped (SIGSTOP: the 1 s link lease)
WORLD_GONE_EXIT = 3.0  # s: `watch` without a terminal exits this long after the world ended

ConnectOpt = Annotated[Optional[str], typer.Option(
    "--connect", help="endpoint of the run, e.g. tcp/HOST:7447 or unixsock-stream/PATH "
    "(default: local runs in $SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)", show_default=False)]
RunOpt = Annotated[Optional[str], typer.Option(
    "--run", help="run id (default: the only live run found)", show_default=False)]
JsonOpt = Annotated[bool, typer.Option("--json", help="machine-readable JSON (see docs/cli.md)")]


def fail(message: str, code: int = EXIT_NO_RUN) -> typer.Exit:
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def _one_line(e: BaseException | str) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


@contextmanager
def attached(connect: str | None, run: str | None) -> Iterator:
    """A LiveRun on the run picked by --connect/--run; any failure to reach it (or its world
    ending mid-command) becomes one line on stderr and exit 1."""
    from swarm.live import LiveRun, NoRun, resolve
    from swarm.contracts.wire import WireError

    try:
        with LiveRun(resolve(connect, run)) as live:
            yield live
    except typer.Exit:
        raise
    except (NoRun, WireError) as e:
        raise fail(_one_line(e)) from None
    except Exception as e:  # zenoh errors: a clear line, never a traceback
        raise fail(f"cannot talk to the run: {_one_line(e)}") from None


def _console(err: bool = False):
    from rich.console import Console

    stream = sys.stderr if err else sys.stdout
    return Console(file=stream, width=None if stream.isatty() else 160, highlight=False)


def _dumps(obj) -> str:
    return json.dumps(obj, indent=2, allow_nan=False)


# --- data: the world's info merged with the agents' own statuses ------------------------------
AGENT_FIELDS = ("id", "role", "state", "alive", "answered", "pid", "host", "out", "hops", "root",
                "phase", "fallback", "pinned", "x", "y", "heading", "speed", "u", "distance",
                "expected_radius", "radial_error", "relative_error", "orbit_radius",
                "last_command_age", "missed", "commands", "joins", "drops", "garbage", "rogue_commands")


def merge_agents(info: dict, statuses: dict[int, dict]) -> list[dict]:
    """One row per agent of the world's info, sorted by id (fields: AGENT_FIELDS).

    A live agent that answered its status query gives its own pid, host, out-neighbour,
    hops and phase; an agent that did not answer, or that the world has dropped, is
    described by the world's info alone.
    """
    rows = []
    for key in sorted(info.get("agents", {}), key=int):
        a = info["agents"][key]
        aid = int(a["id"])
        st = statuses.get(aid)
        own = st if (st is not None and a.get("alive")) else None
        row = {f: a.get(f) for f in AGENT_FIELDS}
        row.update(id=aid, answered=st is not None, phase=None, fallback=None, pinned=None,
                   # bad messages: dropped by the world for this agent, plus those the agent dropped
                   garbage=(a.get("garbage") or 0) + ((st or {}).get("garbage") or 0),
                   rogue_commands=a.get("rogue_commands") or 0)
        if own is not None:
            row.update(pid=own.get("pid", row["pid"]), host=own.get("host", row["host"]),
                       out=own.get("out"), hops=own.get("hops"), phase=own.get("phase"),
                       fallback=own.get("fallback"), pinned=own.get("pinned"))
        rows.append(row)
    return rows


def snapshot(live, sensing: bool = False) -> dict:
    """{"info": world info, "agents": merged rows} read now (statuses right after info)."""
    info = live.info(sensing=sensing)
    statuses = live.statuses()
    return {"info": info, "agents": merge_agents(info, statuses)}


def graph_of(snap: dict, sensing: bool = False) -> dict:
    """The communication graph (see docs/cli.md, `swarm graph --json`)."""
    info, rows = snap["info"], snap["agents"]
    out = {r["id"]: r["out"] for r in rows}
    leaders = {r["id"] for r in rows if r["role"] == "leader"}
    alive = {r["id"] for r in rows if r["alive"]}
    g = analyse(out, leaders, alive)
    doc = {"run": info.get("run"), "tick": info.get("tick"), "time": info.get("time"), **g,
           "dead": sorted(set(out) - alive),
           "agents": [{"id": r["id"], "role": r["role"], "alive": r["alive"], "out": r["out"],
                       "source": "agent" if (r["answered"] and r["alive"]) else "world"} for r in rows]}
    if sensing:
        doc["sensing"] = [list(map(int, e)) for e in info.get("sensing", [])]
    return doc


def _dot_id(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'


def graph_dot(g: dict) -> str:
    """Graphviz DOT of a graph_of() document: leaders blue, followers yellow, followers with
    no path to a leader red, dead agents grey dashed; edges in follower-only cycles red and
    bold; sensing edges (when present) grey dotted."""
    unrooted, dead = set(g["unrooted"]), set(g["dead"])
    cyc = {(c[k], c[(k + 1) % len(c)]) for c in g["cycles"] for k in range(len(c))}
    title = _dot_id(f"run {g['run']} tick {g['tick']}")
    lines = [f"digraph {_dot_id(g['run'])} {{",
             f"  graph [label={title}, labelloc=t, rankdir=BT];",
             '  node [shape=circle, style=filled, fontname="Helvetica"];',
             "  edge [color=black];"]
    for a in g["agents"]:
        i = a["id"]
        if i in dead:
            attrs = 'style=dashed, color=grey50, fontcolor=grey50, fillcolor=white'
        elif a["role"] == "leader":
            attrs = 'fillcolor="#6fa8dc", color=blue, shape=doublecircle'
        elif i in unrooted:
            attrs = 'fillcolor="#ea9999", color=red'
        else:
            attrs = 'fillcolor="#ffe599", color="#bf9000"'
        lines.append(f"  {i} [label={_dot_id(i)}, {attrs}];")
    for i, j in g["edges"]:
        extra = " [color=red, penwidth=2, label=cycle]" if (i, j) in cyc else (
            " [color=grey50, style=dashed]" if j in dead else "")
        lines.append(f"  {i} -> {j}{extra};")
    for i, j in g.get("sensing", []):
        lines.append(f"  {i} -> {j} [style=dotted, color=grey60, arrowsize=0.5, constraint=false];")
    lines.append("}")
    return "\n".join(lines)


def graph_renderable(g: dict):
    """The graph for humans: a tree per leader (who follows whom), then what is wrong."""
    from rich.console import Group
    from rich.text import Text
    from rich.tree import Tree

    kids: dict[int, list[int]] = {}
    for i, j in g["edges"]:
        kids.setdefault(j, []).append(i)
    role = {a["id"]: a["role"] for a in g["agents"]}
    parts = [Text(f"run {g['run']}  tick {g['tick']}  t={g['time']:.2f} s  "
                  f"agents {len(g['nodes'])} live / {len(g['agents'])}", style="bold")]

    def grow(node: Tree, i: int, seen: set[int]) -> None:
        for k in sorted(kids.get(i, [])):
            if k in seen or k in role and role[k] == "leader":
                continue
            seen.add(k)
            grow(node.add(Text(f"{k} follower", style="yellow")), k, seen)

    for lead in g["leaders"]:
        t = Tree(Text(f"{lead} leader", style="bold blue"))
        grow(t, lead, {lead})
        parts.append(t)

    def ids(xs) -> str:
        return ", ".join(map(str, xs)) if xs else "none"

    parts.append(Text(f"components: {'; '.join('{' + ids(c) + '}' for c in g['components']) or 'none'}"))
    parts.append(Text(f"unrooted (no path to a leader): {ids(g['unrooted'])}",
                      style="bold red" if g["unrooted"] else ""))
    parts.append(Text("follower-only cycles: " + ("; ".join(" -> ".join(map(str, c + c[:1])) for c in g["cycles"])
                                                  or "none"), style="bold red" if g["cycles"] else ""))
    parts.append(Text(f"dead: {ids(g['dead'])}", style="grey50" if g["dead"] else ""))
    if "sensing" in g:
        parts.append(Text(f"sensing ({len(g['sensing'])} edges): "
                          + (", ".join(f"{i}->{j}" for i, j in g["sensing"]) or "none"), style="grey50"))
    return Group(*parts)


def _fmt(v, fmt: str, none: str = "-") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return format(v, fmt)


def agents_table(rows: list[dict], compact: bool = False):
    """The agents as a rich table (compact: the columns `swarm watch` has room for)."""
    from rich.table import Table

    from rich import box

    t = Table(box=None if compact else box.SIMPLE_HEAD, header_style="bold", pad_edge=False, show_edge=False)
    cols = [("id", "right"), ("role", "left")]
    if not compact:
        cols += [("pid", "right"), ("host", "left")]
    cols += [("alive", "left"), ("out", "right"), ("hops", "right")]
    if not compact:
        cols += [("phase", "left")]
    cols += [("dist m", "right"), ("err m", "right"), ("u rad/s", "right"), ("age s", "right"),
             ("missed", "right")]
    if not compact:
        cols += [("bad", "right")]
    for name, just in cols:
        t.add_column(name, justify=just, no_wrap=True)
    for r in rows:
        style = ("grey50" if not r["alive"] else "blue" if r["role"] == "leader"
                 else "red" if r["root"] is None and r["hops"] is None else "")
        cells = [str(r["id"]), r["role"]]
        if not compact:
            cells += [_fmt(r["pid"], "d"), r["host"] or "-"]
        cells += ["yes" if r["alive"] else r["state"] or "no", _fmt(r["out"], "d"), _fmt(r["hops"], "d")]
        if not compact:
            cells += [r["phase"] or "-"]
        cells += [_fmt(r["distance"], ".1f"), _fmt(r["radial_error"], ".2f"), _fmt(r["u"], "+.3f"),
                  _fmt(r["last_command_age"], ".2f"), _fmt(r["missed"], "d")]
        if not compact:
            cells += [str((r.get("garbage") or 0) + (r.get("rogue_commands") or 0))]
        t.add_row(*cells, style=style)
    return t


# --- the commands ------------------------------------------------------------------------------
def runs(
    connect: ConnectOpt = None,
    run: RunOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """List the live runs reachable: id, endpoint, scenario, tick, clock, agents live/total.

    Without --connect, every local run in $SWARM_RUNTIME_DIR (or /tmp/swarm-<uid>). Exit 1
    when none is found.

    Example: swarm runs --connect tcp/10.0.0.5:7447 --json
    """
    from swarm.live import LiveRun, find_runs
    from swarm.contracts.transport import runtime_dir

    found = [r for r in find_runs(connect) if run is None or r.run == run]
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
    where = connect or f"local runs in {runtime_dir()}"
    if not docs:
        raise fail(f"run {run!r} not found: looked at {where}" if run else
                   f"no swarm is running: looked at {where} (start one with `swarm up SCENARIO`, "
                   "or pass --connect ENDPOINT)")
    if as_json:
        return
    from rich.table import Table

    t = Table(header_style="bold", show_edge=False, pad_edge=False, box=None)
    for c in ("run", "scenario", "tick", "time s", "clock", "agents", "endpoint"):
        t.add_column(c, no_wrap=True, justify="right" if c in ("tick", "time s", "agents") else "left")
    for d in docs:
        clock = "-" if d["clock"] is None else d["clock"] + (" (paused)" if d["paused"] else "")
        agents = "-" if d["agents_total"] is None else f"{d['agents_live']}/{d['agents_total']}"
        tick = "-" if d["tick"] is None else f"{d['tick']}/{d['ticks']}"
        t.add_row(d["run"], d["scenario"] or "-", tick, _fmt(d["time"], ".2f"), clock, agents, d["endpoint"])
    _console().print(t)


def agents(
    connect: ConnectOpt = None,
    run: RunOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """One row per agent: pid, host, alive, out-neighbour, hops, errors, command age, missed ticks.

    Columns: id, role, pid, host, alive, out-neighbour, hops to a leader, leader phase,
    distance from the target, radial error, turn rate, age of the last command, missed
    (lockstep) ticks. The world's view merged with each live agent's own status (its out-neighbour, hops and
    phase as it chose them); dropped agents as the world last saw them.

    Example: swarm agents --json
    """
    with attached(connect, run) as live:
        snap = snapshot(live)
    info = snap["info"]
    if as_json:
        typer.echo(_dumps({"run": info.get("run"), "scenario": info.get("scenario"), "clock": info.get("clock"),
                           "paused": info.get("paused"), "tick": info.get("tick"), "ticks": info.get("ticks"),
                           "time": info.get("time"), "agents": snap["agents"]}))
        return
    con = _console()
    con.print(_header(info), highlight=False)
    con.print(agents_table(snap["agents"]))


def _header(info: dict, ended: bool = False):
    from rich.text import Text

    t = Text()
    t.append(f"run {info.get('run')}", style="bold")
    t.append(f"  scenario {info.get('scenario')}  tick {info.get('tick')}/{info.get('ticks')}  "
             f"t={_fmt(info.get('time'), '.2f')} s  clock {info.get('clock')}")
    if info.get("paused"):
        t.append("  PAUSED", style="bold yellow")
    if ended:
        t.append("  world ended", style="bold red")
    return t


def graph(
    connect: ConnectOpt = None,
    run: RunOpt = None,
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
            con = _console()
            if watch and not first:
                con.print()
            con.print(graph_renderable(g))

    with attached(connect, run) as live:
        g = graph_of(snapshot(live, sensing), sensing)
        if not watch:
            show(g, True)
            return
        from swarm.live import NoRun

        tty = sys.stdout.isatty() and not (as_json or dot)
        key = None
        try:
            if tty:
                from rich.live import Live

                with Live(graph_renderable(g), console=_console(), auto_refresh=False) as view:
                    key = _graph_key(g)
                    while True:
                        time.sleep(0.25)
                        g = graph_of(snapshot(live, sensing), sensing)
                        if _graph_key(g) != key:
                            key = _graph_key(g)
                            view.update(graph_renderable(g), refresh=True)
            first = True
            while True:
                if _graph_key(g) != key:
                    key = _graph_key(g)
                    show(g, first)
                    first = False
                time.sleep(0.25)
                g = graph_of(snapshot(live, sensing), sensing)
        except KeyboardInterrupt:
            raise typer.Exit(0) from None
        except NoRun:
            typer.secho(f"the world of run {live.ref.run} ended", err=True)
            raise typer.Exit(0) from None


def _graph_key(g: dict) -> tuple:
    return (tuple(map(tuple, g["edges"])), tuple(g["nodes"]), tuple(g["dead"]),
            tuple(map(tuple, g.get("sensing", []))))


SIGNALS = {"KILL": sig.SIGKILL, "TERM": sig.SIGTERM, "STOP": sig.SIGSTOP, "CONT": sig.SIGCONT}


def _looks_like_agent(pid: int, agent_id: int) -> bool:
    """Whether local process `pid` is still agent `agent_id`'s (not a reused pid)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except FileNotFoundError:
        return False
    except OSError:
        return True  # no /proc here: trust the pid
    args = [a.decode(errors="replace") for a in argv]
    if "agents.process" in args:
        k = args.index("agents.process")
        return len(args) > k + 1 and args[k + 1] == str(agent_id)
    if "agent" in args and "--id" in args:
        k = args.index("--id")
        return len(args) > k + 1 and args[k + 1] == str(agent_id)
    return False


def kill(
    agent_id: Annotated[int, typer.Argument(metavar="ID", help="the agent's id", show_default=False)],
    signal: Annotated[str, typer.Option("--signal", "-s", help="KILL | TERM | STOP | CONT")] = "KILL",
    connect: ConnectOpt = None,
    run: RunOpt = None,
) -> None:
    """Send a signal (default KILL) to an agent's process.

    On this machine it is os.kill; an agent on another host is asked over zenoh to
    signal itself (so SIGCONT cannot be delivered that way). Waits until the world drops
    the agent (KILL, TERM, STOP) and prints the tick.

    Example: swarm kill 3 --signal STOP
    """
    name = signal.upper().removeprefix("SIG")
    if name not in SIGNALS:
        raise fail(f"--signal {signal!r}: use one of {', '.join(SIGNALS)}", EXIT_USAGE)
    with attached(connect, run) as live:
        info = live.info()
        a = info["agents"].get(str(agent_id))
        if a is None:
            raise fail(f"agent {agent_id} is not in run {info['run']} "
                       f"(ids: {', '.join(sorted(info['agents'], key=int))})")
        st = live.statuses().get(agent_id) if a["alive"] else None
        pid = (st or a).get("pid")
        host = (st or a).get("host")
        if pid is None:
            raise fail(f"agent {agent_id} has no process (it never joined run {info['run']})")
        # Same host name and the pid is that agent's process (host names can repeat across
        # machines; pids get reused): signal it here, otherwise over zenoh.
        local = host == socket.gethostname() and _looks_like_agent(pid, agent_id)
        if not a["alive"]:
            if host != socket.gethostname():
                raise fail(f"agent {agent_id} is not live (state {a['state']}); it can only be signalled "
                           f"on its own host {host} (kill -{name} {pid})")
            if not local:
                raise fail(f"agent {agent_id} is not live (state {a['state']}) and its process "
                           f"(pid {pid}) is gone")
        if local:
            try:
                os.kill(pid, SIGNALS[name])
            except ProcessLookupError:
                raise fail(f"agent {agent_id}: no process {pid} on this machine") from None
            except PermissionError:
                raise fail(f"agent {agent_id}: not allowed to signal pid {pid}") from None
            how = "sent"
        else:
            if name == "CONT":
                raise fail(f"agent {agent_id} runs on {host}: SIGCONT cannot be delivered over zenoh "
                           f"(a stopped process cannot act on a message); run `kill -CONT {pid}` on {host}")
            live.signal_agent(agent_id, name)
            how = "asked over zenoh to take"
        typer.echo(f"{how} SIG{name} to agent {agent_id} (pid {pid} on {host})")
        if name == "CONT" or not a["alive"]:
            return
        t_end = time.monotonic() + DROP_DEADLINE
        while time.monotonic() < t_end:
            now = live.info()
            if not now["agents"][str(agent_id)]["alive"]:
                typer.echo(f"agent {agent_id} dropped at tick {now['tick']}")
                return
            time.sleep(0.02)
        raise fail(f"agent {agent_id} is still live in the world {DROP_DEADLINE:g} s after SIG{name}")


SPEC_OPTIONS = ("x", "y", "heading", "speed", "role", "orbit_radius", "direction", "follow", "max_turn_rate")


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def spawn(
    agent_id: Annotated[int, typer.Option("--id", help="the agent's id: a dropped one rejoins from "
                                          "where it dropped; a new one needs --x --y --heading --speed",
                                          min=0, show_default=False)],
    x: Annotated[Optional[float], typer.Option(help="new agent: x (m)", show_default=False)] = None,
    y: Annotated[Optional[float], typer.Option(help="new agent: y (m)", show_default=False)] = None,
    heading: Annotated[Optional[float], typer.Option(help="new agent: heading (rad)", show_default=False)] = None,
    speed: Annotated[Optional[float], typer.Option(help="new agent: speed (m/s)", show_default=False)] = None,
    role: Annotated[Optional[str], typer.Option(help="new agent: leader | follower [default: follower]",
                                                show_default=False)] = None,
    orbit_radius: Annotated[Optional[float], typer.Option(help="new leader: orbit radius (m)",
                                                          show_default=False)] = None,
    direction: Annotated[Optional[str], typer.Option(help="new leader: ccw | cw [default: ccw]",
                                                     show_default=False)] = None,
    follow: Annotated[Optional[int], typer.Option(help="new follower: fixed out-neighbour id",
                                                  show_default=False)] = None,
    max_turn_rate: Annotated[Optional[float], typer.Option(help="new agent: turn-rate limit (rad/s)",
                                                           show_default=False)] = None,
    connect: ConnectOpt = None,
    run: RunOpt = None,
) -> None:
    """Start an agent process on this machine (detached) and wait until it is live.

    A dropped id rejoins from the pose it had; a new id joins the run with the given spec.
    Its output goes to a log file in the runtime dir.

    Example: swarm spawn --id 7 --x 10 --y -5 --heading 0 --speed 20 --follow 1
    """
    from pydantic import ValidationError

    from swarm.contracts.scenario import AgentSpec, format_validation_error
    from swarm.contracts.transport import runtime_dir

    given = {k: v for k, v in dict(x=x, y=y, heading=heading, speed=speed, role=role, orbit_radius=orbit_radius,
                                   direction=direction, follow=follow, max_turn_rate=max_turn_rate).items()
             if v is not None}
    with attached(connect, run) as live:
        info = live.info()
        ref = live.ref
        spec = None
        if str(agent_id) in info["agents"]:
            if given:
                raise fail(f"agent {agent_id} is already in run {ref.run}: it rejoins from where it dropped; "
                           f"--{'/--'.join(k.replace('_', '-') for k in given)} only apply to a new id",
                           EXIT_USAGE)
        else:
            spec = {"role": "follower", **given}
            try:
                AgentSpec.model_validate({**spec, "id": agent_id})
            except ValidationError as e:
                msg = format_validation_error(f"agent {agent_id}", e).splitlines()
                raise fail(f"{msg[0].replace('invalid scenario', 'invalid spec')}: "
                           f"{'; '.join(m.strip() for m in msg[1:])} (a new agent needs --x --y --heading --speed)",
                           EXIT_USAGE) from None
            if follow is not None and str(follow) not in info["agents"]:
                raise fail(f"--follow {follow}: no agent has that id in run {ref.run}", EXIT_USAGE)
        logs = runtime_dir() / "logs"
        logs.mkdir(mode=0o700, parents=True, exist_ok=True)
        log_path = logs / f"{ref.run}-agent-{agent_id}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"
        args = [sys.executable, "-m", "agents.process", str(agent_id), ref.endpoint, ref.run]
        if spec is not None:
            args.append(json.dumps(spec))
        with open(log_path, "ab") as log:
            proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True, close_fds=True)
        t_end = time.monotonic() + SPAWN_DEADLINE
        while True:
            rc = proc.poll()
            if rc is not None:
                why = _last_line(log_path) or "no output"
                raise fail(f"agent {agent_id} did not start (exit {rc}): {why.removeprefix('swarm agent: ')}")
            a = live.info()["agents"].get(str(agent_id))
            if a is not None and a["alive"] and a["pid"] == proc.pid:
                typer.echo(f"agent {agent_id} is live: pid {proc.pid} (log {log_path})")
                return
            if time.monotonic() > t_end:
                proc.terminate()
                try:
                    proc.wait(timeout=3)
                except subprocess.TimeoutExpired:
                    proc.kill()
                raise fail(f"agent {agent_id} (pid {proc.pid}) did not join within {SPAWN_DEADLINE:g} s; "
                           f"stopped it (log {log_path})")
            time.sleep(0.05)


def pause(connect: ConnectOpt = None, run: RunOpt = None) -> None:
    """Pause the world's clock and print the tick it stopped at.

    Agents stay connected; no tick happens until `swarm resume`.

    Example: swarm pause --run case2-1a2b3c
    """
    with attached(connect, run) as live:
        rep = live.admin("pause")
        typer.echo(f"run {live.ref.run} paused at tick {rep.get('tick')}")


def resume(connect: ConnectOpt = None, run: RunOpt = None) -> None:
    """Resume the world's clock after `swarm pause` and print the tick.

    Example: swarm resume --run case2-1a2b3c
    """
    with attached(connect, run) as live:
        rep = live.admin("resume")
        typer.echo(f"run {live.ref.run} resumed at tick {rep.get('tick')}")


# --- swarm watch ---------------------------------------------------------------------------------
def bodies_of(snap: dict):
    from swarm.watch import Body

    g_unrooted = set(graph_of(snap)["unrooted"])
    return [Body(r["id"], r["role"], r["x"], r["y"], r["heading"], bool(r["alive"]), r["out"],
                 r["id"] not in g_unrooted, r["orbit_radius"], r["expected_radius"]) for r in snap["agents"]]


def watch_frame(snap: dict, ended: bool, width: int, height: int):
    """One screen of `swarm watch`: header, picture beside (or above) the agents table, legend."""
    from rich.console import Console, Group
    from rich.measure import Measurement
    from rich.table import Table
    from rich.text import Text

    from swarm.watch import draw_scene, legend_items

    info, rows = snap["info"], snap["agents"]
    table = agents_table(rows, compact=True)
    probe = Console(width=max(width, 200), file=io.StringIO())
    table_w = Measurement.get(probe, probe.options, table).maximum
    side = width >= table_w + 40
    if side:
        pic_w, pic_h = width - table_w - 3, max(8, height - 3)
    else:
        pic_w, pic_h = max(10, width - 1), max(8, height - len(rows) - 6)
    target = tuple(info.get("target") or (0.0, 0.0))
    canvas = draw_scene(target, bodies_of(snap), pic_w, pic_h)
    legend = Text()
    for glyph, style, caption in legend_items():
        legend.append(glyph, style=style)
        legend.append(f" {caption}  ")
    pic = canvas.to_rich()
    if side:
        grid = Table.grid(padding=(0, 2))
        grid.add_column(no_wrap=True, width=pic_w)
        grid.add_column(no_wrap=True)
        grid.add_row(pic, table)
        body = grid
    else:
        body = Group(pic, table)
    return Group(_header(info, ended), body, legend)


def watch(
    connect: ConnectOpt = None,
    run: RunOpt = None,
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
    from swarm.live import NoRun

    period = 1.0 / rate
    tty = sys.stdout.isatty()
    con = _console()
    with attached(connect, run) as live:
        snap = snapshot(live)
        ended_at: float | None = None

        def refresh() -> None:
            """A new snapshot, or note when the world ended (the last picture stays)."""
            nonlocal snap, ended_at
            if ended_at is None:
                try:
                    snap = snapshot(live)
                except NoRun:
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


def register(app: typer.Typer) -> None:
    """Add the live commands to the main app."""
    app.command("runs")(runs)
    app.command("agents")(agents)
    app.command("graph")(graph)
    app.command("kill")(kill)
    app.command("spawn")(spawn)
    app.command("pause")(pause)
    app.command("resume")(resume)
    app.command("watch")(watch)
