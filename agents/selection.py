"""Out-neighbour selection from one sensor frame (paper, Definition 2).

Each follower picks the closest agent it senses; ties go to the lowest id (the paper
allows any). Leaders are sinks. With selection = "fixed" a follower keeps the agent
named by its `follow` while it senses it, and falls back to the nearest sensed agent
otherwise (and says so). With selection = "rooted" only agents that advertise a path to
a leader (hops >= 0) are candidates, which keeps the paper's Assumption 1 true wherever
a rooted agent is in sight: nearest choice alone can pair two followers in a cycle.
Hysteresis h in [0, 1): keep the current out-neighbour unless another is closer than
(1 - h) times its range. Neither rule bounds the number of switches: as agents move,
the nearest (rooted) agent keeps changing, and a follower that alternates between two
leaders' trees never settles.

selection = "sticky" (the default, `Sticky` below) makes the paper's nearest choice once,
waits for it to be rooted, and keeps it until it is lost: finitely many switches, loop-
free, reacting on the tick the out-neighbour is lost. Pure: no I/O.
"""

from __future__ import annotations

from typing import NamedTuple

from swarm.contracts.frames import Contact


class Choice(NamedTuple):
    out: int | None  # chosen out-neighbour id, None if nobody is sensed (or a leader)
    contact: Contact | None
    fallback: bool  # a pinned out-neighbour was not sensed and the nearest was used instead
    rooted: bool = True  # sticky rule: advertise a path through `out` (False while acquiring)


def nearest(contacts: tuple[Contact, ...]) -> Contact | None:
    best = None
    for c in contacts:
        if best is None or (c.range, c.id) < (best.range, best.id):
            best = c
    return best


def select(contacts: tuple[Contact, ...], *, mode: str, pinned: int | None, current: int | None,
           hysteresis: float = 0.0, below: int | None = None) -> Choice:
    """Choose a follower's out-neighbour among `contacts`.

    rooted mode: candidates advertise hops >= 0 and, when `below` is given, hops < below
    (the current out-neighbour stays a candidate while it is rooted). A follower's
    descendants advertise more hops than it does, so with below = its own hop count it
    can never pick one: switching is loop-free (the feasibility condition of
    distance-vector routing).
    """
    if mode == "rooted":
        contacts = tuple(c for c in contacts if c.hops >= 0 and (below is None or c.hops < below
                                                                 or c.id == current))
    if mode == "fixed" and pinned is not None:
        for c in contacts:
            if c.id == pinned:
                return Choice(c.id, c, False)
        fallback = True
    else:
        fallback = False
    best = nearest(contacts)
    if best is None:
        return Choice(None, None, fallback)
    if hysteresis > 0.0 and current is not None and current != best.id:
        for c in contacts:
            if c.id == current and best.range > (1.0 - hysteresis) * c.range:
                return Choice(c.id, c, fallback)
    return Choice(best.id, best, fallback)


class Sticky:
    """selection = "sticky" (the default): the paper's nearest choice, made once and kept.

    State machine of one follower, fed one frame's contacts per tick (pure, no I/O):

    - **Acquire** (its first choice after starting): take the nearest sensed agent as soon
      as it advertises a path to a leader. Paths spread one hop per tick from the leaders,
      so while the nearest agent is not rooted yet the follower waits up to `wait_ticks`
      ticks for it, tracking the nearest rooted agent meanwhile and advertising nothing
      (so nobody can root through a choice it may still change). If the nearest agent
      never roots (it is the follower's partner in a follower-only cycle, or loiters),
      the follower commits to the nearest rooted agent when the wait is over.
    - **Keep**: a committed follower keeps its out-neighbour for as long as it senses it
      and it advertises a path. There are no voluntary switches: nearer agents passing by
      change nothing, which is what makes the graph stop changing.
    - **Lost**: when the out-neighbour is no longer sensed (dropped, out of range or
      field of view) or no longer advertises a path, the follower switches on that very
      tick to the nearest *feasible* rooted agent: one advertising fewer hops than the
      fewest this follower has ever advertised since its last reset (`feasible`). Its
      own descendants all advertise more than that, so the switch cannot close a loop
      (the feasibility condition of loop-free distance-vector routing). With no feasible
      agent in sight it loiters (out = None, advertising no path); after `drain_ticks`
      ticks every stale advertisement that passed through it has been replaced, so it
      resets `feasible` and takes any rooted agent.

    Loop-free: along every rooted edge i -> j, feasible_j < feasible_i (j's feasible is
    at most the hops it advertised when i chose it, which were below feasible_i; later
    both only decrease, and i's stays above j's since i advertises j's hops + 1). A cycle
    would need feasible to decrease all the way round. Provisional edges (while acquiring)
    point at rooted agents only, and a follower acquiring advertises no path, so nobody
    rooted sits below it: they cannot close a cycle either.

    Bound: without losses a follower changes its out-neighbour at most 1 + wait_ticks
    times (median 1-2 in the README's studies: provisional choices, then the nearest once
    rooted), and never after it has committed. Each loss of the out-neighbour costs at
    most two more changes (to loitering and back). With unlimited sensing and no faults
    nothing is ever lost, so the graph is fixed within about 2 x wait_ticks ticks and the
    paper's theorem applies from there on. With a range or field of view, losses are forced by geometry
    and are counted in every run's summary (`switches`).
    """

    __slots__ = ("wait_ticks", "drain_ticks", "out", "committed", "acquired", "feasible",
                 "waited", "unrooted_ticks")

    def __init__(self, wait_ticks: int, drain_ticks: int):
        self.wait_ticks = wait_ticks
        self.drain_ticks = drain_ticks
        self.out: int | None = None
        self.committed = False  # rooted through `out`, advertising hops
        self.acquired = False  # has committed at least once since the brain started
        self.feasible: int | None = None  # fewest hops advertised since the last reset
        self.waited = 0  # ticks spent waiting for the nearest agent to root
        self.unrooted_ticks = 0  # ticks since the path was lost

    def choose(self, contacts: tuple[Contact, ...]) -> Choice:
        """This tick's out-neighbour; `Choice.rooted` says whether to advertise a path
        (hops = contact.hops + 1) through it."""
        if self.committed:
            for c in contacts:
                if c.id == self.out:
                    if c.hops >= 0:
                        self.feasible = min(self.feasible, c.hops + 1)  # type: ignore[type-var]
                        return Choice(c.id, c, False, True)
                    break
            self.committed = False  # lost: out of sight, gone, or its path is gone
            self.unrooted_ticks = 0
        if self.feasible is not None and self.unrooted_ticks >= self.drain_ticks:
            self.feasible = None  # stale advertisements have drained
        best = nearest(tuple(c for c in contacts
                             if c.hops >= 0 and (self.feasible is None or c.hops < self.feasible)))
        if best is None:
            self.out = None
            self.unrooted_ticks += 1
            return Choice(None, None, False, False)
        if not self.acquired and self.waited < self.wait_ticks:
            first = nearest(contacts)
            if first is not None and first.id != best.id:
                self.waited += 1  # give the nearest agent time to root; track a rooted one
                self.out = best.id
                return Choice(best.id, best, False, False)
        self.out = best.id
        self.committed = self.acquired = True
        self.unrooted_ticks = 0
        self.feasible = best.hops + 1 if self.feasible is None else min(self.feasible, best.hops + 1)
        return Choice(best.id, best, False, True)
