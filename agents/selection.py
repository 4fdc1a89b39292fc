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
waits for it to be rooted, and keeps it until it is lost (holding it through a short
loss of its path, coasting on it through a short spell out of sight), and with nothing
rooted in reach shadows an agent it senses or searches: loop-free, at most 4 changes
per loss. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from operator import attrgetter
from typing import NamedTuple

from swarm.agents.ops import Num
from swarm.contracts.fastpath import compiled as _c
from swarm.contracts.frames import Contact
from swarm.contracts.orbits import wrap

REACH = 0.85  # sticky: new choices within this fraction of the sensing range only
LOSS_CHANGES = 4  # sticky: changes of out-neighbour one loss can cost, at most (Sticky's docstring)
HOLD_TICKS = 20  # sticky: ticks a follower holds an out-neighbour that lost its path


def reach(sensing_range: float | None) -> float:
    """The range (m) within which a sticky follower makes new choices: REACH x its sensing
    range (inf when unlimited). Kept choices last while sensed at all, so an agent near the
    edge of the range, in and out of sight, is not taken and lost tick after tick."""
    return math.inf if sensing_range is None else REACH * sensing_range


def cone(fov: float | None) -> float | None:
    """The same for a field of view: new choices within REACH x half of it from the heading."""
    return None if fov is None or fov >= 2 * math.pi else REACH * 0.5 * fov


class Choice(NamedTuple):
    out: int | None  # chosen out-neighbour id, None if nobody is sensed (or a leader)
    contact: Contact | None
    fallback: bool  # a pinned out-neighbour was not sensed and the nearest was used instead
    rooted: bool = True  # sticky rule: advertise a path through `out` (False while acquiring)


_RANGE_ID = attrgetter("range", "id")


def nearest_py(contacts: tuple[Contact, ...]) -> Contact | None:
    """The contact with the smallest (range, id), the first of equals; None if there is none.
    min() in C: half the time of a Python loop over 99 contacts. The reference of `nearest`."""
    return min(contacts, key=_RANGE_ID, default=None)


def _nearest_c(contacts: tuple[Contact, ...]) -> Contact | None:
    """nearest_py in the compiled module (swarm/contracts/fastpath.py), which leaves what is not
    a tuple of tuples with a float range and an int id to nearest_py."""
    assert _c is not None
    best = _c.nearest(contacts)
    return nearest_py(contacts) if best is NotImplemented else best


# The contact with the smallest (range, id), the first of equals; None if there is none.
nearest = nearest_py if _c is None else _nearest_c


def keeps_current(r_best: Num, r_current: Num, hysteresis: Num) -> Num:
    """Hysteresis h: the current out-neighbour (range r_current) stays unless the nearest
    candidate (r_best) is closer than (1 - h) times its range. On floats, or on arrays of
    followers (agents/batch_select.py): the same test."""
    return r_best > (1.0 - hysteresis) * r_current


def select(
    contacts: tuple[Contact, ...],
    *,
    mode: str,
    pinned: int | None,
    current: int | None,
    hysteresis: float = 0.0,
    below: int | None = None,
) -> Choice:
    """Choose a follower's out-neighbour among `contacts`.

    rooted mode: candidates advertise hops >= 0 and, when `below` is given, hops < below
    (the current out-neighbour stays a candidate while it is rooted). A follower's
    descendants advertise more hops than it does, so with below = its own hop count it
    can never pick one: switching is loop-free (the feasibility condition of
    distance-vector routing).
    """
    if mode == "rooted":
        contacts = tuple(c for c in contacts if c.hops >= 0 and (below is None or c.hops < below or c.id == current))
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
            if c.id == current and keeps_current(best.range, c.range, hysteresis):
                return Choice(c.id, c, fallback)
    return Choice(best.id, best, fallback)


class Sticky:
    """selection = "sticky" (the default): the paper's nearest choice, made once and kept;
    while nothing rooted can be chosen, hold on, shadow an agent it senses, or search.

    State machine of one follower `me`, fed one frame's contacts per tick (pure, no I/O).
    "Rooted" agents are those whose frame contact advertises a path (hops >= 0); new
    choices are made among agents within `reach` and `cone` (fractions of the sensing
    range and field of view, so that an agent at the edge, in and out of sight, is not
    taken and lost tick after tick):

    - **Acquire** (its first choice after starting): take the nearest agent as soon as it
      is rooted. Paths spread one hop per tick from the leaders, so while the nearest
      agent is not rooted yet the follower waits up to `wait_ticks` ticks for it,
      tracking the nearest rooted agent meanwhile and advertising nothing (so nobody can
      root through a choice it may still change). If the nearest agent never roots, the
      follower commits to the nearest rooted agent when the wait is over.
    - **Keep**: a committed follower keeps its out-neighbour for as long as it senses it
      and it advertises a path. There are no voluntary switches: nearer agents passing by
      change nothing, which is what makes the graph stop changing.
    - **Hold**: when the out-neighbour is still sensed but stops advertising a path (it
      lost its own), the follower keeps steering by it for up to `hold_ticks` ticks,
      advertising nothing, and commits to it again, with no change of out-neighbour, as
      soon as it advertises a path again. One agent's short loss then costs its subtree
      no switch at all. (Only right after a sighting of it rooted: not after coasting.)
    - **Coast**: when the out-neighbour leaves the frame at the edge of the sensor's reach,
      `coast(out)` (agents/coast.py) predicts where it is; the follower steers by that
      prediction for up to `coast_ticks` ticks, advertising nothing, and goes on as before
      if the agent is sensed again, rooted.
    - **Lost**: when the out-neighbour is no longer sensed and cannot be coasted on
      (dropped mid-range, or coasted or held too long), the follower switches on that
      very tick to the nearest *feasible* rooted agent in reach: one advertising fewer
      hops than the fewest this follower has advertised since its last reset
      (`feasible`). Its own descendants all advertise more than that, so the switch
      cannot close a loop (the feasibility condition of loop-free distance-vector
      routing). After `drain_ticks` ticks without advertising a path every stale
      advertisement that passed through it has been replaced, so it resets `feasible`
      and takes any rooted agent.
    - **Shadow**: while no feasible rooted agent is in reach, the follower steers by an
      agent it senses without advertising a path: the nearest rooted one (if not
      feasible), else the nearest one with a lower id than its own. It keeps that agent
      while it senses it and it stays such a candidate, and commits to it, with no change,
      as soon as it is a feasible rooted agent (or to the nearest feasible rooted agent in
      reach). Once it has committed, a follower shadows only after `quiet` =
      max(hold_ticks, coast_ticks) + 1 ticks without advertising (so that nobody still
      holds or coasts on it), and at most once per loss.
    - **Search**: with nobody to hold, coast on, shadow or commit to, out = None; the
      agent's law flies the search pattern of agents/search.py.
    - **Late**: a follower that joins a run already under way (restarted, or added)
      chooses nobody for wait_ticks + 1 ticks (stale advertisements of paths through an
      earlier life of it have drained by then: nobody advertises while holding or
      coasting) and shadows only after `quiet` ticks, like one that lost its path.

    Loop-free, every kind of edge included. *Ordered* edges (committed, held, coasted,
    provisional) go down in `feasible`: along a committed, held or coasted edge i -> j,
    feasible_j < feasible_i (j's feasible is at most the hops it advertised when i chose
    it, which were below feasible_i; later both only decrease, as neither resets while
    i holds or coasts: quiet < drain_ticks; and i's stays above j's since i advertises
    j's hops + 1); a provisional edge starts at a follower that never committed (feasible
    infinite) and ends at a committed one. So no cycle is made of ordered edges alone.
    A *shadow* edge s -> t starts at a follower that advertised nothing on the previous
    tick and that nobody holds or coasts on: it goes to an agent that advertised a path
    on the previous tick, or to a lower id. Ordered edges never end at a shadowing agent
    (committed and provisional edges end at agents that advertised on the previous tick;
    held and coasted ones at agents silent for at most quiet - 1 ticks since they were
    last seen rooted, which do not shadow yet). So from the head of a shadow edge a cycle
    continues either with more shadow edges between silent agents, ids decreasing, which
    cannot close, or with ordered edges only, which never reach a shadowing agent again,
    nor close by themselves. A restarted agent's feasible starts afresh; the `late`
    rule keeps it out of cycles through its earlier life (tests/pure/test_sticky.py checks
    all of this on random graphs with restarts).

    Finite time to a rooted agent, when one can be reached: a follower with nobody to
    steer by searches (agents/search.py), on a spiral that breathes out ever wider, so
    every point of the plane comes within its range, and so does every agent circling a
    point at up to 3/4 of the range from it, whatever its phase; a rooted agent it senses
    it closes in on until it is in reach, and takes as soon as it is feasible, which any
    rooted agent is once the follower has been silent for drain_ticks ticks. So a rooted
    swarm circling a fixed target at such radii is found in finite time (the studies in
    docs/design/selection.md measure the rest: every run of every setting converged).

    Bound: the first commit comes after at most 1 + wait_ticks provisional choices and
    any number of shadows and searches. After that, each loss of the out-neighbour
    costs at most LOSS_CHANGES = 4 changes of out: to a feasible rooted agent (1); or to
    nobody, then at most one shadow, then rooted (2 or 3, or 4 when that shadow is lost
    too: a second loss of contact is searched out, not shadowed again). A held or coasted
    out-neighbour that comes back rooted costs nothing. With unlimited sensing and no
    faults nothing is lost, so the graph is fixed within about 2 x wait_ticks ticks and
    the paper's theorem applies from there on. With a range or field of view, losses are
    forced by geometry while agents settle; once they are on their orbits (rigid
    rotation: fixed relative positions) nothing is lost any more and the graph stops
    changing.
    """

    __slots__ = (
        "wait_ticks",
        "drain_ticks",
        "hold_ticks",
        "coast_ticks",
        "quiet",
        "me",
        "reach",
        "out",
        "committed",
        "acquired",
        "feasible",
        "waited",
        "silent",
        "held",
        "coasted",
        "shadowed",
        "patience",
        "late",
        "cone",
        "heading",
        "losses",
        "in_loss",
        "loss_changes",
        "worst_loss",
    )

    def __init__(
        self,
        wait_ticks: int,
        drain_ticks: int,
        me: int | None = None,
        reach: float = math.inf,
        hold_ticks: int = HOLD_TICKS,
        coast_ticks: int = 0,
        late: bool = False,
        cone: float | None = None,
    ):
        self.wait_ticks = wait_ticks
        self.hold_ticks = hold_ticks
        self.coast_ticks = coast_ticks
        # silent this long, nobody holds it or coasts on it any more: it may shadow
        self.quiet = max(hold_ticks, coast_ticks) + 1
        self.drain_ticks = max(drain_ticks, self.quiet + 1)  # nobody resets while held (see the proof)
        # late: joined a run already under way (restarted, or added): stays out of everybody's way
        # until nothing can still point at, or advertise a path through, an earlier life of it
        self.patience = 0
        self.late = False
        if late:
            self.late_join()
        self.me = me  # own id: shadows of agents without a path go to lower ids only (None: never)
        self.reach = reach  # new choices within this range only (m); kept ones while sensed
        self.cone = cone  # ... and within this angle of its heading (rad; None: any), given each tick:
        self.heading = 0.0  # its own heading (rad)
        self.out: int | None = None
        self.committed = False  # rooted through `out` (advertising hops), or holding it
        self.acquired = False  # has committed at least once since the brain started
        self.feasible: int | None = None  # fewest hops advertised since the last reset
        self.waited = 0  # ticks spent waiting for the nearest agent to root
        self.silent = 0  # ticks in a row it advertised no path, up to the previous one
        self.held = 0  # ticks it has held its out-neighbour without a path
        self.coasted = 0  # ticks it has coasted on its out-neighbour out of sight
        self.shadowed = 0  # shadows taken since the last loss
        self.losses = 0  # committed out-neighbours lost (out of sight, gone, held too long)
        self.in_loss = False  # lost one and not committed again yet
        self.loss_changes = 0  # changes of out since that loss
        self.worst_loss = 0  # the most changes of out any one loss has cost

    def late_join(self) -> None:
        """It joined a run already under way (restarted, or added): it chooses nobody until
        every stale advertisement of a path through an earlier life of it has drained
        (wait_ticks, the deepest a path can be), and shadows nobody until nobody can still
        hold or coast on that earlier life (`quiet`)."""
        self.patience = self.wait_ticks + 1
        self.late = True

    def loss_figures(self) -> dict:
        """losses: committed out-neighbours lost; loss_switches_max: the most changes of
        out-neighbour any one of them cost before it committed again (at most LOSS_CHANGES)."""
        return {"losses": self.losses, "loss_switches_max": self.worst_loss}

    def _reachable(self, c: Contact) -> bool:
        """May it be a new choice: within `reach`, and within `cone` of the own heading?"""
        return c.range <= self.reach and (self.cone is None or abs(wrap(c.bearing - self.heading)) <= self.cone)

    def _shadow_ok(self, c: Contact) -> bool:
        return c.hops >= 0 or (self.me is not None and c.id < self.me)

    def choose(self, contacts: tuple[Contact, ...], coast: Callable[[int], Contact | None] | None = None) -> Choice:
        """This tick's out-neighbour; `Choice.rooted` says whether to advertise a path
        (hops = contact.hops + 1) through it. coast(out): the predicted contact of a
        committed out-neighbour that is not sensed (agents/coast.py), None if it cannot
        coast; asked only then."""
        before = self.out
        ch = self._choose(contacts, coast)
        self.silent = 0 if ch.rooted else self.silent + 1
        if self.in_loss:
            self.loss_changes += ch.out != before
            if ch.rooted:
                self.in_loss = False
                self.worst_loss = max(self.worst_loss, self.loss_changes)
        return ch

    def _choose(self, contacts: tuple[Contact, ...], coast) -> Choice:
        if self.patience:
            self.patience -= 1
            return Choice(None, None, False, False)
        if self.committed:
            for c in contacts:
                if c.id == self.out:
                    if c.hops >= 0:
                        self.held = self.coasted = 0
                        self.feasible = min(self.feasible, c.hops + 1)  # type: ignore[type-var]
                        return Choice(c.id, c, False, True)
                    if self.held < self.hold_ticks and not self.coasted:  # hold on: it may root again
                        self.held += 1
                        return Choice(c.id, c, False, False)
                    break
            else:
                if coast is not None and self.held == 0 and self.coasted < self.coast_ticks:
                    p = coast(self.out)
                    if p is not None:  # out of sight at the edge: steer by where it must be, silent
                        self.coasted += 1
                        return Choice(p.id, p, False, False)
            self.committed = False  # lost: out of sight, gone, or held too long
            self.held = self.coasted = self.shadowed = self.loss_changes = 0
            self.losses += 1
            self.in_loss = True
            self.out = None
        if self.feasible is not None and self.silent >= self.drain_ticks:
            self.feasible = None  # stale advertisements have drained
        rooted = tuple(c for c in contacts if c.hops >= 0 and (self.feasible is None or c.hops < self.feasible))
        best = nearest(tuple(c for c in rooted if self._reachable(c)))
        if self.acquired:
            for c in rooted:  # the agent it shadows has rooted: commit to it
                if c.id == self.out:
                    best = c
                    break
        if best is not None:
            if not self.acquired and self.waited < self.wait_ticks:
                first = nearest(contacts)
                if first is not None and first.id != best.id:
                    self.waited += 1  # give the nearest agent time to root; track a rooted one
                    self.out = best.id
                    return Choice(best.id, best, False, False)
            self.out = best.id
            self.committed = self.acquired = True
            self.feasible = best.hops + 1 if self.feasible is None else min(self.feasible, best.hops + 1)
            return Choice(best.id, best, False, True)
        if (self.acquired or self.late) and self.silent < self.quiet:  # somebody may still hold it, or coast on it
            self.out = None
            return Choice(None, None, False, False)
        for c in contacts:  # keep the agent it shadows while it can
            if c.id == self.out and self._shadow_ok(c):
                return Choice(c.id, c, False, False)
        shadow = None
        if self.shadowed == 0 or not self.acquired:
            shadow = nearest(tuple(c for c in contacts if c.hops >= 0 and self._reachable(c))) or nearest(
                tuple(c for c in contacts if self._shadow_ok(c) and self._reachable(c))
            )
        if shadow is None:
            self.out = None
            return Choice(None, None, False, False)
        self.shadowed += 1
        self.out = shadow.id
        return Choice(shadow.id, shadow, False, False)
