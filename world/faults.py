"""Scripted faults (scenario [[faults]]), as the world applies them. Pure: no I/O.

Network-level faults act where the world talks to agents, so both engines (`swarm sim`
and the world process) apply them identically, deterministic under the run's seed:

- partition: the agent's frames and commands are lost both ways for `duration` s;
- loss: each frame ("sense") and/or command ("cmd") is lost with `probability`;
- delay: the agent's frames arrive `delay` s of simulated time late (it acts on old news);
- noise: Gaussian noise of `std` rad on the bearings and headings it senses.

A lost frame or command means the agent's last command is held for that tick (in
lockstep the world does not wait for it). Process-level faults (kill, restart, freeze,
thaw) are due at a tick; who carries them out depends on the engine.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Any

import numpy as np

from swarm.contracts.frames import SensorFrame
from swarm.contracts.scenario_tables import PROCESS_FAULTS, FaultSpec

_SENSE, _CMD, _NOISE = 1, 2, 3


class FaultPlan:
    def __init__(self, faults: list[FaultSpec], dt: float, seed: int):
        self.dt = dt
        self.faults = list(faults)
        self.tick_of = [int(round(f.at / dt)) for f in self.faults]
        self.end_of = [
            t + (int(round(f.duration / dt)) if f.duration else 0) for t, f in zip(self.tick_of, self.faults)
        ]
        self.seed = seed
        self.history: dict[int, deque] = {}  # agent -> recent frames (delay)
        self.lost_sense = 0
        self.lost_cmd = 0

    def due(self, tick: int) -> list[tuple[int, FaultSpec]]:
        """Faults that start at `tick` (every kind), with their index in the scenario."""
        return [(i, f) for i, (t, f) in enumerate(zip(self.tick_of, self.faults)) if t == tick]

    def process_faults_due(self, tick: int) -> list[tuple[int, FaultSpec]]:
        return [(i, f) for i, f in self.due(tick) if f.kind in PROCESS_FAULTS]

    def _active(self, tick: int, agent: int, kind: str) -> Iterator[Any]:
        for t0, t1, f in zip(self.tick_of, self.end_of, self.faults):
            if f.kind == kind and t0 <= tick < t1 and (f.agent is None or f.agent == agent):
                yield f

    def _rng(self, tick: int, agent: int, salt: int) -> Any:
        """Random numbers that depend only on (seed, tick, agent, salt): the same draws
        whatever order messages arrive in, so both engines lose the same messages."""
        return np.random.default_rng([self.seed, tick, agent, salt])

    def _lost(self, tick: int, agent: int, which: str) -> bool:
        if any(True for _ in self._active(tick, agent, "partition")):
            return True
        losses = [f for f in self._active(tick, agent, "loss") if f.what in (which, "both")]
        if not losses:
            return False
        draws = self._rng(tick, agent, _SENSE if which == "sense" else _CMD).random(len(losses))
        return any(u < f.probability for u, f in zip(draws, losses))

    def sense(self, frame: SensorFrame) -> SensorFrame | None:
        """The frame as the agent receives it at this tick, or None when it is lost."""
        tick, agent = frame.tick, frame.agent
        hist = self.history.setdefault(
            agent,
            deque(maxlen=1 + max((_ticks(f.delay, self.dt) for f in self.faults if f.kind == "delay"), default=0)),
        )
        hist.append(frame)
        for f in self._active(tick, agent, "delay"):
            lag = int(round(f.delay / self.dt))
            old = hist[max(0, len(hist) - 1 - lag)]
            frame = old._replace(tick=tick, time=frame.time)  # old news, answered for this tick
        if self._lost(tick, agent, "sense"):
            self.lost_sense += 1
            return None
        for f in self._active(tick, agent, "noise"):
            n = len(frame.contacts)
            e = self._rng(tick, agent, _NOISE).normal(0.0, f.std, size=2 * n + 1)
            frame = frame._replace(
                heading=frame.heading + float(e[0]),
                contacts=tuple(
                    c._replace(bearing=c.bearing + float(e[1 + 2 * j]), heading=c.heading + float(e[2 + 2 * j]))
                    for j, c in enumerate(frame.contacts)
                ),
            )
        return frame

    def command_lost(self, tick: int, agent: int) -> bool:
        lost = self._lost(tick, agent, "cmd")
        self.lost_cmd += lost
        return lost

    def affects_network(self) -> bool:
        return any(f.kind not in PROCESS_FAULTS for f in self.faults)

    def active_at(self, tick: int) -> bool:
        """Some network fault is in force at this tick."""
        return any(
            t0 <= tick < t1 for t0, t1, f in zip(self.tick_of, self.end_of, self.faults) if f.kind not in PROCESS_FAULTS
        )


def fault_event(index: int, f: FaultSpec) -> dict:
    """The `fault` event of the summary for fault `index`."""
    return {"index": index, **{k: v for k, v in f.model_dump().items() if v is not None}}


def _ticks(seconds: float | None, dt: float) -> int:
    """A delay fault's delay in ticks (every delay fault has one: FaultSpec)."""
    return int(round((seconds or 0.0) / dt))
