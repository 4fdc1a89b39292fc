"""Many AgentBrains at once: B members (scenarios) x N agents as (B, N) arrays.

`BatchBrains.decide` is AgentBrain.decide for every agent of every member in one call,
with the same state and the same arithmetic: the follower law (laws.bearing_law,
laws.loiter_rate), the leaders' orbit hold and arcs (agents/batch_leader.py) and the
hysteresis test are the per-agent brain's own functions, run on arrays (agents/ops.py);
what has an array form of its own (the choice of out-neighbour, agents/batch_select.py;
the rooted rule's filter and hop counts, here; the sticky rule's keep,
agents/batch_sticky.py) is compared with AgentBrain decision by decision on random swarms
(tests/pure/test_batch_decisions.py). A batch run equals the per-agent run (tests/pure/test_batch.py).

What a tick's frames hold, batched (`frames` below, built by the world's batch engine,
world/batch.py; this package never imports it):

    heading (B, N)          every agent's heading (own heading and contacts' headings)
    hops (B, N)             hop counts the agents advertise in this tick's frames (-1 none)
    target(b, i)            (tx, ty): target minus own position of agents (b, i) (leaders' frames)
    ids (B, N), ids_sorted  agent ids; True when ids increase along every row
    sensed_pairs(j)         (B, N): does agent i sense agent j[b, i] (False where j < 0)
    bearing_pairs(j)        (B, N): line-of-sight angle from i to j[b, i]
    matrices(m)             (sensed, range) (|m|, N, N) of members m: the whole frames

Only the built-in "bearing" law is batched (a law of one's own is Python per agent:
run it per agent). Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from swarm.agents import batch_maths as bm
from swarm.agents.batch_leader import BatchLeaders
from swarm.agents.batch_select import NONE, select
from swarm.agents.batch_sticky import BatchSticky
from swarm.agents.brain import follow_state
from swarm.agents.laws import bearing_law, loiter_rate
from swarm.agents.selection import advertised
from swarm.contracts.brain_config import AgentConf, GainsConf, SensingConf
from swarm.contracts.laws import GAINS, resolve_law
from swarm.contracts.vocabulary import FollowState, Phase
from swarm.contracts.wire import FOLLOW_CODE, FOLLOW_STATES

# the follow state of a sticky follower whose tick was a plain keep (BatchSticky.keep): what
# StickyFollower.state says after such a step
_KEEP = FOLLOW_CODE[FollowState.KEEP]


@dataclass
class BatchDecision:
    u: np.ndarray  # (B, N) commanded turn rates (rad/s)
    out: np.ndarray  # (B, N) chosen out-neighbour column, -1 none (leaders, lost followers)
    hops: np.ndarray  # (B, N) advertised hops, -1 none
    follow: np.ndarray  # (B, N) follow state codes (wire.FOLLOW_STATES; 0 none: leaders, other rules)


def vectorised(law: object) -> bool:
    """A follower law of one's own (the `[gains] law` signature) that declares it works element
    by element on arrays as on floats (`law.vectorised = True`): the batch engine runs it."""
    return getattr(law, "vectorised", False) is True


def follower_law_of(gains: list[GainsConf]) -> Callable[..., Any]:
    """The one follower law of a batch: laws.bearing_law itself, or a `[gains] law` of one's own
    declared vectorised (called with (B, N) arrays where the built-in is, and with floats for
    a follower that has just chosen); ValueError for anything else."""
    names = {g.law for g in gains}
    if len(names) != 1:
        raise ValueError(f"one follower law per batch, got {sorted(names)}")
    name = names.pop()
    if name == "bearing":
        return bearing_law
    law = resolve_law(name, GAINS)
    if not vectorised(law):
        raise ValueError(f"only the built-in 'bearing' law and laws declared vectorised are batched, not {name!r}")

    def batched(g_i: Any, g_j: Any, lambda_ij: Any, c1: Any, c2: Any, ops: object = None) -> Any:
        return law(g_i, g_j, lambda_ij, c1, c2)  # (ops: the built-in law's switch between floats and arrays)

    return batched


class BatchBrains:
    def __init__(
        self, specs: list[list[AgentConf]], gains: list[GainsConf], sensing: list[SensingConf], dt: float, max_hops: int
    ) -> None:
        """The parts of the members' BrainConfs (BrainConf.from_scenario): specs, per member its
        agents' AgentConfs in column order (same N); gains, sensing: per member its GainsConf /
        SensingConf (one selection rule for all); max_hops: the agents of a member."""
        modes = {s.selection for s in sensing}
        if len(modes) != 1:
            raise ValueError(f"one selection rule per batch, got {sorted(modes)}")
        self.law = follower_law_of(gains)
        self.mode = modes.pop()
        shape = (len(specs), len(specs[0]))
        self.max_hops = max_hops
        self.c1 = np.array([[g.c1] for g in gains], dtype=float)
        self.c2 = np.array([[g.c2] for g in gains], dtype=float)
        self.hysteresis = np.array([[s.hysteresis] for s in sensing], dtype=float)
        self.limit = np.array([[a.max_turn_rate or math.inf for a in row] for row in specs], dtype=float)
        self.follower = np.array([[a.role == "follower" for a in row] for row in specs], dtype=bool)
        col = [{a.id: k for k, a in enumerate(row)} for row in specs]
        self.pinned = np.array(
            [[col[b][a.follow] if a.follow is not None else NONE for a in row] for b, row in enumerate(specs)],
            dtype=np.int64,
        )
        self.leaders = BatchLeaders(specs, dt)
        self.sticky = BatchSticky(specs, gains, sensing, dt, max_hops, self.law) if self.mode == "sticky" else None
        self.out = np.full(shape, NONE, dtype=np.int64)  # AgentBrain.out
        self.last_u = np.zeros(shape)
        self.hops = np.full(shape, NONE, dtype=np.int64)  # advertised last tick (rooted rule)
        self.feasible = np.full(shape, NONE, dtype=np.int64)  # rooted rule
        self.unrooted = np.zeros(shape, dtype=np.int64)
        self.nonfinite = np.zeros(shape, dtype=np.int64)
        self.rooted = np.ones(shape, dtype=bool)  # last tick: Choice.rooted (the phases)
        self.searching = np.zeros(shape, dtype=bool)  # last tick: flying a search circle
        self.follow = np.zeros(shape, dtype=np.int8)  # last tick: Decision.follow, as wire codes

    # -- selection ------------------------------------------------------------------------------
    def _choose(self, frames: Any) -> tuple[np.ndarray, np.ndarray]:
        """(choice columns, rooted) (B, N) for the followers' rows (not sticky)."""
        ids = None if frames.ids_sorted else frames.ids
        choice = np.full(self.out.shape, NONE, dtype=np.int64)
        need = self.follower.copy()
        if self.mode == "fixed":  # the pinned out-neighbour while it is sensed
            pinned = self.follower & (self.pinned >= 0) & frames.sensed_pairs(self.pinned)
            choice = np.where(pinned, self.pinned, choice)
            need &= ~pinned
        m = np.flatnonzero(need.any(axis=1))
        if m.size:
            cand, rng = frames.matrices(m)
            if self.mode == "rooted":
                cand = cand & self._rooted_candidates(frames.hops[m], m)
            c = select(cand, rng, None if ids is None else ids[m], self.out[m], self.hysteresis[m])
            choice[m] = np.where(need[m], c, choice[m])
        return choice, np.ones(choice.shape, dtype=bool)

    def _rooted_candidates(self, hops: np.ndarray, m: np.ndarray) -> np.ndarray:
        """selection.select's rooted filter with AgentBrain._below: (|m|, N, N)."""
        below = np.where(
            self.hops[m] >= 0, self.hops[m], np.where(self.unrooted[m] < self.max_hops, self.feasible[m], NONE)
        )[..., None]
        hj = hops[:, None, :]
        current = np.arange(hops.shape[1])[None, None, :] == self.out[m][..., None]
        return (hj >= 0) & ((below < 0) | (hj < below) | current)

    def figures(self, b: int, i: int) -> dict:
        """AgentBrain.figures of member b's agent in column i."""
        more = {} if self.sticky is None else self.sticky.stats(b, i)
        return {"nonfinite": int(self.nonfinite[b, i]), **more}

    def phases(self) -> list[list[Phase]]:
        """Decision.phase of every agent (B lists of N) at the last tick decided."""
        lead = dict(zip(zip(self.leaders.b.tolist(), self.leaders.i.tolist()), self.leaders.phases()))
        return [
            [
                lead[b, i]
                if (b, i) in lead
                else (Phase.SEARCH if searching else Phase.LOST)
                if out < 0
                else (Phase.TRACK if rooted else Phase.SHADOW)
                for i, (out, rooted, searching) in enumerate(zip(*row))
            ]
            for b, row in enumerate(zip(self.out.tolist(), self.rooted.tolist(), self.searching.tolist()))
        ]

    def follow_states(self) -> list[list[str]]:
        """Decision.follow of every agent (B lists of N) at the last tick decided."""
        names = [str(s) for s in FOLLOW_STATES]
        return [[names[c] for c in row] for row in self.follow.tolist()]

    def _follow(self, kept: np.ndarray) -> np.ndarray:
        """The follow state codes of this tick (sticky): keep where it kept, the StickyFollower's
        own state for those it stepped, none for leaders."""
        assert self.sticky is not None
        follow = np.where(kept, np.int8(_KEEP), np.int8(0)).astype(np.int8)
        agents = self.sticky.agents
        for b, i in np.argwhere(self.follower & ~kept).tolist():
            follow[b, i] = FOLLOW_CODE[follow_state(agents[(b, i)])]
        return follow

    # -- one tick -------------------------------------------------------------------------------
    def decide(self, tick: int, frames: Any) -> BatchDecision:
        """AgentBrain.decide for every agent of every member on this tick's frames."""
        heading, hops_in = frames.heading, frames.hops
        if self.sticky is not None:
            kept = self.sticky.keep(frames, self.follower)
            choice = np.where(kept, self.sticky.out, NONE)
            rooted = kept.copy()
        else:
            choice, rooted = self._choose(frames)
            choice = np.where(self.follower, choice, NONE)
        track = choice >= 0
        # the law on every follower with an out-neighbour: laws.bearing_law itself, on arrays
        lam = frames.bearing_pairs(choice)
        u = self.law(heading, bm.take(heading, choice), lam, self.c1, self.c2, ops=bm.ARRAY)
        # nobody (rooted) in sight: loiter the way it last turned (laws.loiter's rate)
        u = np.where(track, u, loiter_rate(self.c2, self.last_u, ops=bm.ARRAY))
        h_j = bm.take(hops_in, choice)
        hops = advertised(h_j, track & rooted, self.max_hops, NONE, bm.ARRAY)
        if self.sticky is not None:
            self.sticky.sight(tick, frames, kept, lam)
            # everybody who did not simply keep: one by one, written into choice, u, hops
            self.searching = np.zeros(u.shape, dtype=bool)
            self.sticky.rest(tick, frames, self.follower & ~kept, self.last_u, choice, u, hops, rooted, self.searching)
            self.follow = self._follow(kept)
        bad = self.follower & ~np.isfinite(u)
        if bad.any():  # a NaN or inf turn rate: counted, the last one held
            self.nonfinite += bad
            u = np.where(bad, self.last_u, u)
        u = bm.saturate(u, self.limit)
        lead = self.leaders
        if len(lead.b):
            lb, li = lead.b, lead.i
            tx, ty = frames.target(lb, li)
            u[lb, li] = lead.decide(tick, tx, ty, heading[lb, li])
            hops[lb, li] = 0
        self.out = choice
        self.last_u = u
        self.rooted = rooted
        if self.mode == "rooted":  # what AgentBrain._below reads (only the rooted rule does)
            rooted_now = hops >= 0
            self.feasible = np.where(rooted_now, hops, self.feasible)
            self.unrooted = np.where(rooted_now, 0, self.unrooted + 1)
            self.hops = hops
        return BatchDecision(u, choice, hops, self.follow)
