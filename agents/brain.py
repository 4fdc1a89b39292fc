"""An agent's decision logic: one sensor frame in, one turn rate out.

`AgentBrain` is what runs inside every agent process and, unchanged, inside the
in-process engine `swarm sim`; that is why the two produce the same trajectories.
It sees only its own sensor frames (never ground truth) and keeps a little state:
the leader's circle-circle plan, the follower's current out-neighbour and last command.
Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from agents.laws import make_follower_law
from agents.selection import Sticky, select
from swarm.contracts.frames import SensorFrame


class Decision(NamedTuple):
    """What an agent decided at one tick (a named tuple: made every tick, and cheap)."""

    tick: int
    u: float  # commanded turn rate over [t_k, t_k + dt) (rad/s)
    out: int | None  # chosen out-neighbour (None for leaders and lost followers)
    phase: str  # leaders: "arc1" | "arc2" | "orbit"; followers: "track" | "lost"
    fallback: bool = False  # pinned out-neighbour not sensed, nearest used instead
    hops: int | None = None  # hops to a leader it advertises (leaders 0; None: no path known)


def _overlap(a: float, b: float, lo: float, hi: float) -> float:
    return max(0.0, min(b, hi) - max(a, lo))


def saturate(u: float, limit: float | None) -> float:
    if limit is None:
        return u
    return max(-limit, min(limit, u))


class AgentBrain:
    """Decision logic of one agent; call `decide` once per tick with its frame."""

    def __init__(self, spec, gains, sensing, dt: float, max_hops: int = 10_000):
        """spec/gains/sensing: the scenario's AgentSpec/GainsSpec/SensingSpec or the
        swarm.contracts.brain_config equivalents; dt (s); max_hops caps advertised hop counts (count to
        infinity after a leader dies stops there)."""
        self.max_hops = max_hops
        self.spec = spec
        self.sensing = sensing
        self.gains = gains
        self.dt = dt
        self.is_leader = spec.role == "leader"
        self.law = None if self.is_leader else make_follower_law(gains.law, gains.c1, gains.c2)
        self.cc_path = None  # agents.cc_plan.CCPath once planned
        self.path_tick = 0
        self.out: int | None = None
        self.last_u = 0.0
        self.hops: int | None = None  # hops advertised last tick (rooted rule)
        self.feasible: int | None = None  # rooted rule: accept only agents with fewer hops
        self.unrooted_ticks = 0
        self.nonfinite = 0  # ticks on which the follower law returned NaN or inf (last u held)
        self.last_nonfinite: float | None = None
        # selection = "sticky": wait and drain for max_hops ticks (the deepest a path can be)
        self.sticky = Sticky(max_hops, max_hops) if sensing.selection == "sticky" else None

    # -- leaders -------------------------------------------------------------------
    def _leader(self, frame: SensorFrame) -> Decision:
        s = self.spec
        if frame.target is None:
            raise ValueError(f"leader {s.id}: sensor frame has no target information")
        px, py = -frame.target[0], -frame.target[1]  # own position relative to the target
        sign = s.direction_sign
        # Imported here: only leaders need the planner (pure Python, no numpy: leaders stay as light as followers).
        from agents.cc_plan import plan_cc
        from agents.leader import on_orbit_command

        if self.cc_path is None:
            self.cc_path = plan_cc(px, py, frame.heading, s.speed, s.orbit_radius, sign, s.max_turn_rate)
            self.path_tick = frame.tick
        p = self.cc_path
        a = (frame.tick - self.path_tick) * self.dt
        b = a + self.dt
        t12 = p.t1 + p.t2
        if a >= t12:
            u = on_orbit_command(px, py, frame.heading, s.speed, s.orbit_radius, sign, s.max_turn_rate)
            phase = "orbit"
        else:
            u_orbit = sign * s.speed / s.orbit_radius
            # Average turn rate over the tick: the switch between arcs rarely falls on a tick.
            u = (p.u1 * _overlap(a, b, 0.0, p.t1) + p.u2 * _overlap(a, b, p.t1, t12)
                 + u_orbit * _overlap(a, b, t12, math.inf)) / self.dt
            phase = "arc1" if a < p.t1 else "arc2"
        return Decision(frame.tick, saturate(u, s.max_turn_rate), None, phase, False, 0)

    # -- followers -----------------------------------------------------------------
    def _follower(self, frame: SensorFrame) -> Decision:
        if self.sticky is not None:
            choice = self.sticky.choose(frame.contacts)
        else:
            choice = select(frame.contacts, mode=self.sensing.selection, pinned=self.spec.follow,
                            current=self.out, hysteresis=self.sensing.hysteresis, below=self._below())
        self.out = choice.out
        if choice.contact is None:
            # Nobody (rooted) in sight: loiter on a circle of radius v / C2, turning the way it
            # last turned, until somebody shows up: neither a spin nor bolting off in a line.
            u = saturate(math.copysign(self.gains.c2, self.last_u or 1.0), self.spec.max_turn_rate)
            return Decision(frame.tick, u, None, "lost", choice.fallback)
        c = choice.contact
        u = self.law(frame.heading, c.heading, c.bearing)
        if math.isfinite(u):
            u = saturate(u, self.spec.max_turn_rate)  # (before saturating: min/max would hide a NaN)
        else:
            # A law that returns NaN or inf: counted (the agent reports it in its status and
            # the run's summary), and its last turn rate is held for this tick.
            self.nonfinite += 1
            self.last_nonfinite = u
            u = self.last_u
        hops = c.hops + 1 if choice.rooted and 0 <= c.hops < self.max_hops else None
        return Decision(frame.tick, u, c.id, "track", choice.fallback, hops)

    def _below(self) -> int | None:
        """Rooted rule: the hop count a new out-neighbour must beat (None: anyone rooted).

        While rooted: its own hops. After losing its path: the hops it had, until stale
        advertisements of its former descendants have drained (max_hops ticks)."""
        if self.sensing.selection != "rooted":
            return None
        if self.hops is not None:
            return self.hops
        return self.feasible if self.unrooted_ticks < self.max_hops else None

    def decide(self, frame: SensorFrame) -> Decision:
        d = self._leader(frame) if self.is_leader else self._follower(frame)
        self.last_u = d.u
        if d.hops is not None:
            self.feasible, self.unrooted_ticks = d.hops, 0
        else:
            self.unrooted_ticks += 1
        self.hops = d.hops
        return d
