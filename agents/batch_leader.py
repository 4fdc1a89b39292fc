"""Leaders (AgentBrain._leader) for many members at once.

Each leader plans its circle-circle path with swarm.agents.cc_plan.plan_cc at its first frame,
exactly as AgentBrain does (the same call, the same arguments: one plan per leader),
then every tick commands the path's turn rate averaged over the tick until the path
ends (swarm.agents.leader.arc_rate), and the orbit hold after (leader.orbit_hold, as
on_orbit_command does): the very functions the per-agent brain runs, here on arrays of
leaders (ops = batch_maths.ARRAY, the `math` functions per element where numpy could
round differently), so the turn rates equal the per-agent brain's to the bit (with
SCALAR_MAX leaders or fewer on their orbits, on_orbit_command itself is called: quicker).
Pure: no I/O.
"""

from __future__ import annotations

import functools
import math
from typing import Any, cast

import numpy as np

from swarm.agents import batch_maths as bm
from swarm.agents.cc_plan import CCPath, plan_cc
from swarm.agents.leader import arc_rate, leader_phase, on_orbit_command, orbit_hold
from swarm.contracts.brain_config import AgentConf
from swarm.contracts.vocabulary import Phase

SCALAR_MAX = 8  # leaders on their orbits: up to this many, one on_orbit_command call each


@functools.lru_cache(maxsize=4096)
def _plan(x: float, y: float, g: float, v: float, radius: float, sign: int, limit: float | None) -> CCPath:
    """plan_cc, once per distinct start (a frozen CCPath, the same for the same arguments): a
    plan costs about 0.2 s, and a batch of seeds of one scenario (swarm.env's vector env, a
    study's repeats) starts many leaders from the same pose."""
    return plan_cc(x, y, g, v, radius, sign, limit)


def _orbit(a: AgentConf) -> float:
    """A leader's orbit radius (a leader has one: checked with its scenario or its BrainConf)."""
    return cast(float, a.orbit_radius)


# the "plan" of a leader steered from outside (BatchLeaders.given): on its orbit from the start
GIVEN = CCPath(math.inf, math.inf, 0.0, 0.0, 0.0, 0.0, (math.nan, math.nan, math.nan), 0.0)


class BatchLeaders:
    """The leaders among (B, N) agents: `where` = (members, columns) of each, and per
    leader its spec's speed, orbit radius, direction sign and turn-rate limit."""

    def __init__(self, specs: list[list[AgentConf]], dt: float):
        """specs: per member, its agents' AgentConfs (their BrainConfs') in column order."""
        where = [(b, i) for b, row in enumerate(specs) for i, a in enumerate(row) if a.role == "leader"]
        self.b = np.array([b for b, _ in where], dtype=np.int64)
        self.i = np.array([i for _, i in where], dtype=np.int64)
        lead = [specs[b][i] for b, i in where]
        self.specs = lead
        self.v = np.array([a.speed for a in lead], dtype=float)
        self.radius = np.array([a.orbit_radius for a in lead], dtype=float)
        self.sign = np.array([a.direction_sign for a in lead], dtype=float)
        self.limit = np.array([a.max_turn_rate or math.inf for a in lead], dtype=float)
        self.dt = dt
        self.planned = False
        # leaders whose turn rate is given from outside (swarm.env's vector env, a policy steering
        # them): not planned (a plan costs ~0.2 s and would be thrown away), decided as on orbit
        self.given = np.zeros(len(lead), dtype=bool)
        self.path_tick = 0
        self.a = 0.0  # path time of the last tick decided (s)
        self.t1 = self.t2 = self.u1 = self.u2 = np.zeros(len(lead))

    def plan(self, tick: int, px: np.ndarray, py: np.ndarray, heading: np.ndarray) -> None:
        """plan_cc for every leader from its first frame (own position relative to the target)."""
        paths = [
            GIVEN
            if given
            else _plan(float(x), float(y), float(g), a.speed, _orbit(a), a.direction_sign, a.max_turn_rate)
            for x, y, g, a, given in zip(px.tolist(), py.tolist(), heading.tolist(), self.specs, self.given.tolist())
        ]
        self.t1 = np.array([p.t1 for p in paths], dtype=float)
        self.t2 = np.array([p.t2 for p in paths], dtype=float)
        self.u1 = np.array([p.u1 for p in paths], dtype=float)
        self.u2 = np.array([p.u2 for p in paths], dtype=float)
        self.planned, self.path_tick = True, tick

    def decide(self, tick: int, tx: np.ndarray, ty: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """Turn rates (L,) of the leaders at `tick`; tx, ty: target minus own position
        (the frame's `target`), heading: own headings, all (L,)."""
        px, py = -tx, -ty
        if not self.planned:
            self.plan(tick, px, py, heading)
        dt = self.dt
        a = self.a = (tick - self.path_tick) * dt
        orbit = a >= self.t1 + self.t2  # leader_phase's test
        u = np.empty(len(self.v))
        arc = ~orbit
        if arc.any():
            u_orbit = self.sign[arc] * self.v[arc] / self.radius[arc]
            u[arc] = arc_rate(a, dt, self.t1[arc], self.t2[arc], self.u1[arc], self.u2[arc], u_orbit, ops=bm.ARRAY)
        k = np.flatnonzero(orbit)
        if 0 < len(k) <= SCALAR_MAX:  # a few leaders: the brain's own function is quicker
            for j, x, y, g in zip(k.tolist(), px[k].tolist(), py[k].tolist(), heading[k].tolist()):
                spec = self.specs[j]
                u[j] = on_orbit_command(x, y, g, spec.speed, _orbit(spec), spec.direction_sign, spec.max_turn_rate)
        elif len(k):
            u[k] = on_orbit(px[k], py[k], heading[k], self.v[k], self.radius[k], self.sign[k], self.limit[k])
        return bm.saturate(u, self.limit)

    def phases(self) -> list[Phase]:
        """The phase (leader.leader_phase) of every leader at the last tick decided."""
        return [leader_phase(self.a, t1, t2) for t1, t2 in zip(self.t1.tolist(), self.t2.tolist())]


def on_orbit(x: Any, y: Any, heading: Any, v: Any, radius: Any, s: Any, limit: Any) -> np.ndarray:
    """swarm.agents.leader.on_orbit_command over arrays of leaders (inputs already checked)."""
    return bm.saturate(orbit_hold(x, y, heading, v, radius, s, ops=bm.ARRAY), limit)
