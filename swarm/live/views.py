"""How the live commands look: rich renderables and Graphviz DOT, each a pure function of the
data of `swarm.live.data` (no zenoh, no printing). rich is imported inside the functions
(`--json`, `--dot` never load it)."""

from __future__ import annotations

import io
import math
from typing import TYPE_CHECKING

from swarm.live.data import graph_of
from swarm.live.watch import DEAD_GLYPH, EDGE_GLYPH, STYLES, TARGET_GLYPH, Body, draw_scene

if TYPE_CHECKING:  # annotations only (rich is imported where a view is drawn)
    from rich.console import JustifyMethod, RenderableType


def fmt(v, spec: str, none: str = "-") -> str:
    """format(v, spec), or `none` for a missing or non-finite value."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return format(v, spec)


# --- swarm graph -----------------------------------------------------------------------------------
def _dot_id(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'


def graph_dot(g: dict) -> str:
    """Graphviz DOT of a graph_of() document: leaders blue, followers yellow, followers with
    no path to a leader red, dead agents grey dashed; edges in follower-only cycles red and
    bold; sensing edges (when present) grey dotted."""
    unrooted, dead = set(g["unrooted"]), set(g["dead"])
    cyc = {(c[k], c[(k + 1) % len(c)]) for c in g["cycles"] for k in range(len(c))}
    title = _dot_id(f"run {g['run']} tick {g['tick']}")
    lines = [
        f"digraph {_dot_id(g['run'])} {{",
        f"  graph [label={title}, labelloc=t, rankdir=BT];",
        '  node [shape=circle, style=filled, fontname="Helvetica"];',
        "  edge [color=black];",
    ]
    for a in g["agents"]:
        i = a["id"]
        if i in dead:
            attrs = "style=dashed, color=grey50, fontcolor=grey50, fillcolor=white"
        elif a["role"] == "leader":
            attrs = 'fillcolor="#6fa8dc", color=blue, shape=doublecircle'
        elif i in unrooted:
            attrs = 'fillcolor="#ea9999", color=red'
        else:
            attrs = 'fillcolor="#ffe599", color="#bf9000"'
        lines.append(f"  {i} [label={_dot_id(i)}, {attrs}];")
    for i, j in g["edges"]:
        extra = (
            " [color=red, penwidth=2, label=cycle]"
            if (i, j) in cyc
            else (" [color=grey50, style=dashed]" if j in dead else "")
        )
        lines.append(f"  {i} -> {j}{extra};")
    for i, j in g.get("sensing", []):
        lines.append(f"  {i} -> {j} [style=dotted, color=grey60, arrowsize=0.5, constraint=false];")
    lines.append("}")
    return "\n".join(lines)


def graph_renderable(g: dict):
    """The graph for humans: a tree per leader (who follows whom), then what is wrong."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich.console import Group
    from rich.text import Text
    from rich.tree import Tree

    kids: dict[int, list[int]] = {}
    for i, j in g["edges"]:
        kids.setdefault(j, []).append(i)
    role = {a["id"]: a["role"] for a in g["agents"]}
    parts: list[RenderableType] = [
        Text(
            f"run {g['run']}  tick {g['tick']}  t={g['time']:.2f} s  "
            f"agents {len(g['nodes'])} live / {len(g['agents'])}",
            style="bold",
        )
    ]

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
    parts.append(
        Text(f"unrooted (no path to a leader): {ids(g['unrooted'])}", style="bold red" if g["unrooted"] else "")
    )
    parts.append(
        Text(
            "follower-only cycles: " + ("; ".join(" -> ".join(map(str, c + c[:1])) for c in g["cycles"]) or "none"),
            style="bold red" if g["cycles"] else "",
        )
    )
    parts.append(Text(f"dead: {ids(g['dead'])}", style="grey50" if g["dead"] else ""))
    if "sensing" in g:
        parts.append(
            Text(
                f"sensing ({len(g['sensing'])} edges): " + (", ".join(f"{i}->{j}" for i, j in g["sensing"]) or "none"),
                style="grey50",
            )
        )
    return Group(*parts)


# --- swarm runs / agents -----------------------------------------------------------------------------
def runs_table(docs: list[dict]):
    """The live runs (the documents of `swarm runs --json`) as a rich table."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich.table import Table

    t = Table(header_style="bold", show_edge=False, pad_edge=False, box=None)
    for c in ("run", "scenario", "tick", "time s", "clock", "agents", "endpoint"):
        t.add_column(c, no_wrap=True, justify="right" if c in ("tick", "time s", "agents") else "left")
    for d in docs:
        clock = "-" if d["clock"] is None else d["clock"] + (" (paused)" if d["paused"] else "")
        agents = "-" if d["agents_total"] is None else f"{d['agents_live']}/{d['agents_total']}"
        tick = "-" if d["tick"] is None else f"{d['tick']}/{d['ticks']}"
        t.add_row(d["run"], d["scenario"] or "-", tick, fmt(d["time"], ".2f"), clock, agents, d["endpoint"])
    return t


def header(info: dict, ended: bool | str = False):
    """One line about the run: id, scenario, tick, time, clock; PAUSED, world ended (or what
    `ended` says, when it is a string)."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich.text import Text

    t = Text()
    t.append(f"run {info.get('run')}", style="bold")
    t.append(
        f"  scenario {info.get('scenario')}  tick {info.get('tick')}/{info.get('ticks')}  "
        f"t={fmt(info.get('time'), '.2f')} s  clock {info.get('clock')}"
    )
    if info.get("paused"):
        t.append("  PAUSED", style="bold yellow")
    if ended:
        t.append("  " + (ended if isinstance(ended, str) else "world ended"), style="bold red")
    return t


def follow_cell(follow: str | None) -> str:
    """The state column: the follow state, "-" for none (leaders, the other rules) or unknown."""
    return "-" if not follow or follow == "none" else str(follow)


def agents_table(rows: list[dict], compact: bool = False):
    """The agents as a rich table (compact: the columns `swarm watch` has room for)."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich import box
    from rich.table import Table

    t = Table(box=None if compact else box.SIMPLE_HEAD, header_style="bold", pad_edge=False, show_edge=False)
    cols: list[tuple[str, JustifyMethod]] = [("id", "right"), ("role", "left")]
    if not compact:
        cols += [("pid", "right"), ("host", "left")]
    cols += [("alive", "left"), ("out", "right"), ("hops", "right")]
    if not compact:
        cols += [("phase", "left")]
    cols += [("state", "left")]  # the follow state (sticky followers: keep, hold, coast, ...)
    cols += [("dist m", "right"), ("err m", "right"), ("u rad/s", "right"), ("age s", "right"), ("missed", "right")]
    if not compact:
        cols += [("bad", "right")]
    for name, just in cols:
        t.add_column(name, justify=just, no_wrap=True)
    for r in rows:
        style = (
            "grey50"
            if not r["alive"]
            else "blue"
            if r["role"] == "leader"
            else "red"
            if r["root"] is None and r["hops"] is None
            else ""
        )
        cells = [str(r["id"]), r["role"]]
        if not compact:
            cells += [fmt(r["pid"], "d"), r["host"] or "-"]
        cells += ["yes" if r["alive"] else r["state"] or "no", fmt(r["out"], "d"), fmt(r["hops"], "d")]
        if not compact:
            cells += [r["phase"] or "-"]
        cells += [follow_cell(r.get("follow"))]
        cells += [
            fmt(r["distance"], ".1f"),
            fmt(r["radial_error"], ".2f"),
            fmt(r["u"], "+.3f"),
            fmt(r["last_command_age"], ".2f"),
            fmt(r["missed"], "d"),
        ]
        if not compact:
            cells += [str((r.get("garbage") or 0) + (r.get("rogue_commands") or 0))]
        t.add_row(*cells, style=style)
    return t


# --- swarm watch -------------------------------------------------------------------------------------
def bodies_of(snap: dict) -> list:
    """The agents of a snapshot as the picture's `swarm.live.watch.Body`s."""
    g_unrooted = set(graph_of(snap)["unrooted"])
    return [
        Body(
            r["id"],
            r["role"],
            r["x"],
            r["y"],
            r["heading"],
            bool(r["alive"]),
            r["out"],
            r["id"] not in g_unrooted,
            r["orbit_radius"],
            r["expected_radius"],
        )
        for r in snap["agents"]
    ]


def legend():
    """The line under the picture: each glyph in its style, and what it means."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich.text import Text

    names = {"edge": "out-neighbour", "orbit": "expected orbit"}
    t = Text()
    for glyph, key in [
        ("→", "leader"),
        ("→", "follower"),
        ("→", "unrooted"),
        (DEAD_GLYPH, "dead"),
        (TARGET_GLYPH, "target"),
        (f"{EDGE_GLYPH}{EDGE_GLYPH}→", "edge"),
        ("..", "orbit"),
    ]:
        t.append(glyph, style=STYLES[key])
        t.append(f" {names.get(key, key)}  ")
    return t


def watch_frame(snap: dict, ended: bool | str, width: int, height: int):
    """One screen of `swarm watch`: header (`ended`: see `header`), picture beside (or above)
    the agents table, legend."""
    # lazy: rich (30 ms) only to draw; --json and --dot never load it
    from rich.console import Console, Group
    from rich.measure import Measurement
    from rich.table import Table

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
    pic = draw_scene(target, bodies_of(snap), pic_w, pic_h).to_rich()
    if side:
        grid = Table.grid(padding=(0, 2))
        grid.add_column(no_wrap=True, width=pic_w)
        grid.add_column(no_wrap=True)
        grid.add_row(pic, table)
        body: RenderableType = grid
    else:
        body = Group(pic, table)
    return Group(header(info, ended), body, legend())
