"""The sticky selection rule (selection = "sticky", the default): `Sticky`, an explicit state
machine (FollowState) fed one frame's contacts per tick, with its transition table (TABLE,
TRANSITIONS), its limits (`Limits`) and its loss tally (`LossTally`).

It makes the paper's nearest choice once, waits for it to be rooted, and keeps it until it is
lost (holding it through a short loss of its path, coasting on it through a short spell out of
sight), and with nothing rooted in reach shadows an agent it senses or searches: loop-free, at
most LOSS_CHANGES changes per loss (docs/design/selection.md#states). The per-tick rules it
uses (nearest, keeps_out, feasible_kept, Choice) are in agents/selection.py. Pure: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from swarm.agents.selection import Choice, feasible_kept, keeps_out, nearest
from swarm.contracts.frames import Contact
from swarm.contracts.orbits import wrap
from swarm.contracts.vocabulary import FollowState

Contacts = tuple[Contact, ...]
Coast = Callable[[int], Contact | None] | None  # where a coasted out-neighbour is predicted (agents/coast.py)

LOSS_CHANGES = 4  # sticky: changes of out-neighbour one loss can cost, at most (docs/design/selection.md#switch-bound)

# -- the sticky rule: an explicit state machine (docs/design/selection.md#states) ------------------

_F = FollowState
# The states as module globals, for the handlers: on Python 3.11, FollowState.KEEP looks the member
# up through the enum's class (~0.3 us, every tick: as much as the rest of a KEEP tick's handler).
ACQUIRE, KEEP, HOLD, COAST, SHADOW, SEARCH, LOST, LATE = (
    _F.ACQUIRE,
    _F.KEEP,
    _F.HOLD,
    _F.COAST,
    _F.SHADOW,
    _F.SEARCH,
    _F.LOST,
    _F.LATE,
)
COMMITTED = frozenset({KEEP, HOLD, COAST})  # states with an out-neighbour it is committed to

# The transition table, as in docs/design/selection.md#states: (from any of, condition, to). The
# handlers return the condition's name with the next state; tests/pure/test_follow_states.py walks
# every row, and tests/pure/test_sticky.py checks that no other transition is ever taken.
TABLE: tuple[tuple[tuple[FollowState, ...], str, FollowState], ...] = (
    ((_F.LATE,), "patience", _F.LATE),  # silent for at most `wait` ticks since it joined
    ((_F.LATE, _F.ACQUIRE), "quiet", _F.LATE),  # late, never committed, silent < quiet, nobody feasible
    ((_F.LATE, _F.ACQUIRE, _F.SHADOW, _F.SEARCH), "wait", _F.ACQUIRE),  # its nearest agent may still root
    ((_F.LATE, _F.ACQUIRE, _F.SHADOW, _F.SEARCH, _F.LOST), "commit", _F.KEEP),  # a feasible rooted agent
    ((_F.LATE, _F.ACQUIRE, _F.SHADOW, _F.SEARCH, _F.LOST), "shadow", _F.SHADOW),  # keeps or takes a shadow
    ((_F.LATE, _F.ACQUIRE, _F.SHADOW, _F.SEARCH, _F.LOST), "search", _F.SEARCH),  # nobody
    ((_F.LOST,), "quiet", _F.LOST),  # silent < quiet, nobody feasible
    ((_F.KEEP, _F.HOLD, _F.COAST), "rooted", _F.KEEP),  # out-neighbour sensed with a path
    ((_F.KEEP, _F.HOLD), "unrooted", _F.HOLD),  # ... sensed without one, held < hold
    ((_F.KEEP, _F.COAST), "edge", _F.COAST),  # ... not sensed, predicted beyond the edge, coasted < coast
    ((_F.KEEP, _F.HOLD, _F.COAST), "switch", _F.KEEP),  # lost; a feasible rooted agent in reach
    ((_F.KEEP, _F.HOLD, _F.COAST), "lost", _F.LOST),  # lost; nobody feasible
)
TRANSITIONS = frozenset((src, cond, dst) for srcs, cond, dst in TABLE for src in srcs)
_NOBODY = Choice(None, None, False, False)
_new = tuple.__new__
_AFTER_LOSS = {"commit": "switch", "quiet": "lost"}  # what _seek's conditions are called on a loss


class Limits(NamedTuple):
    """What a sticky follower's machine needs to know, in ticks (a tuning's TuningTicks and
    the run's depth) and metres/radians."""

    wait: int  # ticks it waits for its nearest agent to root (the deepest a path can be)
    drain: int  # ticks without a path after which stale advertisements through it are gone
    hold: int  # ticks it holds an out-neighbour that lost its path
    coast: int  # ticks it coasts on an out-neighbour that left at the edge
    me: int | None  # own id: shadows of agents without a path go to lower ids only (None: never)
    reach: float  # new choices within this range (m); kept ones while sensed
    cone: float | None  # ... and within this angle of its heading (rad; None: any)

    @property
    def quiet(self) -> int:
        """Silent this long, nobody holds it or coasts on it any more: it may shadow."""
        return max(self.hold, self.coast) + 1


class LossTally:
    """Losses of a committed out-neighbour and the changes of out-neighbour each cost."""

    __slots__ = ("losses", "open", "changes", "worst")

    def __init__(self) -> None:
        self.losses = 0  # committed out-neighbours lost (out of sight, gone, held or coasted too long)
        self.open = False  # lost one and not committed again yet
        self.changes = 0  # changes of out since that loss
        self.worst = 0  # the most changes of out any one loss has cost

    def lost(self) -> None:
        self.losses += 1
        self.open, self.changes = True, 0

    def step(self, changed: bool, rooted: bool) -> None:
        if self.open:
            self.changes += changed
            if rooted:
                self.open = False
                self.worst = max(self.worst, self.changes)


class Sticky:
    """selection = "sticky" (the default): the paper's nearest choice, made once and kept;
    while nothing rooted can be chosen, hold on, shadow an agent it senses, or search.

    A state machine (FollowState), fed one frame's contacts per tick: `state` is where the
    last tick left it, `choose` runs that state's handler, which returns the condition that
    held, the next state and the choice: a transition of TRANSITIONS. The states, the table
    and why it is loop-free with at most LOSS_CHANGES changes per loss:
    docs/design/selection.md#states, #loop-free and #switch-bound. Pure, no I/O.
    """

    __slots__ = (
        "limits",
        "state",
        "out",
        "feasible",
        "silent",
        "waited",
        "spell",
        "shadowed",
        "acquired",
        "late",
        "tally",
    )

    def __init__(
        self,
        *,
        wait_ticks: int,
        drain_ticks: int,
        hold_ticks: int = 0,
        coast_ticks: int = 0,
        me: int | None = None,
        reach: float = math.inf,
        cone: float | None = None,
        late: bool = False,
    ):
        quiet = max(hold_ticks, coast_ticks) + 1
        # nobody resets `feasible` while held or coasted on (the proof): drain > quiet
        self.limits = Limits(wait_ticks, max(drain_ticks, quiet + 1), hold_ticks, coast_ticks, me, reach, cone)
        self.state = ACQUIRE
        self.out: int | None = None  # the agent it steers by (committed, provisional or shadowed)
        self.feasible: int | None = None  # fewest hops advertised since the last reset
        self.silent = 0  # ticks in a row it advertised no path, up to the previous one
        self.waited = 0  # ACQUIRE: provisional choices made while waiting for the nearest agent to root
        self.spell = 0  # HOLD, COAST: ticks held, coasted
        self.shadowed = False  # took a shadow since the last loss
        self.acquired = False  # has committed at least once since the brain started
        self.late = False  # joined a run under way
        self.tally = LossTally()
        if late:
            self.late_join()

    def late_join(self) -> None:
        """It joined a run already under way (restarted, or added), before its first tick: it
        chooses nobody until every stale advertisement of a path through an earlier life of it
        has drained (wait + 1 ticks: the deepest a path can be), and shadows nobody until nobody
        can still hold or coast on that earlier life (`quiet` ticks). Both count its silence."""
        self.state, self.late = LATE, True

    # -- what others read -------------------------------------------------------------------------
    @property
    def committed(self) -> bool:
        return self.state in COMMITTED

    @property
    def losses(self) -> int:
        return self.tally.losses

    @property
    def worst_loss(self) -> int:
        return self.tally.worst

    def loss_figures(self) -> dict:
        """losses: committed out-neighbours lost; loss_switches_max: the most changes of
        out-neighbour any one of them cost before it committed again (at most LOSS_CHANGES)."""
        return {"losses": self.tally.losses, "loss_switches_max": self.tally.worst}

    # -- one tick -----------------------------------------------------------------------------
    def choose(
        self,
        contacts: tuple[Contact, ...],
        coast: Callable[[int], Contact | None] | None = None,
        heading: float = 0.0,
    ) -> Choice:
        """This tick's out-neighbour; `Choice.rooted` says whether to advertise a path
        (hops = contact.hops + 1) through it. coast(out): the predicted contact of a
        committed out-neighbour that is not sensed (agents/coast.py), None if it cannot
        coast; asked only then. heading: its own (rad), for `cone`."""
        before = self.out
        _, self.state, ch = self.step(contacts, coast, heading)
        self.silent = 0 if ch.rooted else self.silent + 1
        tally = self.tally
        if tally.open:  # (LossTally.step counts nothing otherwise: no call on a tick without a loss)
            tally.step(ch.out != before, ch.rooted)
        return ch

    def step(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """The current state's handler: (condition, next state, choice), a row of
        TRANSITIONS. Changes everything but `state` and `silent` (choose's)."""
        return _HANDLERS[self.state](self, contacts, coast, heading)

    # -- the handlers, one per state (ACQUIRE, LOST, SHADOW, SEARCH share one) ----------------------
    def _late(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """LATE: nobody for wait + 1 ticks after joining, then as ACQUIRE (quiet: LATE again)."""
        if self.silent <= self.limits.wait:
            return "patience", LATE, _NOBODY
        return self._seek(contacts, coast, heading)

    def _keep(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """KEEP: keep it while it is sensed and rooted; hold it if it lost its path, coast on
        it if it left at the edge; else it is lost."""
        out = self.out
        for c in contacts:
            if c.id == out:
                if keeps_out(True, c.hops):
                    return self._rooted(c)
                if self.limits.hold > 0:  # hold on: it may root again
                    self.spell = 1
                    return "unrooted", HOLD, Choice(c.id, c, False, False)
                return self._lose(contacts, coast, heading)
        return self._coasting(contacts, coast, heading)

    def _hold(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """HOLD: sensed without a path; KEEP when it roots again, lost when gone or held too long."""
        out = self.out
        for c in contacts:
            if c.id == out:
                if keeps_out(True, c.hops):
                    return self._rooted(c)
                if self.spell < self.limits.hold:
                    self.spell += 1
                    return "unrooted", HOLD, Choice(c.id, c, False, False)
                break
        return self._lose(contacts, coast, heading)

    def _coast(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """COAST: steering by a prediction; KEEP when sensed rooted again; lost when sensed
        without a path, coasted too long, or the prediction fails."""
        out = self.out
        for c in contacts:
            if c.id == out:
                return self._rooted(c) if keeps_out(True, c.hops) else self._lose(contacts, coast, heading)
        return self._coasting(contacts, coast, heading)

    def _rooted(self, c: Contact) -> tuple[str, FollowState, Choice]:
        """Its out-neighbour is sensed and advertises a path (keeps_out): KEEP."""
        self.spell = 0
        self.feasible = feasible_kept(self.feasible, c.hops)  # type: ignore[type-var]
        return "rooted", KEEP, _new(Choice, (c.id, c, False, True))  # Choice(c.id, c, False, True), half the cost

    def _coasting(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """KEEP or COAST, the out-neighbour not sensed: coast on its prediction, or lose it."""
        if coast is not None and self.out is not None and self.spell < self.limits.coast:
            p = coast(self.out)
            if p is not None:  # out of sight at the edge: steer by where it must be, silent
                self.spell += 1
                return "edge", COAST, Choice(p.id, p, False, False)
        return self._lose(contacts, coast, heading)

    def _lose(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """Lost (out of sight, gone, held or coasted too long): it seeks on this very tick;
        a commit is then a switch, a quiet wait LOST."""
        self.spell, self.shadowed, self.out = 0, False, None
        self.tally.lost()
        cond, nxt, ch = self._seek(contacts, coast, heading)
        return _AFTER_LOSS.get(cond, cond), nxt, ch

    def _seek(self, contacts: Contacts, coast: Coast, heading: float) -> tuple[str, FollowState, Choice]:
        """ACQUIRE, LOST, SHADOW, SEARCH (and LATE after its patience): nobody committed to.
        One rule for all: what differs between them is in `out` (a provisional choice or a
        shadow, kept while it may be) and in `acquired` and `late`."""
        lim = self.limits
        if self.feasible is not None and self.silent >= lim.drain:
            self.feasible = None  # stale advertisements have drained
        rooted = tuple(c for c in contacts if c.hops >= 0 and (self.feasible is None or c.hops < self.feasible))
        best = nearest(tuple(c for c in rooted if self._reachable(c, heading)))
        if self.acquired:
            for c in rooted:  # the agent it shadows has rooted: commit to it
                if c.id == self.out:
                    best = c
                    break
        if best is not None:
            return self._take(best, contacts)
        if (self.acquired or self.late) and self.silent < lim.quiet:  # somebody may still hold it, or coast on it
            self.out = None
            return "quiet", LOST if self.acquired else LATE, _NOBODY
        return self._shadow(contacts, heading)

    def _take(self, best: Contact, contacts: Contacts) -> tuple[str, FollowState, Choice]:
        """A feasible rooted agent: commit to it, or, never committed yet, wait for the nearest
        agent to root while it may (`waited` < wait), steering by `best` meanwhile."""
        if not self.acquired and self.waited < self.limits.wait:
            first = nearest(contacts)
            if first is not None and first.id != best.id:
                self.waited += 1  # give the nearest agent time to root; track a rooted one
                self.out = best.id
                return "wait", ACQUIRE, Choice(best.id, best, False, False)
        self.out = best.id
        self.acquired = True
        self.feasible = best.hops + 1 if self.feasible is None else min(self.feasible, best.hops + 1)
        return "commit", KEEP, Choice(best.id, best, False, True)

    def _shadow(self, contacts: Contacts, heading: float) -> tuple[str, FollowState, Choice]:
        """Nobody feasible, and it may shadow: keep its shadow while it may, else take a new one
        (a rooted agent in reach, else a lower id in reach; after a loss only once), else search."""
        for c in contacts:
            if c.id == self.out and self._shadow_ok(c):
                return "shadow", SHADOW, Choice(c.id, c, False, False)
        shadow = None
        if not self.shadowed or not self.acquired:
            shadow = nearest(tuple(c for c in contacts if c.hops >= 0 and self._reachable(c, heading))) or nearest(
                tuple(c for c in contacts if self._shadow_ok(c) and self._reachable(c, heading))
            )
        if shadow is None:
            self.out = None
            return "search", SEARCH, _NOBODY
        self.shadowed = True
        self.out = shadow.id
        return "shadow", SHADOW, Choice(shadow.id, shadow, False, False)

    def _reachable(self, c: Contact, heading: float) -> bool:
        """May it be a new choice: within `reach`, and within `cone` of the own heading?"""
        lim = self.limits
        return c.range <= lim.reach and (lim.cone is None or abs(wrap(c.bearing - heading)) <= lim.cone)

    def _shadow_ok(self, c: Contact) -> bool:
        return c.hops >= 0 or (self.limits.me is not None and c.id < self.limits.me)


_HANDLERS = {
    FollowState.LATE: Sticky._late,
    FollowState.ACQUIRE: Sticky._seek,
    FollowState.KEEP: Sticky._keep,
    FollowState.HOLD: Sticky._hold,
    FollowState.COAST: Sticky._coast,
    FollowState.LOST: Sticky._seek,
    FollowState.SHADOW: Sticky._seek,
    FollowState.SEARCH: Sticky._seek,
}
