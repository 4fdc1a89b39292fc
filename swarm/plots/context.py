"""What every panel of one run is drawn from, made once per run so that all figures agree:
the run, the rows to draw, each agent's look, the events and the expected radii."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarm.contracts.vocabulary import EventKind
from swarm.offline.csv_export import expected_by_column
from swarm.plots.palette import Looks, agent_looks
from swarm.plots.style import MAX_POINTS, decimation_rows
from swarm.world.run_reader import RunData, RunEvent, run_events

#: Above this many agents the time series are drawn as small multiples, a panel per tree.
GROUP_ABOVE = 12
#: At most this many agents per small-multiple panel (a larger tree is split).
PER_PANEL = 12


@dataclass(frozen=True)
class Span:
    """A fault that lasts (partition, loss, delay, noise: one with a `duration`), from
    `start` to `end` (s); `agent` None when it hits every agent."""

    start: float
    end: float
    kind: str
    agent: int | None

    @property
    def label(self) -> str:
        return self.kind + ("" if self.agent is None else f" {self.agent}")


@dataclass
class Ctx:
    run: RunData
    rows: np.ndarray  # row indices drawn (decimated)
    looks: Looks
    events: list[RunEvent]
    expected: np.ndarray  # (N,) expected radius per column, NaN if unknown
    max_points: int = MAX_POINTS
    spans: list[Span] = field(default_factory=list)  # the faults that last, shaded over their time

    @property
    def all_columns(self) -> list[int]:
        return list(range(self.run.n_agents))


def make_context(run: RunData, max_points: int = MAX_POINTS) -> Ctx:
    max_points = max(16, int(max_points))
    return Ctx(
        run,
        decimation_rows(run, max_points),
        agent_looks(run),
        named_faults(run, run_events(run)),
        expected_by_column(run),
        max_points,
        fault_spans(run),
    )


def fault_spans(run: RunData) -> list[Span]:
    """summary.json's faults that last (a positive `duration`), each cut to the run's end."""
    faults = run.summary.get("faults")
    if not isinstance(faults, list) or run.n_rows == 0:
        return []
    end = float(run.t[-1])
    out = []
    for f in faults:
        if not isinstance(f, dict):
            continue
        at, duration, kind, agent = f.get("at", f.get("time")), f.get("duration"), f.get("kind"), f.get("agent")
        if not (isinstance(at, (int, float)) and isinstance(duration, (int, float)) and isinstance(kind, str)):
            continue
        if duration > 0 and at < end:
            who = int(agent) if isinstance(agent, int) and not isinstance(agent, bool) else None
            out.append(Span(float(at), min(end, float(at) + float(duration)), kind, who))
    return out


def named_faults(run: RunData, events: list[RunEvent]) -> list[RunEvent]:
    """Fault events labelled with the fault's kind from summary.json's `faults` ("kill 4"
    rather than "fault 4")."""
    faults = run.summary.get("faults")
    if not isinstance(faults, list):
        return events
    dt = float(run.t[1] - run.t[0]) if run.n_rows > 1 else 1e-6
    out = []
    for ev in events:
        words = ev.label.split()
        if ev.kind == EventKind.FAULT and words and words[0] == "fault":
            agent = words[1] if len(words) > 1 else None
            for f in faults:
                at = f.get("at", f.get("time")) if isinstance(f, dict) else None
                if (
                    isinstance(at, (int, float))
                    and abs(at - ev.time) <= dt / 2
                    and isinstance(f.get("kind"), str)
                    and (None if f.get("agent") is None else str(f.get("agent"))) == agent
                ):
                    ev = RunEvent(ev.time, ev.kind, f["kind"] + (f" {agent}" if agent else ""))
                    break
        out.append(ev)
    return out


def panel_groups(ctx: Ctx) -> list[tuple[str, list[int]]]:
    """(title, columns) of the small multiples: one per tree, a large tree split into
    parts of at most PER_PANEL agents, each part with its leader."""
    out = []
    for tree in ctx.looks.trees:
        cols = tree.columns
        lead, rest = (cols[:1], cols[1:]) if tree.root is not None else ([], cols)
        size = PER_PANEL - len(lead)
        parts = [rest[k : k + size] for k in range(0, len(rest), size)] or [[]]
        for p, part in enumerate(parts):
            title = tree.title + (f" ({p + 1}/{len(parts)})" if len(parts) > 1 else "")
            out.append((title, lead + part))
    return out


def grouped(ctx: Ctx) -> bool:
    """Time series as small multiples: more than GROUP_ABOVE agents."""
    return ctx.run.n_agents > GROUP_ABOVE
