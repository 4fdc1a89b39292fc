"""What the parts of the world process share: its configuration (`WorldConfig`) and the
state of the run that more than one part reads or changes (`RunState`).

The world process (world/process.py) is composed of parts that each get this state in
their constructor: the inbox (world/inbox.py: what each message does), the joins
(world/joins.py: join queries), the clock (world/clock.py: how ticks are paced). Everything
here is read and written on the world's main thread only, except what world/fairness.py
reads, as it says, from the zenoh callbacks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from swarm.contracts.scenario import Scenario
from swarm.contracts.transport import HubAuth
from swarm.contracts.vocabulary import EventKind
from swarm.world.core import WorldCore
from swarm.world.engine import Engine
from swarm.world.plant import Plant
from swarm.world.roster import AgentBook

MAX_REASONS = 20  # reasons kept for `not_reproducible`


@dataclass
class WorldConfig:
    scenario: Scenario
    run: str
    listen: str
    out_dir: Path | None  # where the results go (None: nowhere)
    clock: str = "lockstep"
    time_scale: float = 1.0  # realtime clock: simulated s per wall s
    duration: float | None = None
    join_timeout: float | None = None  # s to wait for every agent before tick 0; None = forever
    deadline: float | None = None  # lockstep deadline override (s)
    progress: bool = True
    auth: HubAuth | None = None  # who may connect and do what (None: an open hub)
    foxglove: tuple[str, int] | None = None  # (host, port) to serve the live view on (world/live_view.py)
    plant: Plant | None = None  # what moves the agents instead of the kinematics (world/plant.py); realtime only


@dataclass
class RunState:
    """The run as the world's parts share it: the engine (ground truth, events, recording),
    each agent's book, the world's counts, whether the clock runs, what the launcher and the
    operator are waiting for, and why the run would not be what `swarm sim` gives."""

    cfg: WorldConfig
    engine: Engine
    ticks: int  # ticks the run is to last
    book: dict[int, AgentBook] = field(default_factory=dict)  # per agent id (world/roster.py)
    garbage: int = 0  # malformed or foreign messages on keys the world listens to
    ignored: int = 0  # well-formed messages of nobody's concern (duplicates, late, strangers)
    over_limit: dict[str, int] = field(default_factory=dict)  # how often each limit refused something
    started: bool = False  # every agent joined and the clock runs
    paused: bool = False  # the operator paused the clock
    ticking: bool = False  # between the first frame of a tick and its step
    pause_waiters: list[Any] = field(default_factory=list)  # pause queries answered after this tick
    faults_done: set[int] = field(default_factory=set)  # scripted faults the launcher carried out
    fault_awaited: int | None = None  # index of the scripted fault the clock waits for (world/clock.py)
    carrying: int | None = None  # the agent a scripted fault is being carried out on
    irreproducible: list[str] = field(default_factory=list)  # why `swarm sim` would not give this run

    def __post_init__(self) -> None:
        if not self.book:
            self.book = {i: AgentBook() for i in self.cfg.scenario.ids}

    @property
    def core(self) -> WorldCore:
        return self.engine.core

    def event(self, kind: EventKind, agent: int | None, reason: str, **more: Any) -> None:
        """One event of the run (the engine records it and tells the world, world/process.py)."""
        self.engine.event(kind, agent, reason, **more)

    def limited(self, what: str, reason: str) -> None:
        """Something over a limit: counted each time, one event the first time."""
        self.over_limit[what] = self.over_limit.get(what, 0) + 1
        if self.over_limit[what] == 1:
            self.event(EventKind.LIMIT, None, reason, limit=what)

    def not_reproducible(self, reason: str) -> None:
        if len(self.irreproducible) < MAX_REASONS:
            self.irreproducible.append(reason)
        elif len(self.irreproducible) == MAX_REASONS:
            self.irreproducible.append("... and more")

    def unscripted(self, aid: int, what: str) -> None:
        """Agent `aid` joined or left the started run, not by a scripted fault: `swarm sim`
        cannot do the same, so the run is no longer reproducible (its reasons say why)."""
        if self.started and aid != self.carrying:
            self.not_reproducible(f"agent {aid} {what} at tick {self.core.tick}, not by a scripted fault")
