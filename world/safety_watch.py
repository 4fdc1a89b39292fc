"""One run's safety filter and its record: what the world does with a scenario's [safety] table.

`SafetyWatch` sits between the commands the world latched and the integration (or the
robots), in world/engine.py's `end_tick` and in the batch engine (swarm/offline/batch.py),
one per swarm, so `swarm sim`, `swarm up` (lockstep equal to sim to the bit), robots mode and
the batch engine all filter and count alike. Each tick:

- `command`: the filter (world/safety.py) on every agent in the world: the turn rates (and,
  with `speed = true`, the speeds) to apply instead of the laws'. Every change is counted;
  the first tick of each agent's spell of changes is a "safety" event (what it asked, what it
  got, which barriers bound it, whether no safe command existed), and so is the first tick of
  each spell with no safe command within a spell of changes. `enabled = false`: the
  laws' commands go through and only the figures below are kept.
- `measure`: Robotarium's figures of the recorded poses (ticks 0..T, the final pose too):
  the least distance between two agents, collisions (a pair closer than `radius`, counted
  once per spell: a pair that stays close is one collision; `collision_ticks` counts the
  pair-ticks), boundary exits (an agent's position outside the arena, once per spell;
  `outside_ticks` the agent-ticks) and saturations (agent-ticks whose applied turn rate is
  at the agent's max_turn_rate).

`figures()` is summary.json's "safety" section, `agent_figures()` each agent's.
docs/reference/outputs.md lists the fields.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from swarm.contracts.scenario_tables import SafetySpec
from swarm.contracts.vocabulary import EventKind
from swarm.world.safety import Arena, Filtered, barriers_of, distances, pairs, safe_commands

SATURATED = 1.0 - 1e-12  # |u| >= this x the limit counts as at the limit

EventSink = Callable[..., Any]  # (kind, agent, reason, **more): world/engine.py `Engine.event`


class SafetyWatch:
    def __init__(self, spec: SafetySpec, ids: Sequence[int]):
        self.spec = spec
        self.bar = barriers_of(spec)
        self.arena: Arena | None = self.bar.arena
        self.ids: list[int] = [int(i) for i in ids]
        n = len(self.ids)
        self.interventions = np.zeros(n, dtype=np.int64)  # agent-ticks the filter changed the command
        self.spells = np.zeros(n, dtype=np.int64)  # spells of changes (one "safety" event each)
        self.infeasible = np.zeros(n, dtype=np.int64)  # agent-ticks with no safe command
        self.speed_cuts = np.zeros(n, dtype=np.int64)  # agent-ticks the filter slowed the agent
        self.saturations = np.zeros(n, dtype=np.int64)  # agent-ticks at the turn-rate limit
        self.exits = np.zeros(n, dtype=np.int64)  # boundary exits (spells outside the arena)
        self.outside_ticks = np.zeros(n, dtype=np.int64)
        self.infeasible_spells = np.zeros(n, dtype=np.int64)  # spells with no safe command (an event each)
        self.in_spell = np.zeros(n, dtype=bool)
        self.stuck = np.zeros(n, dtype=bool)  # no safe command at the last tick
        self.outside = np.zeros(n, dtype=bool)
        self.touching: set[tuple[int, int]] = set()  # id pairs closer than radius at the last measure
        self.collisions = 0
        self.collision_ticks = 0
        self.min_distance = math.inf
        self.min_pair: tuple[int, int] | None = None
        self.min_tick: int | None = None
        self.filtered_ticks = 0  # ticks with at least one change
        self.solves = 0  # QPs solved

    def add_agent(self, aid: int) -> None:
        """One more agent (added at run time): its counts start at zero."""
        self.ids.append(int(aid))
        for name in (
            "interventions",
            "spells",
            "infeasible",
            "infeasible_spells",
            "speed_cuts",
            "saturations",
            "exits",
            "outside_ticks",
        ):
            setattr(self, name, np.append(getattr(self, name), 0))
        self.in_spell = np.append(self.in_spell, False)
        self.stuck = np.append(self.stuck, False)
        self.outside = np.append(self.outside, False)

    # -- the filter ------------------------------------------------------------------------------
    def command(
        self,
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        speed: np.ndarray,
        u: np.ndarray,
        limit: np.ndarray,
        present: np.ndarray,
        controlled: np.ndarray,
        event: EventSink | None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """The turn rates to apply (and the speeds, None when they may not change) instead of
        the laws' `u` (NaN for agents not in the world). `controlled`: the agents whose command
        may change (the active ones; coasting ones are obstacles)."""
        if not self.spec.enabled:
            return u, None
        f = safe_commands(self.bar, x, y, heading, speed, u, limit, present, controlled)
        self.solves += f.solves
        changed = f.changed
        if changed.any():
            self.filtered_ticks += 1
            self.interventions += changed
            self.infeasible += f.infeasible
            cut = changed & (f.v < speed)
            self.speed_cuts += cut
            new = changed & ~self.in_spell
            self.spells += new
            stuck = f.infeasible & ~self.stuck  # no safe command, for the first tick in a while
            self.infeasible_spells += stuck
            if event is not None:
                for k in np.flatnonzero(new | stuck).tolist():
                    self._event(event, k, f, float(u[k]), float(speed[k]))
        self.in_spell = changed
        self.stuck = f.infeasible
        return f.u, (f.v if self.bar.speed else None)

    def _event(self, event: EventSink, k: int, f: Filtered, u_law: float, v_law: float) -> None:
        by = [f"agent {self.ids[j]}" if kind == "agent" else f"wall {j}" for kind, j in f.reasons(k)]
        u, v = float(f.u[k]), float(f.v[k])
        if f.infeasible[k]:
            what = "no safe command: stopped" if self.bar.speed else "no safe turn rate: the least violating applied"
        else:
            what = f"turn rate {u_law:+.3g} -> {u:+.3g} rad/s"
            if v != v_law:
                what += f", speed {v_law:.3g} -> {v:.3g} m/s"
        event(
            EventKind.SAFETY,
            self.ids[k],
            what + (f" ({', '.join(by)})" if by else ""),
            u_law=u_law,
            u=u,
            v_law=v_law,
            v=v,
            by=by,
            infeasible=bool(f.infeasible[k]),
        )

    # -- the figures -----------------------------------------------------------------------------
    def measure(
        self, tick: int, x: np.ndarray, y: np.ndarray, present: np.ndarray, active: np.ndarray, u: Any, limit: Any
    ) -> None:
        """The figures of the poses of `tick` (x, y: (N,) m; present: in the world; active:
        controlled by a law, whose applied turn rate `u` is checked against `limit`). A pose
        that is not finite is no position: left out, as the filter leaves it out."""
        present = present & np.isfinite(x) & np.isfinite(y)
        i, j = pairs(present)
        d = distances(x, y, i, j)
        touching: set[tuple[int, int]] = set()
        if d.size:
            m = int(np.argmin(d))
            if d[m] < self.min_distance:
                self.min_distance = float(d[m])
                self.min_pair = (self.ids[i[m]], self.ids[j[m]])
                self.min_tick = tick
            close = np.flatnonzero(d < self.spec.radius)
            if close.size:
                touching = {(self.ids[i[c]], self.ids[j[c]]) for c in close.tolist()}
                self.collision_ticks += len(touching)
                self.collisions += len(touching - self.touching)
        self.touching = touching
        if self.arena is not None:
            out = present & ~self.arena.inside(x, y)
            self.outside_ticks += out
            self.exits += out & ~self.outside
            self.outside = out
        with np.errstate(invalid="ignore"):
            at_limit = active & np.isfinite(limit) & (np.abs(u) >= SATURATED * limit)
        self.saturations += at_limit

    def figures(self) -> dict[str, Any]:
        """summary.json's "safety" section."""
        return {
            "enabled": self.spec.enabled,
            "radius": self.spec.radius,
            "lookahead": self.bar.lookahead,
            "gamma": self.spec.gamma,
            "speed": self.spec.speed,
            "arena": None if self.spec.corners is None else [list(p) for p in self.spec.corners],
            "min_distance": self.min_distance if math.isfinite(self.min_distance) else None,
            "min_distance_pair": list(self.min_pair) if self.min_pair is not None else None,
            "min_distance_tick": self.min_tick,
            "collisions": self.collisions,
            "collision_ticks": self.collision_ticks,
            "boundary_exits": int(self.exits.sum()),
            "outside_ticks": int(self.outside_ticks.sum()),
            "saturations": int(self.saturations.sum()),
            "interventions": int(self.interventions.sum()),
            "spells": int(self.spells.sum()),
            "infeasible": int(self.infeasible.sum()),
            "infeasible_spells": int(self.infeasible_spells.sum()),
            "speed_cuts": int(self.speed_cuts.sum()),
            "filtered_ticks": self.filtered_ticks,
            "solves": self.solves,
        }

    def agent_figures(self) -> dict[str, dict[str, Any]]:
        """Per agent (str(id)): its "safety" figures in summary.json's agents."""
        return {
            str(aid): {
                "safety": {
                    "interventions": int(self.interventions[k]),
                    "spells": int(self.spells[k]),
                    "infeasible": int(self.infeasible[k]),
                    "infeasible_spells": int(self.infeasible_spells[k]),
                    "speed_cuts": int(self.speed_cuts[k]),
                    "saturations": int(self.saturations[k]),
                    "boundary_exits": int(self.exits[k]),
                }
            }
            for k, aid in enumerate(self.ids)
        }
