"""The sticky rule's state machine (agents/sticky.Sticky; docs/design/selection.md#states):
every row of its transition table walked with hand-built contacts, the state before and
after and the choice asserted; the walk covers the whole table; StickyFollower's `state`.

Pure tier. That the machine takes no transition outside the table on random, changing
sensing graphs: tests/pure/test_sticky.py (`Checked`, in every hypothesis property).
"""

from __future__ import annotations

import pytest

from swarm.agents.sticky import TRANSITIONS, Sticky
from swarm.agents.sticky_follower import StickyFollower
from swarm.contracts.brain_config import AgentConf, GainsConf, SensingConf
from swarm.contracts.frames import Contact
from swarm.contracts.vocabulary import FollowState as K

WALKED: set = set()  # rows of the table the walk below took


class Walked(Sticky):
    """A Sticky that records each transition it takes (as the row it is in the table)."""

    __slots__ = ("last",)

    def step(self, contacts, coast, heading):
        cond, nxt, ch = super().step(contacts, coast, heading)
        self.last = (self.state, cond, nxt)
        assert self.last in TRANSITIONS, self.last
        WALKED.add(self.last)
        return cond, nxt, ch


def C(i, r, hops, bearing=0.0):
    return Contact(i, bearing, 0.0, r, hops)


def machine(**kw) -> Walked:
    kw = {"wait_ticks": 3, "drain_ticks": 3, "me": 9, **kw}
    return Walked(**kw)


def tick(s: Walked, contacts, row, out, rooted=False, coast=None):
    """One tick: it takes `row` (from, condition, to) and chooses `out` (advertising a path or not)."""
    assert s.state == row[0]
    ch = s.choose(tuple(contacts), coast)
    assert s.last == row and s.state == row[2]
    assert (ch.out, ch.rooted) == (out, rooted)
    return ch


LEADER, FAR_LEADER, LOW, HIGH = C(1, 50.0, 0), C(6, 60.0, 0), C(3, 10.0, -1), C(12, 5.0, -1)
GHOST = C(1, 61.0, 0)


def committed(**kw) -> Walked:
    s = machine(**kw)
    tick(s, [LEADER], (K.ACQUIRE, "commit", K.KEEP), 1, True)
    return s


# -- LATE ----------------------------------------------------------------------------------------


def test_late_waits_wait_plus_one_ticks_then_commits():
    s = machine(wait_ticks=2, late=True)
    for _ in range(3):
        tick(s, [LEADER], (K.LATE, "patience", K.LATE), None)
    tick(s, [LEADER], (K.LATE, "commit", K.KEEP), 1, True)


def test_late_stays_late_until_quiet_then_shadows():
    s = machine(wait_ticks=1, hold_ticks=4, late=True)  # quiet = 5 silent ticks
    tick(s, [LOW], (K.LATE, "patience", K.LATE), None)
    tick(s, [LOW], (K.LATE, "patience", K.LATE), None)
    tick(s, [LOW], (K.LATE, "quiet", K.LATE), None)  # 2 silent ticks: not quiet yet
    tick(s, [LOW], (K.LATE, "quiet", K.LATE), None)
    tick(s, [LOW], (K.LATE, "quiet", K.LATE), None)
    tick(s, [LOW], (K.LATE, "shadow", K.SHADOW), 3)  # a lower id without a path: shadowed


def test_late_then_acquire_then_late_again():
    s = machine(wait_ticks=1, hold_ticks=4, late=True)
    tick(s, [], (K.LATE, "patience", K.LATE), None)
    tick(s, [], (K.LATE, "patience", K.LATE), None)
    tick(s, [LEADER, LOW], (K.LATE, "wait", K.ACQUIRE), 1)  # 3 is nearest, not rooted yet
    tick(s, [LOW], (K.ACQUIRE, "quiet", K.LATE), None)


def test_late_searches_when_nobody_is_there():
    s = machine(wait_ticks=1, late=True)  # quiet = 1
    tick(s, [], (K.LATE, "patience", K.LATE), None)
    tick(s, [], (K.LATE, "patience", K.LATE), None)
    tick(s, [HIGH], (K.LATE, "search", K.SEARCH), None)  # a higher id without a path: no shadow


# -- ACQUIRE, SHADOW, SEARCH (before the first commit) ------------------------------------------------


def test_acquire_waits_for_the_nearest_then_commits_to_it():
    s = machine()
    tick(s, [LEADER, LOW], (K.ACQUIRE, "wait", K.ACQUIRE), 1)
    tick(s, [LEADER, LOW], (K.ACQUIRE, "wait", K.ACQUIRE), 1)
    tick(s, [LEADER, C(3, 10.0, 1)], (K.ACQUIRE, "commit", K.KEEP), 3, True)


def test_acquire_shadows_its_provisional_choice_out_of_reach_and_searches():
    s = machine(reach=55.0)
    tick(s, [LEADER, LOW], (K.ACQUIRE, "wait", K.ACQUIRE), 1)
    tick(s, [C(1, 58.0, 0)], (K.ACQUIRE, "shadow", K.SHADOW), 1)  # beyond reach: kept as a shadow
    tick(s, [C(1, 58.0, 0)], (K.SHADOW, "shadow", K.SHADOW), 1)
    tick(s, [], (K.SHADOW, "search", K.SEARCH), None)
    tick(s, [], (K.SEARCH, "search", K.SEARCH), None)
    tick(s, [LOW], (K.SEARCH, "shadow", K.SHADOW), 3)
    tick(s, [LOW, LEADER], (K.SHADOW, "wait", K.ACQUIRE), 1)
    tick(s, [], (K.ACQUIRE, "search", K.SEARCH), None)
    tick(s, [LEADER, LOW], (K.SEARCH, "wait", K.ACQUIRE), 1)


def test_shadow_and_search_commit():
    s = machine()
    tick(s, [LOW], (K.ACQUIRE, "shadow", K.SHADOW), 3)
    tick(s, [C(3, 10.0, 0)], (K.SHADOW, "commit", K.KEEP), 3, True)
    s = machine()
    tick(s, [], (K.ACQUIRE, "search", K.SEARCH), None)
    tick(s, [LEADER], (K.SEARCH, "commit", K.KEEP), 1, True)


# -- KEEP, HOLD, COAST ---------------------------------------------------------------------------


def test_keep_keeps_whatever_passes_by():
    s = committed()
    tick(s, [LEADER, C(7, 1.0, 0)], (K.KEEP, "rooted", K.KEEP), 1, True)


def test_hold_then_rooted_again():
    s = committed(hold_ticks=2)
    tick(s, [C(1, 50.0, -1)], (K.KEEP, "unrooted", K.HOLD), 1)
    tick(s, [C(1, 50.0, -1)], (K.HOLD, "unrooted", K.HOLD), 1)
    tick(s, [LEADER], (K.HOLD, "rooted", K.KEEP), 1, True)
    assert s.losses == 0


def test_hold_too_long_switches_or_is_lost():
    s = committed(hold_ticks=1)
    tick(s, [C(1, 50.0, -1), FAR_LEADER], (K.KEEP, "unrooted", K.HOLD), 1)
    tick(s, [C(1, 50.0, -1), FAR_LEADER], (K.HOLD, "switch", K.KEEP), 6, True)
    s = committed(hold_ticks=1)
    tick(s, [C(1, 50.0, -1)], (K.KEEP, "unrooted", K.HOLD), 1)
    tick(s, [], (K.HOLD, "lost", K.LOST), None)  # gone: a held agent is not coasted on
    assert s.losses == 1


def test_coast_then_sensed_again():
    s = committed(coast_ticks=2)
    ch = tick(s, [], (K.KEEP, "edge", K.COAST), 1, coast=lambda out: GHOST)
    assert ch.contact is GHOST
    tick(s, [], (K.COAST, "edge", K.COAST), 1, coast=lambda out: GHOST)
    tick(s, [LEADER], (K.COAST, "rooted", K.KEEP), 1, True)


def test_coast_ends_in_a_switch_or_a_loss():
    s = committed(coast_ticks=2)
    tick(s, [FAR_LEADER], (K.KEEP, "edge", K.COAST), 1, coast=lambda out: GHOST)
    tick(s, [C(1, 50.0, -1), FAR_LEADER], (K.COAST, "switch", K.KEEP), 6, True)  # sensed, no path: lost
    s = committed(coast_ticks=1)
    tick(s, [], (K.KEEP, "edge", K.COAST), 1, coast=lambda out: GHOST)
    tick(s, [], (K.COAST, "lost", K.LOST), None, coast=lambda out: GHOST)  # coasted long enough


def test_keep_loses_and_switches_at_once():
    s = committed()
    tick(s, [FAR_LEADER], (K.KEEP, "switch", K.KEEP), 6, True)
    assert (s.losses, s.worst_loss) == (1, 1)


# -- LOST ----------------------------------------------------------------------------------------


def test_lost_waits_quiet_then_commits():
    s = committed(hold_ticks=3)
    tick(s, [], (K.KEEP, "lost", K.LOST), None, coast=lambda out: None)  # vanished mid-range
    tick(s, [LOW], (K.LOST, "quiet", K.LOST), None)
    tick(s, [FAR_LEADER], (K.LOST, "commit", K.KEEP), 6, True)


def test_lost_shadows_once_quiet_or_searches():
    s = committed()  # quiet = 1
    tick(s, [], (K.KEEP, "lost", K.LOST), None)
    tick(s, [LOW], (K.LOST, "shadow", K.SHADOW), 3)
    tick(s, [], (K.SHADOW, "search", K.SEARCH), None)
    tick(s, [C(2, 5.0, -1)], (K.SEARCH, "search", K.SEARCH), None)  # shadowed once this loss already
    s = committed()
    tick(s, [], (K.KEEP, "lost", K.LOST), None)
    tick(s, [], (K.LOST, "search", K.SEARCH), None)


# -- the table -------------------------------------------------------------------------------------


def test_the_walk_takes_every_row_of_the_table():
    """After every walk above (run in this module's order; on its own, this runs them)."""
    if WALKED != TRANSITIONS:
        for name, fn in list(globals().items()):
            if name.startswith("test_") and name != "test_the_walk_takes_every_row_of_the_table" and callable(fn):
                if fn.__code__.co_argcount == 0:
                    fn()
    assert TRANSITIONS - WALKED == set()


def test_every_state_but_none_has_a_row_from_it_and_to_it():
    states = set(K) - {K.NONE}
    assert {row[0] for row in TRANSITIONS} == states
    assert {row[2] for row in TRANSITIONS} == states


# -- StickyFollower.state ----------------------------------------------------------------------------


SPEC = AgentConf(9, "follower", 10.0, None, "ccw", None, None)
GAINS = GainsConf(1.0, 0.5, "bearing")


def follower(sensing_range: float | None = 100.0) -> StickyFollower:
    return StickyFollower(SPEC, GAINS, SensingConf("sticky", 0.0, sensing_range, None), 0.05, 3)


@pytest.mark.parametrize(
    ("frames", "states"),
    [
        ([[LEADER], [LEADER]], [K.KEEP, K.KEEP]),
        ([[LEADER, LOW], [LEADER, C(3, 10.0, 1)]], [K.ACQUIRE, K.KEEP]),
        ([[LOW]], [K.SHADOW]),
        ([[]], [K.SEARCH]),
        ([[LEADER], []], [K.KEEP, K.SEARCH]),  # the machine is LOST: it flies the search pattern
        ([[LEADER], [C(1, 50.0, -1)]], [K.KEEP, K.HOLD]),
    ],
)
def test_sticky_follower_state_after_each_step(frames, states):
    f = follower()
    for k, (contacts, want) in enumerate(zip(frames, states)):
        choice, search = f.step(tuple(contacts), 0.0, 0.05 * k, 0.0, k)
        assert f.state == want
        assert (search is not None) == (choice.out is None)
        assert f.sticky.state == (K.LOST if (k, want) == (1, K.SEARCH) else want)  # LOST: just lost


def test_sticky_follower_joining_late_is_late_then_coasts():
    f = follower(60.0)
    ch, search = f.step((), 0.0, 1.0, 0.0, 20)  # first frame at tick 20: joined late
    assert f.state == K.LATE and ch.out is None and search is not None
    f = follower(60.0)
    f.step((C(1, 50.0, 0, bearing=0.1),), 0.0, 0.0, 0.0, 0)
    f.step((C(1, 55.0, 0, bearing=0.1),), 0.0, 0.05, 0.0, 1)  # at the edge (> 0.8 x 60 m)
    ch, search = f.step((), 0.0, 0.1, 0.0, 2)
    assert f.state == K.COAST and ch.out == 1 and not ch.rooted and search is None


def test_sticky_follower_takes_its_tuning_from_sensing():
    from swarm.contracts.tuning import SelectionTuning

    tuning = SelectionTuning(hold_s=1.0, coast_s=2.0, reach=0.5, edge=0.9, search_pitch=0.25)
    f = StickyFollower(SPEC, GAINS, SensingConf("sticky", 0.0, 80.0, None, tuning), 0.05, 3)
    lim = f.sticky.limits
    assert (lim.hold, lim.coast, lim.reach, lim.quiet) == (20, 40, 40.0, 41)
    assert f.tracker.edge_range == pytest.approx(72.0) and f.memory.rho0 == 20.0
    default = follower(80.0)
    assert (default.sticky.limits.hold, default.sticky.limits.reach, default.memory.rho0) == (100, 68.0, 40.0)
