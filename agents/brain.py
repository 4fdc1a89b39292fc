"""An agent's decision logic: one sensor frame in, one turn rate out.

`AgentBrain` is what runs inside every agent process and, unchanged, inside the
in-process engine `swarm sim`; that is why the two produce the same trajectories.
It sees only its own sensor frames (never ground truth) and keeps a little state: the
follower's current out-neighbour, the last command, and its law's own `state` dict (the
leader's circle-circle plan lives there). Each tick it chooses the out-neighbour
(followers), hands its law one Observation (swarm/contracts/observation.py) and checks
what comes back. Pure: no I/O, no clocks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from swarm.agents.laws import agent_law, law_params
from swarm.agents.selection import select
from swarm.agents.sticky_follower import StickyFollower
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.observation import Observation, Search
from swarm.contracts.vocabulary import FollowState, Phase

LEADER_PHASES = (Phase.ARC1, Phase.ARC2, Phase.ORBIT)
_new = tuple.__new__
# Phases and a follow state as module globals: on Python 3.11, Phase.TRACK looks the member up
# through the enum's class (~0.3 us a time, on every tick), a global costs a load.
ORBIT, TRACK, SHADOW, SEARCH, LOST = Phase.ORBIT, Phase.TRACK, Phase.SHADOW, Phase.SEARCH, Phase.LOST
NO_FOLLOW = FollowState.NONE


class Decision(NamedTuple):
    """What an agent decided at one tick (a named tuple: made every tick, and cheap)."""

    tick: int
    u: float  # commanded turn rate over [t_k, t_k + dt) (rad/s)
    out: int | None  # chosen out-neighbour (None for leaders and lost followers)
    phase: str  # a Phase: leaders ARC1 | ARC2 | ORBIT; followers TRACK (advertising a path through
    # out), SHADOW (steering by out without a path), SEARCH (sticky: nobody to steer by, flying
    # the search pattern), LOST (other rules: nobody to steer by, loitering)
    fallback: bool = False  # pinned out-neighbour not sensed, nearest used instead
    hops: int | None = None  # hops to a leader it advertises (leaders 0; None: no path known)
    follow: str = FollowState.NONE  # a FollowState: the sticky follower's selection state after this
    # tick (NONE: leaders, followers under the other rules); sent with the command, recorded


def follow_state(sticky: StickyFollower) -> str:
    """A sticky follower's FollowState after its last step (agents/sticky_follower.py)."""
    return sticky.state


def saturate(u: float, limit: float | None) -> float:
    if limit is None:
        return u
    return max(-limit, min(limit, u))


class AgentBrain:
    """Decision logic of one agent; call `decide` once per tick with its frame."""

    def __init__(self, conf: BrainConf, max_hops: int | None = None):
        """conf: this agent's BrainConf (swarm/contracts/brain_config.py; from a scenario:
        BrainConf.from_scenario). max_hops caps advertised hop counts (count to infinity after
        a leader dies stops there); None: conf.n_agents, the agents in the scenario."""
        spec, gains, sensing, dt = conf.agent, conf.gains, conf.sensing, conf.dt
        self.conf = conf
        self.max_hops = conf.n_agents if max_hops is None else max_hops
        self.spec = spec
        self.sensing = sensing
        self.gains = gains
        self.dt = dt
        self.is_leader = spec.role == "leader"
        self.law = agent_law(spec.role, gains, conf.law)  # law(obs) -> u
        self.params = law_params(conf.law)
        self.sign = spec.direction_sign
        self.state: dict = {}  # the law's own, kept for as long as this brain lives
        self.out: int | None = None
        self.last_u = 0.0
        self.hops: int | None = None  # hops advertised last tick (rooted rule)
        self.feasible: int | None = None  # rooted rule: accept only agents with fewer hops
        self.unrooted_ticks = 0
        self.nonfinite = 0  # ticks on which the law returned NaN or inf (last u held)
        self.last_nonfinite: float | None = None
        # selection = "sticky" (agents/sticky_follower.py): choose, hold, coast, shadow, search
        sticky = sensing.selection == "sticky" and not self.is_leader
        self.sticky = StickyFollower(spec, gains, sensing, dt, self.max_hops) if sticky else None

    def _observe(self, frame: SensorFrame, out: Contact | None, search: Search | None) -> Observation:
        s, g = self.spec, self.gains
        # tuple.__new__ straight away: a third of the cost of Observation(...) (0.2 against 0.6 us)
        return _new(
            Observation,
            (
                s.id,
                s.role,
                frame.tick,
                frame.time,
                self.dt,
                s.speed,
                frame.heading,
                s.max_turn_rate,
                frame.contacts,
                out,
                frame.target,
                s.orbit_radius,
                self.sign,
                g.c1,
                g.c2,
                self.params,
                self.state,
                self.last_u,
                search,
            ),
        )

    def _command(self, frame: SensorFrame, out: Contact | None, search: Search | None = None) -> float:
        """The law's turn rate, saturated; NaN or inf is counted (the agent reports it in its
        status and the run's summary) and its last turn rate held for this tick."""
        u = float(self.law(self._observe(frame, out, search)))
        if math.isfinite(u):
            return saturate(u, self.spec.max_turn_rate)  # (before saturating: min/max would hide a NaN)
        self.nonfinite += 1
        self.last_nonfinite = u
        return self.last_u

    # -- leaders -------------------------------------------------------------------
    def _leader(self, frame: SensorFrame) -> Decision:
        if frame.target is None:
            raise ValueError(f"leader {self.spec.id}: sensor frame has no target information")
        u = self._command(frame, None)
        phase = self.state.get("phase", ORBIT)
        return _new(Decision, (frame.tick, u, None, phase if phase in LEADER_PHASES else ORBIT, False, 0, NO_FOLLOW))

    # -- followers -----------------------------------------------------------------
    def _follower(self, frame: SensorFrame) -> Decision:
        search = None
        if self.sticky is not None:
            choice, search = self.sticky.step(frame.contacts, frame.heading, frame.time, self.last_u, frame.tick)
        else:
            choice = select(
                frame.contacts,
                mode=self.sensing.selection,
                pinned=self.spec.follow,
                current=self.out,
                hysteresis=self.sensing.hysteresis,
                below=self._below(),
            )
        self.out = choice.out
        c = choice.contact
        u = self._command(frame, c, search)
        follow = NO_FOLLOW if self.sticky is None else self.sticky.state  # follow_state(self.sticky), inline
        # Decisions made with tuple.__new__, all fields given: half the cost of Decision(...)
        if c is None:  # nobody (rooted) in sight: the law searches (sticky) or loiters
            phase = LOST if search is None else SEARCH
            return _new(Decision, (frame.tick, u, None, phase, choice.fallback, None, follow))
        hops = c.hops + 1 if choice.rooted and 0 <= c.hops < self.max_hops else None
        phase = TRACK if choice.rooted else SHADOW
        return _new(Decision, (frame.tick, u, c.id, phase, choice.fallback, hops, follow))

    def _below(self) -> int | None:
        """Rooted rule: the hop count a new out-neighbour must beat (None: anyone rooted).

        While rooted: its own hops. After losing its path: the hops it had, until stale
        advertisements of its former descendants have drained (max_hops ticks)."""
        if self.sensing.selection != "rooted":
            return None
        if self.hops is not None:
            return self.hops
        return self.feasible if self.unrooted_ticks < self.max_hops else None

    def figures_of_selection(self) -> dict:
        """selection = "sticky": losses of its out-neighbour and the worst one's switches."""
        return {} if self.sticky is None else self.sticky.sticky.loss_figures()

    def figures(self) -> dict:
        """What this brain counted, for the run's summary: non-finite law outputs and, under
        selection = "sticky", losses of its out-neighbour and the worst one's switches."""
        return {"nonfinite": self.nonfinite, **self.figures_of_selection()}

    def decide(self, frame: SensorFrame) -> Decision:
        d = self._leader(frame) if self.is_leader else self._follower(frame)
        self.last_u = d.u
        if d.hops is not None:
            self.feasible, self.unrooted_ticks = d.hops, 0
        else:
            self.unrooted_ticks += 1
        self.hops = d.hops
        return d
