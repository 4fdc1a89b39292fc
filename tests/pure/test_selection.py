"""swarm.world.sensing (who senses whom, frames) and swarm.agents.selection (out-neighbour choice)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarm.agents.selection import nearest, select
from swarm.world.sensing import Contact, build_frames, sensing_matrix

# Agent 0 at the origin heading +x; 1 ahead at 1 m, 2 to the left at 2 m, 3 behind at 3 m,
# 4 ahead-right at 45 deg and sqrt(8) m.
IDS = np.array([10, 11, 12, 13, 14])
X = np.array([0.0, 1.0, 0.0, -3.0, 2.0])
Y = np.array([0.0, 0.0, 2.0, 0.0, -2.0])
H = np.array([0.0, 0.5, -1.0, 2.0, 3.0])
ALL = np.ones(5, dtype=bool)


def _seen(s, i=0):
    return set(np.flatnonzero(s[i]).tolist())


def test_unlimited_sensing_sees_everyone_but_self():
    s, bearing, rng = sensing_matrix(X, Y, H, ALL, None, None)
    assert s.shape == (5, 5)
    assert not s.diagonal().any()
    assert s.sum() == 5 * 4
    assert _seen(s) == {1, 2, 3, 4}


def test_bearings_and_ranges():
    _, bearing, rng = sensing_matrix(X, Y, H, ALL, None, None)
    assert bearing[0, 1] == pytest.approx(0.0)
    assert bearing[0, 2] == pytest.approx(math.pi / 2)
    assert bearing[0, 3] == pytest.approx(math.pi)
    assert bearing[0, 4] == pytest.approx(-math.pi / 4)
    assert bearing[1, 0] == pytest.approx(math.pi)  # line of sight points from i to j
    assert rng[0, 1] == pytest.approx(1.0)
    assert rng[0, 2] == pytest.approx(2.0)
    assert rng[0, 3] == pytest.approx(3.0)
    assert rng[0, 4] == pytest.approx(math.sqrt(8))
    assert np.allclose(rng, rng.T)


def test_range_limit():
    s, _, _ = sensing_matrix(X, Y, H, ALL, 2.5, None)
    assert _seen(s, 0) == {1, 2}
    s, _, _ = sensing_matrix(X, Y, H, ALL, 2.0, None)  # inclusive at the limit
    assert _seen(s, 0) == {1, 2}
    s, _, _ = sensing_matrix(X, Y, H, ALL, 0.5, None)
    assert not s.any()


def test_field_of_view_centred_on_heading():
    # +-1 rad around heading 0: only agent 1 (0 rad) and 4 (-pi/4)
    s, _, _ = sensing_matrix(X, Y, H, ALL, None, 2.0)
    assert _seen(s, 0) == {1, 4}
    # turn agent 0 to face +y: sees agent 2 only
    h = H.copy()
    h[0] = math.pi / 2
    s, _, _ = sensing_matrix(X, Y, h, ALL, None, 2.0)
    assert _seen(s, 0) == {2}
    # facing -x (heading pi): agent 3 at bearing pi, across the wrap
    h[0] = -math.pi + 0.1
    s, _, _ = sensing_matrix(X, Y, h, ALL, None, 1.0)
    assert _seen(s, 0) == {3}


def test_full_fov_is_all_round():
    s_full, _, _ = sensing_matrix(X, Y, H, ALL, None, 2 * math.pi)
    s_none, _, _ = sensing_matrix(X, Y, H, ALL, None, None)
    assert np.array_equal(s_full, s_none)


def test_range_and_fov_combine():
    s, _, _ = sensing_matrix(X, Y, H, ALL, 2.5, 2.0)
    assert _seen(s, 0) == {1}  # 4 is in the fov but out of range, 2 in range but out of fov


def test_absent_agents_neither_sense_nor_are_sensed():
    present = ALL.copy()
    present[1] = False
    s, _, _ = sensing_matrix(X, Y, H, present, None, None)
    assert not s[:, 1].any() and not s[1].any()
    assert _seen(s, 0) == {2, 3, 4}


def test_frames_content():
    is_leader = np.array([True, False, False, False, False])
    frames = build_frames(7, 0.35, IDS, X, Y, H, ALL, [0, 1], is_leader, (5.0, -1.0), 2.5, None)
    assert set(frames) == {10, 11}
    f0, f1 = frames[10], frames[11]
    assert (f0.tick, f0.time, f0.agent, f0.heading) == (7, 0.35, 10, 0.0)
    assert f0.target == (5.0, -1.0)  # target minus own position
    assert f1.target is None  # followers never get the target
    assert [c.id for c in f0.contacts] == [11, 12]  # sorted by id, range-limited
    c = f0.contacts[1]
    assert c.bearing == pytest.approx(math.pi / 2) and c.range == pytest.approx(2.0)
    assert c.heading == H[2]
    assert [c.id for c in f1.contacts] == [10, 12, 14]
    assert f1.heading == 0.5


def test_frame_of_leader_not_at_origin():
    is_leader = np.array([False, True, False, False, False])
    frames = build_frames(0, 0.0, IDS, X, Y, H, ALL, [1], is_leader, (0.0, 0.0))
    assert frames[11].target == (-1.0, 0.0)


# -- selection --------------------------------------------------------------------------


def C(i, r):
    return Contact(i, 0.1 * i, 0.0, r)


def test_nearest_picks_smallest_range():
    cs = (C(5, 3.0), C(2, 1.5), C(9, 2.0))
    assert nearest(cs).id == 2
    assert nearest(()) is None


def test_nearest_tie_goes_to_lowest_id():
    cs = (C(7, 2.0), C(3, 2.0), C(5, 2.0), C(9, 4.0))
    assert nearest(cs).id == 3
    ch = select(cs, mode="nearest", pinned=None, current=None)
    assert ch.out == 3 and ch.contact == C(3, 2.0) and not ch.fallback


def test_nearest_mode_ignores_pinned():
    cs = (C(1, 5.0), C(2, 1.0))
    ch = select(cs, mode="nearest", pinned=1, current=None)
    assert ch.out == 2 and not ch.fallback


def test_fixed_keeps_pinned_even_when_farther():
    cs = (C(1, 50.0), C(2, 1.0))
    ch = select(cs, mode="fixed", pinned=1, current=2)
    assert ch.out == 1 and ch.contact.range == 50.0 and not ch.fallback


def test_fixed_falls_back_to_nearest_when_pinned_not_sensed():
    cs = (C(4, 3.0), C(2, 1.0))
    ch = select(cs, mode="fixed", pinned=1, current=1)
    assert ch.out == 2 and ch.fallback


def test_nobody_sensed():
    ch = select((), mode="fixed", pinned=1, current=1)
    assert ch.out is None and ch.contact is None and ch.fallback
    ch = select((), mode="nearest", pinned=None, current=3, hysteresis=0.5)
    assert ch.out is None and not ch.fallback


@pytest.mark.parametrize("other_range, expected", [(9.5, 1), (9.01, 1), (8.9, 2), (5.0, 2)])
def test_hysteresis_keeps_current_unless_much_closer(other_range, expected):
    # current (id 1) at 10 m, h = 0.1: switch only if the other is closer than 9 m
    cs = (C(1, 10.0), C(2, other_range))
    ch = select(cs, mode="nearest", pinned=None, current=1, hysteresis=0.1)
    assert ch.out == expected
    assert ch.contact.id == expected


def test_without_hysteresis_switches_immediately():
    cs = (C(1, 10.0), C(2, 9.99))
    assert select(cs, mode="nearest", pinned=None, current=1, hysteresis=0.0).out == 2


def test_hysteresis_current_lost_goes_to_nearest():
    cs = (C(3, 10.0), C(2, 12.0))
    ch = select(cs, mode="nearest", pinned=None, current=1, hysteresis=0.5)
    assert ch.out == 3


def test_hysteresis_applies_to_fallback():
    cs = (C(3, 10.0), C(2, 9.5))
    ch = select(cs, mode="fixed", pinned=1, current=3, hysteresis=0.1)
    assert ch.out == 3 and ch.fallback
