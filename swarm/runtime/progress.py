"""`swarm up`'s progress line, from the latest ground truth the launcher heard.

Each live agent's radial error: its distance to the target against the radius expected
from its path to a leader (swarm/contracts/orbits.py), or none without a path; then the
line's text, agent by agent for a small swarm, summed up for a large one: how many agents
are settled (radial error within the settling band, 2%), how many are not and the worst
few of those, how many have no leader, which (or how many) dropped. Agents added at run time (`swarm spawn`) count
once the launcher knows their spec (`AddedSpec`, from the world's info). `ProgressLine`
draws the line from the figures `swarm.launch` reports; while the world's clock is paused
(`swarm pause`: the figures' "paused", from the world's pause and resume events,
`Paused`) it says "paused" where the tick rate goes, and a world that does not tick
otherwise shows 0 ticks/s, not the last rate it had.
"""

from __future__ import annotations

import atexit
import math
import os
import struct
import sys
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import zenoh

from swarm.contracts import wire
from swarm.contracts.orbits import expected_radius, root_of
from swarm.contracts.vocabulary import AgentState, EventKind

if TYPE_CHECKING:  # annotations only: `swarm up` imports this module for every command's app
    from swarm.contracts.scenario import Scenario

ACTIVE = wire.STATES.index(AgentState.ACTIVE)  # the state byte of a live agent in a truth record
# A truth record (wire.TRUTH_FIELDS, numpy's packed little-endian layout) as a struct, so that
# the launcher reads ground truth without numpy (wire.decode_truth's 0.1 s import)
_TRUTH_RECORD = struct.Struct("<" + "".join({"<i4": "i", "<f8": "d", "u1": "B"}[t] for _, t in wire.TRUTH_FIELDS))
_TRUTH_NAMES = tuple(name for name, _ in wire.TRUTH_FIELDS)


def truth_records(buf: bytes) -> tuple[int, float, list[dict[str, Any]]]:
    """wire.decode_truth without numpy: (tick, time, records), each record a dict of
    TRUTH_FIELDS' names and the same numbers (Python ints and floats); WireError as it raises."""
    head = wire.TRUTH_HEAD
    if len(buf) < head.size:
        raise wire.WireError(f"truth: {len(buf)} bytes, shorter than its {head.size}-byte header")
    kind, version, _, _, n, tick, t = head.unpack_from(buf)
    if kind != wire.KIND_TRUTH:
        raise wire.WireError(f"truth: kind byte {kind}, expected {wire.KIND_TRUTH}")
    if version != wire.VERSION:
        raise wire.WireError(f"truth: protocol version {version}, this build speaks {wire.VERSION}")
    if n > wire.MAX_AGENTS or len(buf) != head.size + n * _TRUTH_RECORD.size:
        raise wire.WireError(f"truth: {len(buf)} bytes do not hold {n} agent records")
    recs = [dict(zip(_TRUTH_NAMES, r)) for r in _TRUTH_RECORD.iter_unpack(memoryview(buf)[head.size :])]
    return tick, t, recs


PROGRESS_AGENTS = 12  # more agents than this: the progress line sums them up
WORST_SHOWN = 3  # unsettled agents named on a summed-up line


@dataclass(frozen=True)
class AddedSpec:
    """What the progress line needs of an agent added at run time (the world's info has it)."""

    id: int
    role: str
    speed: float
    orbit_radius: float | None = None


def added_spec(row: dict) -> AddedSpec | None:
    """An `AddedSpec` from one agent's row of the world's info (None if it lacks a field)."""
    try:
        return AddedSpec(
            int(row["id"]),
            str(row["role"]),
            float(row["speed"]),
            None if row.get("orbit_radius") is None else float(row["orbit_radius"]),
        )
    except (KeyError, TypeError, ValueError):
        return None


def added_specs(session, run: str, ids: set[int]) -> dict[int, AddedSpec]:
    """The specs of agents `ids`, added at run time, from the world's info (those it knows;
    none if it does not answer now)."""
    try:
        for r in session.get(wire.world_info_key(run), timeout=1.0, consolidation=zenoh.ConsolidationMode.NONE):
            if r.ok is not None:
                rows = wire.decode_info(r.ok.payload.to_bytes()).get("agents", {})
                found = {i: added_spec(rows[str(i)]) for i in ids if str(i) in rows}
                return {i: a for i, a in found.items() if a is not None}
    except Exception:  # the world ended meanwhile, or its info is malformed: asked again next time
        pass
    return {}


def truth_progress(buf: bytes | None, s: Scenario, added: dict[int, AddedSpec] | None = None) -> dict | None:
    """Figures for the progress line from a ground-truth message (None: none, or unreadable).
    `added`: the specs of agents added at run time; one not (yet) known is left out."""
    if buf is None:
        return None
    try:
        tick, t, recs = truth_records(buf)
    except wire.WireError:
        return None
    spec = {a.id: a for a in s.agents} | dict(added or {})
    recs = [r for r in recs if int(r["id"]) in spec]
    leaders = {i for i, a in spec.items() if a.role == "leader"}
    alive = {int(r["id"]) for r in recs if r["state"] == ACTIVE}
    out = {int(r["id"]): (int(r["out"]) if r["out"] >= 0 else None) for r in recs}
    errs: dict[int, float | None] = {}
    for r in recs:
        aid = int(r["id"])
        if aid not in alive:
            continue
        root, _ = root_of(aid, out, leaders & alive)
        L, me = (None, None) if root is None else (spec[root], spec[aid])
        if L is None or me is None or L.orbit_radius is None:  # no leader (a leader has an orbit radius)
            errs[aid] = None
            continue
        R = expected_radius(me.speed, L.speed, L.orbit_radius)
        errs[aid] = abs(math.hypot(r["x"] - s.target.x, r["y"] - s.target.y) - R) / R
    return {"tick": tick, "time": t, "errors": errs, "dropped": sorted(set(out) - alive)}


def _pct(e: float) -> str:
    """A relative error as a short percentage: 0.4%, 12%, 480%."""
    p = 100 * e
    return f"{p:.1f}%" if p < 10 else f"{p:.0f}%"


def progress_errors(p: dict) -> str:
    """The progress line's radial errors: one per agent for a small swarm; for a large one
    how many are settled, the worst few of the others, how many have no leader to follow
    and how many dropped."""
    errs, dropped = p["errors"], p["dropped"]
    gone = f"dropped {', '.join(map(str, dropped))}" if dropped else ""
    if len(errs) + len(dropped) <= PROGRESS_AGENTS:
        text = " ".join(f"{i}:{'-' if e is None else _pct(e)}" for i, e in sorted(errs.items()))
        return f"radial error {text}" + (f"  {gone}" if gone else "")
    from swarm.world.metrics import SETTLING_BAND  # lazy: numpy (0.1 s), which the launcher needs nowhere else

    rooted = [(e, i) for i, e in errs.items() if e is not None]
    off = sorted(((e, i) for e, i in rooted if not e <= SETTLING_BAND), key=lambda x: (-x[0], x[1]))
    text = f"{len(errs)} live: {len(rooted) - len(off)} settled"
    if off:
        text += f", {len(off)} not (worst {' '.join(f'{i}:{_pct(e)}' for e, i in off[:WORST_SHOWN])})"
    if len(rooted) < len(errs):
        text += f", {len(errs) - len(rooted)} without a leader"
    if dropped:
        text += "; " + (gone if len(dropped) <= WORST_SHOWN else f"{len(dropped)} dropped")
    return text


class ProgressLine:
    """`swarm up`'s progress line, from the figures `swarm.launch` reports (`show`): at most
    one a second when stdout is not a terminal (and the last tick's), plain lines for a log;
    on a terminal, one row that rich keeps at the bottom (a live display: other lines printed
    meanwhile, on stdout or stderr, go above it), cut to the terminal's width; `end` leaves the
    last one there and moves past it."""

    def __init__(self, tty: bool):
        self.tty = tty
        self.last, self.tick, self.wall = 0.0, 0, 0.0
        self.clock = ""  # the rate (or "paused") last shown
        self.live: Any = None  # rich's live display (rich.live.Live), from the first line on a terminal

    def show(self, p: dict) -> None:
        now = time.monotonic()
        still = p["tick"] == self.tick and self.wall > 0
        if p.get("paused") and self.wall > 0:  # the rate after the pause counts from its end
            still, self.tick, self.wall = True, p["tick"], p["wall"]
        if still and now - self.last < 1.0:
            return  # no new tick: said again at most once a second (the rate falls, or "paused")
        if not self.tty and now - self.last < 1.0 and p["tick"] < p["ticks"] - 1:
            return
        rate = (p["tick"] - self.tick) / max(p["wall"] - self.wall, 1e-9)
        clock = "paused" if p.get("paused") else f"{rate:6.0f} ticks/s"
        if still and not self.tty and clock == self.clock:
            return  # a log gets a line when something changed
        self.last, self.tick, self.wall, self.clock = now, p["tick"], p["wall"], clock
        line = f"t={p['time']:7.2f}s tick {p['tick']}/{p['ticks']} {clock}  " + progress_errors(p)
        if self.tty:
            self._draw(line)
        else:
            print(line, flush=True)

    def _draw(self, line: str) -> None:
        # lazy: rich (40 ms) only where the line is drawn; swarm.launch does not need it
        from rich.console import Console
        from rich.live import Live
        from rich.text import Text

        text = Text(line, no_wrap=True, overflow="crop")  # one terminal row
        if self.live is None:
            console = Console(file=sys.stdout, force_terminal=True, highlight=False)
            self.live = Live(
                text, console=console, auto_refresh=False, transient=False, redirect_stderr=_same_terminal()
            )
            self.live.start()
            atexit.register(self.end)  # a command that ends without `end` gives the terminal back
        self.live.update(text, refresh=True)

    def end(self) -> None:
        if self.live is not None:
            live, self.live = self.live, None
            live.stop()


def _same_terminal() -> bool:
    """Whether stderr is the terminal stdout is: then its lines go above the live line too
    (through rich); stderr elsewhere (`2>file`) stays where it is."""
    try:
        out, err = os.fstat(sys.stdout.fileno()), os.fstat(sys.stderr.fileno())
    except (OSError, ValueError, AttributeError):  # a stream without a file (a test's capture)
        return False
    return sys.stderr.isatty() and (out.st_dev, out.st_ino, out.st_rdev) == (err.st_dev, err.st_ino, err.st_rdev)


class Paused:
    """Whether the world's clock is paused, from the events the launcher heard (a list that
    only grows): the last `pause` or `resume`. Each call reads only the new events."""

    def __init__(self):
        self.seen, self.paused = 0, False

    def __call__(self, events: list[dict]) -> bool:
        n = len(events)
        for ev in events[self.seen : n]:
            if ev.get("kind") in (EventKind.PAUSE, EventKind.RESUME):
                self.paused = ev["kind"] == EventKind.PAUSE
        self.seen = n
        return self.paused
