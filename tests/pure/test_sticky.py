"""The sticky selection rule (agents/sticky.Sticky): its state machine, and its guarantees as properties.

Pure tier: `Sticky` fed scripted contacts, and a whole swarm of `Sticky` selectors on
random, changing sensing graphs with agents dropping out (hypothesis), with no physics:
no follower-only cycle is ever formed, and without losses nobody switches once committed.
In-process tier: random swarms through `swarm sim`'s engine stay under the switch bound.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm.agents.brain import AgentBrain
from swarm.agents.sticky import LOSS_CHANGES, TRANSITIONS, Sticky
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.graph import analyse
from swarm.contracts.scenario import parse_scenario
from swarm.offline.sim import run_sim
from swarm.study.swarms import SwarmSetting, random_swarm
from swarm.world.metrics import switch_ticks


def C(i, r, hops):
    return Contact(i, 0.0, 0.0, r, hops)


class Checked(Sticky):
    """A Sticky that checks every transition it takes against the table (sticky.TRANSITIONS)
    and records it in `seen` (the class's, over every run)."""

    __slots__ = ()
    seen: set = set()

    def step(self, contacts, coast, heading):
        cond, nxt, ch = super().step(contacts, coast, heading)
        row = (self.state, cond, nxt)
        assert row in TRANSITIONS, row
        Checked.seen.add(row)
        return cond, nxt, ch


# -- the state machine ---------------------------------------------------------------------


def test_commits_at_once_to_a_nearest_agent_that_is_rooted():
    s = Sticky(wait_ticks=5, drain_ticks=5)
    ch = s.choose((C(1, 10.0, 0), C(3, 20.0, -1)))
    assert (ch.out, ch.rooted) == (1, True)


def test_waits_for_the_nearest_agent_to_root_tracking_a_rooted_one_meanwhile():
    s = Sticky(wait_ticks=5, drain_ticks=5)
    ch = s.choose((C(1, 50.0, 0), C(3, 10.0, -1)))  # 3 is nearest but not rooted yet
    assert (ch.out, ch.rooted) == (1, False)  # tracks the leader, advertises no path
    ch = s.choose((C(1, 50.0, 0), C(3, 10.0, 1)))  # 3 rooted now
    assert (ch.out, ch.rooted) == (3, True)


def test_commits_to_nearest_rooted_when_the_wait_is_over():
    s = Sticky(wait_ticks=3, drain_ticks=3)
    for _ in range(3):
        ch = s.choose((C(1, 50.0, 0), C(3, 10.0, -1)))
        assert not ch.rooted
    ch = s.choose((C(1, 50.0, 0), C(3, 10.0, -1)))
    assert (ch.out, ch.rooted) == (1, True)


def test_keeps_its_out_neighbour_when_nearer_agents_pass_by():
    s = Sticky(wait_ticks=3, drain_ticks=3)
    s.choose((C(1, 50.0, 0),))
    for r in (40.0, 5.0, 0.1):
        ch = s.choose((C(1, 50.0, 0), C(6, r, 0), C(7, r / 2, 1)))
        assert (ch.out, ch.rooted) == (1, True)


def test_switches_on_the_tick_its_out_neighbour_is_lost():
    s = Sticky(wait_ticks=3, drain_ticks=3)
    s.choose((C(1, 50.0, 0), C(6, 60.0, 0)))
    ch = s.choose((C(6, 60.0, 0), C(7, 5.0, 2)))  # 1 gone; 7 (2 hops) is not below our 1
    assert (ch.out, ch.rooted) == (6, True)


def test_holds_an_out_neighbour_that_lost_its_path_and_commits_again_when_it_roots():
    s = Sticky(wait_ticks=3, drain_ticks=3, me=9, hold_ticks=5)
    s.choose((C(4, 10.0, 1), C(6, 60.0, 0)))
    assert s.feasible == 2
    for _ in range(5):  # held: same out-neighbour, no path advertised
        assert s.choose((C(4, 10.0, -1), C(6, 60.0, 0)))[::3] == (4, False)
    ch = s.choose((C(4, 10.0, 1), C(6, 60.0, 0)))  # it rooted again: no change at all
    assert (ch.out, ch.rooted) == (4, True) and s.losses == 0


def test_switches_when_its_out_neighbour_stays_without_a_path_longer_than_the_hold():
    s = Sticky(wait_ticks=3, drain_ticks=3, me=9, hold_ticks=5)
    s.choose((C(4, 10.0, 1), C(6, 60.0, 0)))
    for _ in range(5):
        s.choose((C(4, 10.0, -1), C(6, 60.0, 0)))
    ch = s.choose((C(4, 10.0, -1), C(6, 60.0, 0)))
    assert (ch.out, ch.rooted) == (6, True) and s.feasible == 1 and s.losses == 1


def test_after_a_loss_ignores_its_former_descendants_searches_shadows_then_resets():
    s = Sticky(wait_ticks=4, drain_ticks=4, me=9, hold_ticks=1)  # quiet after 2 silent ticks, drained after 4
    s.choose((C(1, 50.0, 0),))  # hops 1
    # leader gone; 5 still advertises 2 hops (it followed us): not feasible
    ch = s.choose((C(5, 5.0, 2),))
    assert ch.out is None and not ch.rooted
    assert s.choose((C(5, 5.0, 3),)).out is None  # nobody may hold it yet: no shadow
    ch = s.choose((C(5, 5.0, 3),))  # quiet long enough: shadow it, advertising nothing
    assert (ch.out, ch.rooted) == (5, False)
    ch = s.choose((C(5, 5.0, 3),))
    assert (ch.out, ch.rooted) == (5, False)
    ch = s.choose((C(5, 5.0, 3),))  # drained: any rooted agent now, the one it shadows first
    assert (ch.out, ch.rooted) == (5, True) and s.feasible == 4
    assert (s.losses, s.worst_loss) == (1, 2)  # to nobody, then to 5


def test_shadows_a_lower_id_only_among_agents_without_a_path():
    s = Sticky(wait_ticks=3, drain_ticks=3, me=5)
    ch = s.choose((C(7, 5.0, -1), C(3, 20.0, -1)))  # 7 is nearer, but only 3 is below 5
    assert (ch.out, ch.rooted) == (3, False)
    assert Sticky(wait_ticks=3, drain_ticks=3, me=2).choose((C(7, 5.0, -1), C(3, 20.0, -1))).out is None


def test_new_choices_only_within_reach_but_kept_while_sensed():
    s = Sticky(wait_ticks=3, drain_ticks=3, me=9, reach=50.0)
    assert s.choose((C(1, 55.0, 0),)).out is None  # beyond reach: not taken
    ch = s.choose((C(1, 45.0, 0),))
    assert (ch.out, ch.rooted) == (1, True)
    ch = s.choose((C(1, 59.0, 0),))  # drifted beyond reach: kept
    assert (ch.out, ch.rooted) == (1, True)


def test_coasts_on_a_predicted_contact_then_loses_it():
    s = Sticky(wait_ticks=3, drain_ticks=3, me=9, coast_ticks=2)
    s.choose((C(1, 50.0, 0),))
    ghost = C(1, 61.0, 0)
    for _ in range(2):
        ch = s.choose((), lambda out: ghost)
        assert ch.contact is ghost and not ch.rooted  # steers by it, advertising nothing (it cannot see it)
        assert s.committed and s.losses == 0
    ch = s.choose((), lambda out: ghost)  # coasted long enough
    assert ch.out is None and s.losses == 1
    s2 = Sticky(wait_ticks=3, drain_ticks=3, me=9, coast_ticks=2)
    s2.choose((C(1, 50.0, 0),))
    assert s2.choose((), lambda out: None).out is None  # cannot coast (vanished mid-range): lost at once


def test_feasible_follows_the_fewest_hops_advertised():
    s = Sticky(wait_ticks=2, drain_ticks=2)
    s.choose((C(4, 10.0, 3),))
    assert s.feasible == 4
    s.choose((C(4, 10.0, 1),))  # upstream got shallower
    assert s.feasible == 2
    s.choose((C(4, 10.0, 5),))  # and deeper again: feasible stays at the minimum
    assert s.feasible == 2


def test_nobody_to_steer_by_searches_then_the_brain_tracks():
    sc = parse_scenario(
        {
            "gains": {"c1": 1.0, "c2": 0.5},
            "agents": [
                {"id": 1, "role": "leader", "x": 0, "y": 0, "heading": 0, "speed": 1, "orbit_radius": 1},
                {"id": 2, "role": "follower", "x": 5, "y": 0, "heading": 0, "speed": 1},
            ],
        }
    )
    assert sc.sensing.selection == "sticky"  # the default
    b = AgentBrain(dataclasses.replace(BrainConf.from_scenario(sc, 2), dt=0.01))  # max_hops: its 2 agents
    d = b.decide(SensorFrame(0, 0.0, 2, 0.0, (C(3, 1.0, -1),), None))  # 3: a higher id, no path
    assert d.out is None and d.phase == "search" and d.hops is None and math.isfinite(d.u)
    d = b.decide(SensorFrame(1, 0.01, 2, 0.0, (C(3, 1.0, -1), C(1, 9.0, 0)), None))
    assert d.out == 1 and d.hops is None  # waiting for 3, tracking 1
    d = b.decide(SensorFrame(2, 0.02, 2, 0.0, (C(3, 1.0, 1), C(1, 9.0, 0)), None))
    assert d.out == 3 and d.hops == 2


# -- properties on abstract swarms ---------------------------------------------------------


def _abstract_run(
    seed: int,
    n: int,
    leaders: int,
    ticks: int,
    p_sense: float,
    p_drop: float,
    hold: int = 20,
    coast: int = 0,
    reach: float = math.inf,
    selectors: dict | None = None,
):
    """n Sticky selectors (ids 0..n-1, the first `leaders` are leaders) on random sensing
    graphs that change every tick, with agents dropping out and coming back; hop counts
    relayed with one tick of delay, as the world does. With coast > 0 an out-neighbour out
    of sight may be coasted on (a predicted contact carrying the hops last seen, offered at
    random, as an edge sighting would be). Yields (tick, out, alive); `selectors`, when
    given, is filled with the Sticky objects (the live ones)."""
    rng = np.random.default_rng(seed)

    def fresh(i, late=False):
        return Checked(wait_ticks=n, drain_ticks=n, me=i, reach=reach, hold_ticks=hold, coast_ticks=coast, late=late)

    sel = {i: fresh(i) for i in range(leaders, n)}
    if selectors is not None:
        selectors.clear()
        selectors.update(sel)
    hops = np.array([0] * leaders + [-1] * (n - leaders))
    alive = np.ones(n, dtype=bool)
    pos = rng.uniform(0, 100, size=(n, 2))
    seen_hops: dict[tuple[int, int], int] = {}
    for k in range(ticks):
        pos += rng.normal(0, 3.0, size=(n, 2))
        if p_drop:
            flip = rng.random(n) < p_drop
            for i in np.flatnonzero(flip):
                alive[i] = not alive[i]
                if alive[i] and i >= leaders:
                    sel[i] = fresh(i, late=True)  # a restarted process: a fresh brain, late
                    if selectors is not None:
                        selectors[i] = sel[i]
                hops[i] = (0 if i < leaders else -1) if alive[i] else -1
        sensed = (rng.random((n, n)) < p_sense) & alive[None, :] & alive[:, None]
        np.fill_diagonal(sensed, False)
        dist = np.hypot(*(pos[:, None, :] - pos[None, :, :]).transpose(2, 0, 1))
        new_hops = hops.copy()
        out: dict[int, int | None] = {i: None for i in range(n) if alive[i]}
        for i in range(leaders, n):
            if not alive[i]:
                continue
            contacts = tuple(
                Contact(int(j), 0.0, 0.0, float(dist[i, j]), int(hops[j])) for j in np.flatnonzero(sensed[i])
            )
            for c in contacts:
                seen_hops[(i, c.id)] = c.hops

            def predict(j, i=i, dist=dist):
                if rng.random() < 0.5 or (i, j) not in seen_hops:
                    return None
                return Contact(j, 0.0, 0.0, float(dist[i, j]), seen_hops[(i, j)])

            ch = sel[i].choose(contacts, predict if coast else None)
            out[i] = ch.out
            new_hops[i] = ch.contact.hops + 1 if ch.rooted else -1
        hops = new_hops
        yield k, out, alive.copy()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 14),
    leaders=st.integers(1, 3),
    p_sense=st.floats(0.1, 1.0),
    p_drop=st.sampled_from([0.0, 0.01, 0.05]),
    hold=st.integers(0, 6),
    coast=st.integers(0, 6),
    reach=st.sampled_from([math.inf, 60.0, 100.0]),
)
def test_no_follower_only_cycle_is_ever_formed(seed, n, leaders, p_sense, p_drop, hold, coast, reach):
    """Every out edge counts: committed, held, coasted, provisional and shadow edges. (Every
    transition taken is a row of the table: `Checked`.)"""
    leaders = min(leaders, n - 1)
    for k, out, _alive in _abstract_run(seed, n, leaders, 80, p_sense, p_drop, hold, coast, reach):
        g = analyse(out, set(range(leaders)))
        assert g["cycles"] == [], (k, out)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 14),
    leaders=st.integers(1, 3),
    p_sense=st.floats(0.1, 1.0),
    p_drop=st.sampled_from([0.0, 0.01, 0.05]),
    hold=st.integers(0, 6),
    coast=st.integers(0, 6),
)
def test_each_loss_costs_at_most_loss_changes(seed, n, leaders, p_sense, p_drop, hold, coast):
    """Counted from the outside: from the tick a committed follower loses its out-neighbour
    (its loss count goes up) to the tick it advertises a path again, its out changes at
    most LOSS_CHANGES times."""
    leaders = min(leaders, n - 1)
    sel: dict = {}
    episodes: dict[int, list] = {}  # follower -> [changes] of the loss under way
    last: dict[int, int | None] = {}
    losses = {i: 0 for i in range(leaders, n)}
    for k, out, alive in _abstract_run(seed, n, leaders, 80, p_sense, p_drop, hold, coast, selectors=sel):
        for i, s in sel.items():
            if not alive[i]:
                episodes.pop(i, None)
                last.pop(i, None)
                continue
            if s is not sel.get(i) or s.losses < losses.get(i, 0):
                losses[i] = 0
            if s.losses > losses[i]:  # lost this tick: the change to this tick's choice counts
                losses[i] = s.losses
                episodes[i] = [int(last.get(i) != out[i])]
            elif i in episodes:
                episodes[i][0] += int(last.get(i) != out[i])
            if i in episodes:
                assert episodes[i][0] <= LOSS_CHANGES, (k, i, episodes[i])
                if s.committed and s.silent == 0:
                    del episodes[i]
            last[i] = out[i]
        assert all(s.worst_loss <= LOSS_CHANGES for s in sel.values())


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 14), leaders=st.integers(1, 3))
def test_without_losses_the_graph_stops_changing(seed, n, leaders):
    """Everyone senses everyone (the distances still change every tick): every follower
    commits within n + depth ticks and never switches after that; at most 1 + n changes."""
    leaders = min(leaders, n - 1)
    history = [out for _, out, _ in _abstract_run(seed, n, leaders, 4 * n + 10, 1.0, 0.0)]
    settled = history[2 * n + 1]
    assert all(out == settled for out in history[2 * n + 1 :])
    assert analyse(settled, set(range(leaders)))["unrooted"] == []
    for i in range(leaders, n):
        changes = sum(1 for a, b in zip(history, history[1:]) if a[i] != b[i])
        assert changes <= 1 + n


# -- random swarms through the in-process engine ---------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 17, 101])
def test_random_swarm_switches_stay_under_the_bound(seed):
    setting = SwarmSetting(n=8, leaders=2, duration=30.0, dt=0.05)
    res = run_sim(random_swarm(setting, seed))
    a = res.recorder.arrays()
    n = len(a["ids"])
    for j, ks in enumerate(switch_ticks(a["out"], a["alive"])):
        assert len(ks) <= 1 + n, (j, ks)
        assert all(k <= 2 * n for k in ks), (j, ks)  # nothing after the acquisition phase
    final = {int(i): (int(o) if o >= 0 else None) for i, o in zip(a["ids"], a["out"][-1])}
    g = analyse(final, {1, 2})
    assert g["cycles"] == [] and g["unrooted"] == []


def test_random_swarm_is_the_same_for_every_rule_and_range():
    a = random_swarm(SwarmSetting(selection="sticky"), 5)
    b = random_swarm(SwarmSetting(selection="nearest", range=30.0), 5)
    assert [(x.x, x.y, x.heading, x.speed) for x in a.agents] == [(x.x, x.y, x.heading, x.speed) for x in b.agents]
    assert a.agents[0].orbit_radius == pytest.approx(a.agents[0].speed)  # omega = 1
    assert math.isinf(SwarmSetting().range)


def test_a_first_choice_after_joining_is_never_a_switch():
    """Ticks without an out-neighbour before the first choice, and the
    first choice itself, are not switches; nor is the first choice after a rejoin. Later
    changes, to or from none, are."""
    out = np.array([[-1, -1], [-1, 3], [2, 3], [2, -1], [5, -1], [5, -1], [-1, -1], [-1, 4], [6, 4]])
    alive = np.array([[1, 1], [1, 1], [1, 1], [1, 1], [1, 1], [0, 1], [1, 1], [1, 1], [1, 1]], dtype=bool)
    a, b = switch_ticks(out, alive)
    assert a.tolist() == [4]  # 2 -> 5; not the first choice (tick 2) nor the one after its rejoin (tick 8)
    assert b.tolist() == [3, 7]  # 3 -> none, none -> 4
