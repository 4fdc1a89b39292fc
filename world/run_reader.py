"""Reading a run back: `load_run` checks and loads what world/recording.py wrote
(trajectory.npz, required; summary.json, optional) into a `RunData`, and the pure
figures computed from it that the plots show: the final communication graph, switch
counts, the drop/rejoin/fault events and the expected orbit radii. No drawing here.

Any problem with the input files comes out as a `RunReadError` whose message names the
file (swarm.plots re-exports it as `PlotError`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.orbits import root_of
from swarm.contracts.vocabulary import Coded, EventKind, ExitCode
from swarm.world.metrics import switch_ticks
from swarm.world.recording import SUMMARY_FILE, TRAJECTORY_FILE

__all__ = [
    "RunReadError",
    "RunData",
    "RunEvent",
    "load_run",
    "final_graph",
    "switch_count",
    "switch_counts",
    "run_events",
    "expected_radii",
    "first_alive",
    "last_alive",
    "EVENT_KINDS",
]

# Array keys of trajectory.npz that a reader needs (heading/speed/dt are optional).
REQUIRED_KEYS = ("ids", "role", "target", "t", "x", "y", "u", "out", "alive")

#: Kinds of summary.json events that `run_events` reports.
EVENT_KINDS = (EventKind.DROP, EventKind.REJOIN, EventKind.FAULT)


class RunReadError(Coded):
    """A run directory cannot be read; the message names the offending file."""

    exit_code = ExitCode.FAILED


@dataclass
class RunData:
    """The arrays of one run plus its (possibly empty) summary."""

    ids: np.ndarray  # (N,) int
    role: np.ndarray  # (N,) str
    target: np.ndarray  # (2,)
    t: np.ndarray  # (T,)
    x: np.ndarray  # (T, N)
    y: np.ndarray  # (T, N)
    u: np.ndarray  # (T, N)
    out: np.ndarray  # (T, N) int
    alive: np.ndarray  # (T, N) bool
    orbit_radius: np.ndarray | None = None  # (N,) or None
    summary: dict[str, Any] = field(default_factory=dict)
    follow: np.ndarray | None = None  # (T, N) int8 follow state codes (wire.FOLLOW_STATES); None: an older run

    @property
    def n_agents(self) -> int:
        return int(self.ids.shape[0])

    @property
    def n_rows(self) -> int:
        return int(self.t.shape[0])

    def is_leader(self, j: int) -> bool:
        return str(self.role[j]) == "leader"

    def leaders(self) -> list[int]:
        """Columns of the leaders, in scenario order."""
        return [j for j in range(self.n_agents) if self.is_leader(j)]

    def followers(self) -> list[int]:
        """Columns of the followers, in scenario order."""
        return [j for j in range(self.n_agents) if not self.is_leader(j)]

    def column_of(self) -> dict[int, int]:
        """Agent id -> column."""
        return {int(a): j for j, a in enumerate(self.ids)}


def load_run(run_dir: Path) -> RunData:
    """Read and check ``trajectory.npz`` (required) and ``summary.json`` (optional)."""
    run_dir = Path(run_dir)
    traj = run_dir / TRAJECTORY_FILE
    if not traj.is_file():
        raise RunReadError(f"{traj}: no {TRAJECTORY_FILE} in run directory {run_dir}")
    try:
        with np.load(traj, allow_pickle=False) as z:
            missing = [k for k in REQUIRED_KEYS if k not in z.files]
            if missing:
                raise RunReadError(f"{traj}: malformed {TRAJECTORY_FILE}: missing array key(s) {', '.join(missing)}")
            arrays = {k: np.asarray(z[k]) for k in REQUIRED_KEYS}
            orbit = np.asarray(z["orbit_radius"], dtype=float) if "orbit_radius" in z.files else None
            follow = np.asarray(z["follow"]) if "follow" in z.files else None
    except RunReadError:
        raise
    except Exception as exc:  # zipfile/pickle/value errors from a corrupt file
        raise RunReadError(f"{traj}: cannot read {TRAJECTORY_FILE}: {exc}") from exc

    def bad(msg: str) -> RunReadError:
        return RunReadError(f"{traj}: malformed {TRAJECTORY_FILE}: {msg}")

    ids = arrays["ids"].reshape(-1)
    n = ids.shape[0]
    t = arrays["t"].reshape(-1).astype(float)
    nt = t.shape[0]
    if n == 0 or nt == 0:
        raise bad(f"empty run (N={n} agents, T={nt} rows)")
    if arrays["role"].reshape(-1).shape[0] != n:
        raise bad(f"'role' has shape {arrays['role'].shape}, expected ({n},)")
    if arrays["target"].reshape(-1).shape[0] != 2:
        raise bad(f"'target' has shape {arrays['target'].shape}, expected (2,)")
    for k in ("x", "y", "u", "out", "alive"):
        if arrays[k].shape != (nt, n):
            raise bad(f"'{k}' has shape {arrays[k].shape}, expected (T, N) = ({nt}, {n})")
    if orbit is not None and orbit.reshape(-1).shape[0] != n:
        orbit = None
    if follow is not None and follow.shape != (nt, n):
        raise bad(f"'follow' has shape {follow.shape}, expected (T, N) = ({nt}, {n})")

    summary: dict[str, Any] = {}
    spath = run_dir / SUMMARY_FILE
    if spath.is_file():
        try:
            loaded = json.loads(spath.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise RunReadError(f"{spath}: cannot read {SUMMARY_FILE}: {exc}") from exc
        if not isinstance(loaded, dict):
            raise RunReadError(f"{spath}: malformed {SUMMARY_FILE}: top level is not an object")
        summary = loaded

    return RunData(
        ids=ids.astype(np.int64),
        role=arrays["role"].reshape(-1).astype(str),
        target=arrays["target"].reshape(-1).astype(float),
        t=t,
        x=arrays["x"].astype(float),
        y=arrays["y"].astype(float),
        u=arrays["u"].astype(float),
        out=arrays["out"].astype(np.int64),
        alive=arrays["alive"].astype(bool),
        orbit_radius=None if orbit is None else orbit.reshape(-1),
        summary=summary,
        follow=None if follow is None else follow.astype(np.int8),
    )


# ------------------------------------------------------------------ figures of a run


def first_alive(alive_col: np.ndarray) -> int | None:
    """First row at which the agent of this `alive` column is alive, None if never."""
    idx = np.flatnonzero(alive_col)
    return int(idx[0]) if idx.size else None


def last_alive(alive_col: np.ndarray) -> int | None:
    """Last row at which the agent of this `alive` column is alive, None if never."""
    idx = np.flatnonzero(alive_col)
    return int(idx[-1]) if idx.size else None


def switch_counts(run: RunData) -> list[int]:
    """Per column: out-neighbour changes while alive (see `swarm.world.metrics.switch_ticks`)."""
    return [len(k) for k in switch_ticks(run.out, run.alive)]


def switch_count(run: RunData) -> int:
    """Out-neighbour changes of all agents while alive (summary.json's `switches`)."""
    return int(sum(switch_counts(run)))


def final_graph(run: RunData) -> tuple[dict[int, int], set[int], set[int]]:
    """The final communication graph.

    Returns (edges, dead, orphans): ``edges[i] = j`` for agent id i whose out-neighbour
    at its last alive row was id j; ``dead`` = ids not alive in the last row;
    ``orphans`` = live ids with no path along out-edges through live agents to a live
    leader.
    """
    index = run.column_of()
    edges: dict[int, int] = {}
    for j, a in enumerate(run.ids):
        last = last_alive(run.alive[:, j])
        if last is None:
            continue
        o = int(run.out[last, j])
        if o >= 0 and o in index and o != int(a):
            edges[int(a)] = o
    alive_end = {int(a) for j, a in enumerate(run.ids) if run.alive[-1, j]}
    dead = {int(a) for a in run.ids} - alive_end
    leaders = {int(run.ids[j]) for j in run.leaders()}
    live_out = {a: edges.get(a) for a in alive_end}  # walks end at dead agents
    orphans = {a for a in alive_end if root_of(a, live_out, leaders & alive_end)[0] is None}
    return edges, dead, orphans


def expected_radii(run: RunData) -> list[float]:
    """Distinct expected orbit radii: summary's expected_radius (swarm.world.metrics computes it
    with `swarm.contracts.orbits.expected_radius`), else the leaders' orbit_radius."""
    radii: list[float] = []
    agents = run.summary.get("agents")
    if isinstance(agents, dict):
        for info in agents.values():
            if isinstance(info, dict):
                r = info.get("expected_radius")
                if isinstance(r, (int, float)) and math.isfinite(r) and r > 0:
                    radii.append(float(r))
    if not radii and run.orbit_radius is not None:
        radii = [float(r) for r in run.orbit_radius if math.isfinite(r) and r > 0]
    out: list[float] = []
    for r in sorted(radii):
        if not out or abs(r - out[-1]) > 1e-6 * max(1.0, r):
            out.append(r)
    return out


@dataclass
class RunEvent:
    time: float  # s
    kind: str  # one of EVENT_KINDS
    label: str


def run_events(run: RunData) -> list[RunEvent]:
    """drop/rejoin/fault events from summary.json (plus `faults` not already listed), by time."""
    out: list[RunEvent] = []
    seen_faults: set[tuple[float, Any]] = set()
    events = run.summary.get("events")
    dt = float(run.t[1] - run.t[0]) if run.n_rows > 1 else 0.0

    def when(ev: dict[str, Any]) -> float | None:
        tm = ev.get("time")
        if isinstance(tm, (int, float)) and math.isfinite(tm):
            return float(tm)
        tick = ev.get("tick")
        if isinstance(tick, int) and 0 <= tick < run.n_rows:
            return float(run.t[tick])
        if isinstance(tick, int):
            return float(run.t[0] + tick * dt)
        return None

    if isinstance(events, list):
        for ev in events:
            if not isinstance(ev, dict) or ev.get("kind") not in EVENT_KINDS:
                continue
            tm = when(ev)
            if tm is None:
                continue
            agent = ev.get("agent")
            kind = str(ev["kind"])
            if kind == EventKind.FAULT:
                seen_faults.add((round(tm, 9), agent))
            out.append(RunEvent(tm, kind, f"{kind} {agent}" if agent is not None else kind))
    faults = run.summary.get("faults")
    if isinstance(faults, list):
        for ev in faults:
            if not isinstance(ev, dict):
                continue
            tm = when(ev)
            agent = ev.get("agent")
            if tm is None or (round(tm, 9), agent) in seen_faults:
                continue
            kind = str(ev.get("kind", "fault"))
            out.append(RunEvent(tm, EventKind.FAULT, f"{kind} {agent}" if agent is not None else kind))
    out.sort(key=lambda e: e.time)
    return out
