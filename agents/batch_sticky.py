"""selection = "sticky" for (B, N) followers at once, equal to the per-agent brain to the bit.

Most ticks of most followers are a plain *keep*: the committed out-neighbour is sensed
and advertises a path, and the follower keeps it. That step is done here over arrays
(`keep`, then `sight`, which records the sighting the follower's Tracker and
SearchMemory would). Every other follower-tick (acquiring, holding, coasting, lost,
shadowing, searching) goes through the follower's own swarm.agents.sticky_follower
.StickyFollower, the very code AgentBrain runs (`rest`), fed the contacts its frame
would hold; its law is swarm.agents.laws.bearing's arithmetic, or the search. A follower's
scalar object is brought up to date from the arrays before it steps after keeps, and
the arrays from it after: the two never disagree on what the next tick needs.

Pure: no I/O.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from swarm.agents import batch_maths as bm
from swarm.agents.batch_select import NONE
from swarm.agents.coast import Sighting
from swarm.agents.laws import bearing_law, loiter_rate
from swarm.agents.leader import on_orbit_command
from swarm.agents.selection import advertised, feasible_kept, keeps_out
from swarm.agents.sticky_follower import StickyFollower
from swarm.contracts.vocabulary import FollowState


class BatchSticky:
    """The sticky followers of a batch: arrays for the keep, one StickyFollower each."""

    def __init__(
        self,
        specs: list[list],
        gains: list,
        sensing: list,
        dt: float,
        max_hops: int,
        law: Callable[..., Any] = bearing_law,
    ):
        """law: the follower law (laws.bearing_law, or batch.follower_law_of's law of one's own)."""
        shape = (len(specs), len(specs[0]))
        self.law = law
        self.dt = dt
        self.max_hops = max_hops
        self.specs = specs
        self.gains = gains
        self.col = [{a.id: k for k, a in enumerate(row)} for row in specs]
        self.agents = {
            (b, i): StickyFollower(a, gains[b], sensing[b], dt, max_hops)
            for b, row in enumerate(specs)
            for i, a in enumerate(row)
            if a.role == "follower"
        }
        self.out = np.full(shape, NONE, dtype=np.int64)  # Sticky.out (a column)
        self.committed = np.zeros(shape, dtype=bool)  # Sticky.committed: state KEEP, HOLD or COAST
        self.feasible = np.full(shape, NONE, dtype=np.int64)
        self.fresh = np.ones(shape, dtype=bool)  # the scalar object is up to date
        # the last sighting of the agent steered by (Tracker.last), and the one before (prev)
        self.last = _Sightings(shape)
        self.prev = _Sightings(shape)
        # (b, i) -> the contact `rest` steered it by at its last step there (None: nobody): what
        # its Observation.out was (a predicted one while it coasts); swarm.env's vector env reads it
        self.chosen: dict[tuple[int, int], Any] = {}

    # -- the keep, over arrays --------------------------------------------------------------------
    def keep(self, frames: Any, follower: np.ndarray) -> np.ndarray:
        """(B, N) True where a committed follower (KEEP, HOLD, COAST) senses its out-neighbour
        and it advertises a path: the machine's "rooted" transition to KEEP (Sticky._rooted:
        feasible updated; spell and silent 0): selection.keeps_out and feasible_kept, what
        Sticky's KEEP, HOLD and COAST handlers call, on arrays."""
        h_out = bm.take(frames.hops, self.out)
        # keeps_out(committed & sensed, h_out), with the sensing of pairs (the dearer part)
        # and-ed in last, only when some committed follower's out-neighbour has a path
        kept = keeps_out(follower & self.committed, h_out)
        if kept.any():
            kept &= frames.sensed_pairs(self.out)
        self.feasible = np.where(kept, feasible_kept(self.feasible, h_out, bm.ARRAY), self.feasible)
        self.fresh &= ~kept
        return kept

    def sight(self, tick: int, frames: Any, kept: np.ndarray, lam: np.ndarray) -> None:
        """Tracker.sighted (and SearchMemory's anchor) for the kept followers: lam the bearing
        to their out-neighbours."""
        if not kept.any():
            return
        out = self.out
        dx, dy = frames.offsets(out)
        same = self.last.valid & (self.last.col == out)
        self.prev.assign(kept, self.last, same)
        self.last.put(
            kept,
            out,
            tick * self.dt,
            np.hypot(dx, dy),
            lam,
            bm.take(frames.heading, out),
            bm.take(frames.hops, out),
            frames.heading,
        )

    # -- everybody else, one by one -----------------------------------------------------------------
    def rest(
        self,
        tick: int,
        frames: Any,
        need: np.ndarray,
        last_u: np.ndarray,
        choice: np.ndarray,
        u: np.ndarray,
        hops: np.ndarray,
        rooted: np.ndarray,
        searching: np.ndarray,
    ) -> None:
        """StickyFollower.step and the law for the followers `need`, written into choice, u,
        hops, rooted (Choice.rooted) and searching (a search circle to fly) (B, N) in place."""
        if not need.any():
            return
        time = tick * self.dt
        members = np.flatnonzero(need.any(axis=1))
        sensed, rng = frames.matrices(members)
        for k, b in enumerate(members.tolist()):
            col = self.col[b]
            for i in np.flatnonzero(need[b]).tolist():
                f = self.agents[(b, i)]
                if not self.fresh[b, i]:
                    self._load(f, b, i)
                heading = float(frames.heading[b, i])
                ch, search = f.step(
                    frames.contacts(b, i, sensed[k, i], rng[k, i]), heading, time, float(last_u[b, i]), tick
                )
                self._store(f, b, i, col)
                c, g = ch.contact, self.gains[b]
                self.chosen[(b, i)] = c
                rooted[b, i], searching[b, i] = ch.rooted, search is not None
                if c is None:
                    spec = self.specs[b][i]
                    u[b, i] = (
                        loiter_rate(g.c2, float(last_u[b, i]))
                        if search is None
                        else on_orbit_command(
                            -search.x,
                            -search.y,
                            heading,
                            spec.speed,
                            search.radius,
                            search.direction,
                            spec.max_turn_rate,
                        )
                    )
                    choice[b, i], hops[b, i] = NONE, NONE
                else:
                    u[b, i] = self.law(heading, c.heading, c.bearing, g.c1, g.c2)
                    choice[b, i] = col[c.id]
                    hops[b, i] = advertised(c.hops, ch.rooted, self.max_hops, NONE)

    def _load(self, f: StickyFollower, b: int, i: int) -> None:
        """Bring the scalar follower up to date after keeps (what they changed)."""
        st, tr, mem = f.sticky, f.tracker, f.memory
        st.state = f.state = FollowState.KEEP  # kept: Sticky._rooted's transition, "rooted" -> KEEP
        st.spell = st.silent = 0
        st.feasible = int(self.feasible[b, i])
        ids = self.specs[b]
        tr.last = self.last.get(b, i, ids)
        tr.prev = self.prev.get(b, i, ids)
        tr.state = tr.predicted = None
        s = tr.last
        mem.anchor, mem.home, mem.prev = (s.range, s.bearing), None, (s.own, s.time)  # type: ignore[union-attr]
        mem.searching = False
        self.fresh[b, i] = True

    def _store(self, f: StickyFollower, b: int, i: int, col: dict) -> None:
        """The arrays after a scalar step."""
        st, tr = f.sticky, f.tracker
        self.out[b, i] = NONE if st.out is None else col[st.out]
        self.committed[b, i] = st.committed
        self.feasible[b, i] = NONE if st.feasible is None else st.feasible
        self.last.set(b, i, tr.last, col)
        self.prev.set(b, i, tr.prev, col)

    def stats(self, b: int, i: int) -> dict:
        """Loss figures of one follower (as AgentBrain reports them)."""
        f = self.agents.get((b, i))
        return {} if f is None else f.sticky.loss_figures()


class _Sightings:
    """swarm.agents.coast.Sighting over (B, N) arrays (`valid` False: None)."""

    FIELDS = ("time", "range", "bearing", "heading", "own")

    def __init__(self, shape: tuple[int, int]) -> None:
        self.valid = np.zeros(shape, dtype=bool)
        self.col = np.full(shape, NONE, dtype=np.int64)
        self.hops = np.full(shape, NONE, dtype=np.int64)
        # Sighting's float fields (FIELDS), each (B, N)
        self.time, self.range, self.bearing, self.heading, self.own = (np.zeros(shape) for _ in self.FIELDS)

    def put(
        self,
        where: np.ndarray,
        col: np.ndarray,
        time: Any,
        rng: np.ndarray,
        bearing: np.ndarray,
        heading: np.ndarray,
        hops: np.ndarray,
        own: np.ndarray,
    ) -> None:
        self.valid |= where
        self.col = np.where(where, col, self.col)
        self.hops = np.where(where, hops, self.hops)
        for name, v in zip(self.FIELDS, (time, rng, bearing, heading, own)):
            setattr(self, name, np.where(where, v, getattr(self, name)))

    def assign(self, where: np.ndarray, other: _Sightings, same: np.ndarray) -> None:
        """self = other where `where` and `same`, None where `where` and not `same`."""
        take = where & same
        self.valid = np.where(where, take & other.valid, self.valid)
        self.col = np.where(take, other.col, self.col)
        self.hops = np.where(take, other.hops, self.hops)
        for name in self.FIELDS:
            setattr(self, name, np.where(take, getattr(other, name), getattr(self, name)))

    def get(self, b: int, i: int, specs: Any) -> Sighting | None:
        if not self.valid[b, i]:
            return None
        return Sighting(
            specs[int(self.col[b, i])].id,
            float(self.time[b, i]),
            float(self.range[b, i]),
            float(self.bearing[b, i]),
            float(self.heading[b, i]),
            int(self.hops[b, i]),
            float(self.own[b, i]),
        )

    def set(self, b: int, i: int, s: Sighting | None, col: dict) -> None:
        self.valid[b, i] = s is not None
        if s is not None:
            self.col[b, i], self.hops[b, i] = col[s.id], s.hops
            for name in self.FIELDS:
                getattr(self, name)[b, i] = getattr(s, name)
