"""The safety filter (world/safety.py) checked independently of its solver.

The barriers and their time derivatives are written again here, from the definitions
(docs/design/safety.md), with numpy: the derivative both in closed form and by a central
difference along the unicycle's flow, so that neither the filter's rows nor its solver
are trusted. Over 10,000 random configurations of 2-10 unicycles near each other and the
walls: every filtered command keeps every barrier's condition, and a law's command that is
already safe is passed through unchanged.
"""

from __future__ import annotations

import math
from functools import cache, lru_cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm.world.safety import Arena, Barriers, safe_commands

CONFIGS = 10_000
CANDIDATES = 400  # points drawn about a cluster's centre, of which n are kept
TOL = 1e-9  # m/s: a condition kept to this (the filter's own check)
FD_TOL = 1e-6  # m/s: the central difference's own error at FD_EPS on these scales
FD_EPS = 1e-5  # s


# -- the barriers, from their definitions ------------------------------------------------------
def lookahead_points(bar: Barriers, x, y, g):
    return x + bar.lookahead * np.cos(g), y + bar.lookahead * np.sin(g)


def _walls(bar: Barriers):
    """Each wall's start corner, unit direction, and the polygon's orientation (+1: ccw)."""
    return _walls_of(bar.arena.vertices)


@lru_cache(maxsize=64)
def _walls_of(vertices):  # (once per arena: the checks ask for it a few times per configuration)
    verts = np.array(vertices)
    edge = np.roll(verts, -1, axis=0) - verts
    length = np.hypot(edge[:, 0], edge[:, 1])
    return verts, edge / length[:, None], np.sign(polygon_area(verts))


@cache
def pairs(n: int):
    """The pairs i < j of n agents, in np.triu_indices' order."""
    return np.triu_indices(n, 1)


def barrier_values(bar: Barriers, x, y, g) -> np.ndarray:
    """Every barrier: pairs (i < j) then (agent, wall) in agent-major order."""
    qx, qy = lookahead_points(bar, x, y, g)
    i, j = pairs(len(x))
    out = [np.hypot(qx[i] - qx[j], qy[i] - qy[j]) - (bar.radius + 2 * bar.lookahead)]
    if bar.arena is not None:
        start, unit, orient = _walls(bar)
        # signed distance to each wall's line, positive on the polygon's inner side (a cross product)
        cross = unit[None, :, 0] * (qy[:, None] - start[None, :, 1]) - unit[None, :, 1] * (
            qx[:, None] - start[None, :, 0]
        )
        out.append((orient * cross - (0.5 * bar.radius + bar.lookahead)).reshape(-1))
    return np.concatenate(out)


def polygon_area(verts) -> float:
    x, y = verts[:, 0], verts[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def barrier_rates(bar: Barriers, x, y, g, v, u) -> np.ndarray:
    """d/dt of every barrier along x' = v cos g, y' = v sin g, g' = u (central difference)."""
    plus = barrier_values(bar, x + FD_EPS * v * np.cos(g), y + FD_EPS * v * np.sin(g), g + FD_EPS * u)
    minus = barrier_values(bar, x - FD_EPS * v * np.cos(g), y - FD_EPS * v * np.sin(g), g - FD_EPS * u)
    return (plus - minus) / (2 * FD_EPS)


def barrier_rates_exact(bar: Barriers, x, y, g, v, u) -> np.ndarray:
    """The same in closed form: dq/dt = v e + l u n for q = p + l e. u: the n turn rates, or
    rows of them (k, n): a row of rates each."""
    qx, qy = lookahead_points(bar, x, y, g)
    la = bar.lookahead
    u = np.asarray(u)
    dqx = v * np.cos(g) - la * u * np.sin(g)
    dqy = v * np.sin(g) + la * u * np.cos(g)
    i, j = pairs(len(x))
    dx, dy = qx[i] - qx[j], qy[i] - qy[j]
    out = [(dx * (dqx[..., i] - dqx[..., j]) + dy * (dqy[..., i] - dqy[..., j])) / np.hypot(dx, dy)]
    if bar.arena is not None:
        _, unit, orient = _walls(bar)
        walls = orient * (unit[:, 0] * dqy[..., :, None] - unit[:, 1] * dqx[..., :, None])
        out.append(walls.reshape(*u.shape[:-1], -1))
    return np.concatenate(out, axis=-1)


def kept(bar, x, y, g, v, u, tol=TOL) -> np.ndarray:
    """Per barrier: dh/dt >= -gamma h (closed form, to tol)."""
    return barrier_rates_exact(bar, x, y, g, v, u) >= -bar.gamma * barrier_values(bar, x, y, g) - tol


# -- random configurations -----------------------------------------------------------------------
def random_arena(rng) -> Arena:
    if rng.random() < 0.5:
        w, h = rng.uniform(3.0, 8.0, 2)
        x0, y0 = rng.uniform(-5.0, 5.0, 2)
        return Arena.rectangle(x0, y0, x0 + w, y0 + h)
    k = int(rng.integers(3, 9))
    r = rng.uniform(3.0, 6.0)
    angles = np.sort(rng.uniform(0, 2 * np.pi, k)) if rng.random() < 0.5 else np.linspace(0, 2 * np.pi, k, False)
    pts = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1) + rng.uniform(-3, 3, 2)
    try:
        return Arena.polygon(pts[::-1] if rng.random() < 0.5 else pts)  # either orientation
    except ValueError:  # random angles that give a sliver: a square instead
        return Arena.rectangle(-3.0, -3.0, 3.0, 3.0)


def random_config(rng, speed: bool):
    """2-10 unicycles near each other and the walls, every barrier >= 0 to start with: candidate
    points about a centre, each kept when it clears the walls and the points kept before."""
    n = int(rng.integers(2, 11))
    while True:
        arena = random_arena(rng)
        bar = Barriers(
            radius=float(rng.uniform(0.2, 0.8)),
            lookahead=float(rng.uniform(0.05, 0.3)),
            gamma=float(rng.uniform(0.5, 5.0)),
            arena=arena,
            speed=speed,
        )
        verts = np.array(arena.vertices)
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        cx, cy = rng.uniform(lo, hi).tolist()  # a cluster, somewhere (often by a wall)
        # CANDIDATES points about it, drawn at once, those whose lookahead points clear the walls
        # kept in order while they clear the points kept before: each kept one blocks the
        # candidates too near it (arrays: Python loops and numpy's per-call cost on a few floats
        # were most of this test's time)
        px, py = cx + rng.normal(0.0, 1.2, CANDIDATES), cy + rng.normal(0.0, 1.2, CANDIDATES)
        pg = rng.uniform(-np.pi, np.pi, CANDIDATES)
        qx, qy = px + bar.lookahead * np.cos(pg), py + bar.lookahead * np.sin(pg)
        depth = np.outer(qx, arena.normals[:, 0]) + np.outer(qy, arena.normals[:, 1]) - arena.offsets
        blocked = ~(depth >= bar.wall_margin).all(axis=1)
        chosen: list[int] = []
        while len(chosen) < n and not blocked.all():
            k = int(np.argmin(blocked))  # the first candidate left
            chosen.append(k)
            blocked[: k + 1] = True
            blocked |= np.hypot(qx - qx[k], qy - qy[k]) - bar.pair_distance < 0
        if len(chosen) == n:
            break
    x, y, g = px[chosen], py[chosen], pg[chosen]
    v = rng.uniform(0.1, 2.0, n)
    u_max = rng.uniform(0.5, 4.0, n)
    u_law = rng.uniform(-1.0, 1.0, n) * u_max
    return bar, x, y, g, v, u_law, u_max


def certified_infeasible(bar, x, y, g, v, u_max, agents, rng) -> bool:
    """No turn rates within the limits keep every condition of these agents' barriers (speeds
    fixed): one condition that fails at its best corner alone, or none of 2000 random
    commands and the box's corners keeps them all."""
    n = len(x)
    h = barrier_values(bar, x, y, g)
    # each barrier's rate is affine in u: its gradient by unit steps (the n + 1 rows at once)
    at = barrier_rates_exact(bar, x, y, g, v, np.vstack([np.zeros(n), np.eye(n)]))
    base, grad = at[0], (at[1:] - at[0]).T
    best = base + np.abs(grad) @ u_max
    if (best < -bar.gamma * h - TOL).any():
        return True
    samples = rng.uniform(-1, 1, (2000, n)) * u_max
    corners = np.sign(rng.uniform(-1, 1, (200, n))) * u_max
    rates = base + np.vstack([samples, corners]) @ grad.T
    return not (rates >= -bar.gamma * h - TOL).all(axis=1).any()


@pytest.mark.slow  # 10,000 configurations: about 10 s of CPU each way
@pytest.mark.parametrize("speed", [True, False], ids=["speed-may-change", "turn-only"])
def test_filtered_commands_keep_every_barrier_and_safe_commands_pass_unchanged(speed):
    rng = np.random.default_rng(34 + speed)
    passed = solved = infeasible = 0
    for _ in range(CONFIGS // 2):
        bar, x, y, g, v, u_law, u_max = random_config(rng, speed)
        n = len(x)
        f = safe_commands(bar, x, y, g, v, u_law, u_max, np.ones(n, dtype=bool))
        # limits
        assert np.all(np.abs(f.u) <= u_max + 1e-12)
        assert np.all(f.v >= -1e-12) and np.all(f.v <= v + 1e-12)
        if not speed:
            assert np.array_equal(f.v, v)
        law_safe = kept(bar, x, y, g, v, u_law, tol=-1e-7)  # safe with a margin: no doubt about it
        if law_safe.all():
            passed += 1
            assert np.allclose(f.u, u_law, rtol=0, atol=1e-9) and np.allclose(f.v, v, rtol=0, atol=1e-9)
            assert not f.changed.any() and f.solves == 0
            continue
        if f.infeasible.any():
            infeasible += 1
            assert not speed, "with speeds that may change, stopping is always safe from a safe start"
            assert certified_infeasible(bar, x, y, g, v, u_max, f.infeasible, rng)
            continue
        solved += 1
        assert kept(bar, x, y, g, f.v, f.u).all(), "a filtered command breaks a barrier's condition"
        rates = barrier_rates(bar, x, y, g, f.v, f.u)  # the derivation checked too: by the flow itself
        assert (rates >= -bar.gamma * barrier_values(bar, x, y, g) - FD_TOL).all()
        assert f.changed.any()
    assert passed + solved + infeasible == CONFIGS // 2
    print(f"[safety] speed={speed}: {passed} passed unchanged, {solved} solved, {infeasible} infeasible")
    # the configurations exercise every branch: at constant speed, clusters this close often
    # have no safe turn rate at all (each such case certified above)
    assert passed > 200 and solved > 300
    assert infeasible == 0 if speed else infeasible > 0


def test_the_filter_changes_as_little_as_it_can():
    """Two agents closing on a wall-free plane: the filtered command keeps the conditions and
    no random command that keeps them is closer to the law's (the QP's optimality, checked
    by sampling)."""
    rng = np.random.default_rng(7)
    bar = Barriers(radius=0.5, lookahead=0.2, gamma=1.0)
    for _ in range(50):
        x, y = np.array([0.0, 1.5]), np.array([0.0, rng.uniform(-0.3, 0.3)])
        g = np.array([rng.uniform(-0.5, 0.5), np.pi + rng.uniform(-0.5, 0.5)])
        v, u_max = np.array([1.0, 1.0]), np.array([3.0, 3.0])
        u_law = rng.uniform(-1, 1, 2)
        f = safe_commands(bar, x, y, g, v, u_law, u_max, np.ones(2, dtype=bool))
        if f.infeasible.any():
            continue
        cost = np.sum((f.u - u_law) ** 2)
        for u in rng.uniform(-3, 3, (3000, 2)):
            if kept(bar, x, y, g, v, u).all():
                assert np.sum((u - u_law) ** 2) >= cost - 1e-9


def test_head_on_at_constant_speed_is_infeasible_and_recorded_and_stops_when_speed_may_change():
    """Head on, the lookahead points' line is along both headings: no turn rate changes the
    distance's rate, so no turn rate is safe; with speeds that may change, both stop."""
    x, y, g = np.array([-0.75, 0.75]), np.zeros(2), np.array([0.0, np.pi])
    v, u_max, u_law = np.ones(2), np.full(2, 2.0), np.zeros(2)
    turn_only = Barriers(radius=1.0, lookahead=0.1, gamma=1.0)
    f = safe_commands(turn_only, x, y, g, v, u_law, u_max, np.ones(2, dtype=bool))
    assert f.infeasible.all() and f.changed.all()
    assert np.array_equal(f.v, v)  # the paper's agents never change speed
    assert np.all(np.abs(f.u) <= u_max)
    slow = Barriers(radius=1.0, lookahead=0.1, gamma=1.0, speed=True)
    f = safe_commands(slow, x, y, g, v, u_law, u_max, np.ones(2, dtype=bool))
    assert not f.infeasible.any() and f.changed.all()
    assert np.all(f.v < v) and kept(slow, x, y, g, f.v, f.u).all()
    inside = Barriers(radius=2.0, lookahead=0.1, gamma=1.0, speed=True)  # already too close: stop
    f = safe_commands(inside, x, y, g, v, u_law, u_max, np.ones(2, dtype=bool))
    assert f.infeasible.all() and np.array_equal(f.v, [0.0, 0.0]) and np.array_equal(f.u, [0.0, 0.0])


def test_agents_not_present_are_ignored_and_coasting_ones_are_obstacles():
    x, y, g = np.array([0.0, 3.0, 50.0]), np.zeros(3), np.array([0.3, np.pi, 0.0])
    v, u_max = np.ones(3), np.full(3, 2.0)
    u_law = np.array([0.0, 0.0, np.nan])  # agent 2 is gone: NaN, as WorldCore.applied gives
    bar = Barriers(radius=0.5, lookahead=0.2, gamma=1.1)
    present = np.array([True, True, False])
    controlled = np.array([True, False, False])  # agent 1 coasts: an obstacle
    f = safe_commands(bar, x, y, g, v, u_law, u_max, present, controlled=controlled)
    assert f.u[1] == 0.0 and not f.changed[1]  # coasting: keeps u = 0, the other one turns
    assert f.changed[0] and not f.infeasible.any() and math.isnan(f.u[2]) and not f.changed[2]
    assert kept(bar, x[:2], y[:2], g[:2], v[:2], f.u[:2]).all()


def test_arena_polygons():
    square = Arena.polygon([(0, 0), (0, 2), (2, 2), (2, 0)])  # clockwise: turned round
    assert square.inside(1.0, 1.0) and not square.inside(3.0, 1.0)
    assert np.allclose(np.sort(square.depth(1.0, 0.5)), [0.5, 1.0, 1.0, 1.5])
    assert Arena.rectangle(0, 0, 2, 2).inside(np.array([0.0, 2.0, 2.1]), np.array([0.0, 2.0, 1.0])).tolist() == [
        True,
        True,
        False,
    ]
    with pytest.raises(ValueError, match="not convex"):
        Arena.polygon([(0, 0), (2, 0), (1, 0.5), (2, 2), (0, 2)])
    with pytest.raises(ValueError, match="3 corners"):
        Arena.polygon([(0, 0), (1, 1)])
    with pytest.raises(ValueError, match="not convex"):
        Arena.polygon([(0, 0), (1, 0), (2, 0), (1, 1)])  # collinear corners


def test_a_star_that_crosses_itself_is_no_arena():
    """A pentagram turns the same way at every corner, as a convex polygon does, but goes round
    twice: its 'walls' cross, so it is refused by the world and by the scenario's [safety] table."""
    from pydantic import ValidationError

    from swarm.contracts.scenario_tables import SafetySpec

    star = [(math.cos(a), math.sin(a)) for a in (math.pi / 2 + 4 * math.pi * k / 5 for k in range(5))]
    pentagon = [(math.cos(a), math.sin(a)) for a in (math.pi / 2 + 2 * math.pi * k / 5 for k in range(5))]
    with pytest.raises(ValueError, match="crosses itself"):
        Arena.polygon(star)
    with pytest.raises(ValidationError, match="crosses itself"):
        SafetySpec(radius=0.1, arena=[list(p) for p in star])
    assert Arena.polygon(pentagon).inside(0.0, 0.0)
    assert Arena.polygon(pentagon[::-1]).inside(0.0, 0.0)
    assert SafetySpec(radius=0.1, arena=[list(p) for p in pentagon]).inside(0.0, 0.0)


def test_a_wall_turns_an_agent_heading_out():
    """An agent heading straight at a wall of a triangle, near it: its command is changed
    to turn away, within its limit, and the wall's condition holds."""
    tri = Arena.polygon([(0, 0), (10, 0), (5, 8)])
    bar = Barriers(radius=0.4, lookahead=0.3, gamma=0.5, arena=tri)
    x, y, g = np.array([5.0]), np.array([2.0]), np.array([-np.pi / 2 + 0.6])
    f = safe_commands(bar, x, y, g, np.array([1.0]), np.array([0.0]), np.array([3.0]), np.ones(1, dtype=bool))
    assert f.changed[0] and not f.infeasible[0] and 0 < f.u[0] <= 3.0
    assert f.reasons(0) == [("wall", 0)]
    assert kept(bar, x, y, g, np.array([1.0]), f.u).all()


@pytest.mark.slow  # 200 examples: 0.6 s
@settings(max_examples=200, deadline=None)
@given(
    dist=st.floats(3.0, 20.0),
    bearing=st.floats(-np.pi, np.pi),
    g0=st.floats(-np.pi, np.pi),
    g1=st.floats(-np.pi, np.pi),
    u0=st.floats(-1.0, 1.0),
    u1=st.floats(-1.0, 1.0),
)
def test_far_apart_agents_pass_unchanged_to_the_bit(dist, bearing, g0, g1, u0, u1):
    """Agents whose barriers cannot shrink fast enough to matter keep the law's commands exactly."""
    bar = Barriers(radius=0.5, lookahead=0.1, gamma=1.0)
    x, y = np.array([0.0, dist * math.cos(bearing)]), np.array([0.0, dist * math.sin(bearing)])
    u_law = np.array([u0, u1])
    f = safe_commands(bar, x, y, np.array([g0, g1]), np.ones(2), u_law, np.full(2, 1.0), np.ones(2, dtype=bool))
    assert np.array_equal(f.u, u_law) and not f.changed.any()


@pytest.mark.slow  # 200 examples: 0.6 s
@settings(max_examples=200, deadline=None)
@given(
    k=st.integers(3, 8),
    r=st.floats(1.0, 50.0),
    turn=st.floats(0.0, 2 * math.pi),
    cw=st.booleans(),
    px=st.floats(-60.0, 60.0),
    py=st.floats(-60.0, 60.0),
)
def test_the_scenario_and_the_world_agree_on_inside(k, r, turn, cw, px, py):
    """The start check (swarm/contracts/scenario_tables.py) and the exits the world counts
    (world/safety.py) say the same of a point, away from the walls."""
    from swarm.contracts.scenario_tables import SafetySpec

    angles = turn + np.linspace(0, 2 * np.pi, k, endpoint=False)
    pts = [[float(r * math.cos(a)), float(r * math.sin(a))] for a in (angles[::-1] if cw else angles)]
    spec = SafetySpec(radius=1.0, arena=pts)
    arena = Arena.polygon(spec.corners)
    if np.min(np.abs(arena.depth(px, py))) < 1e-9:
        return  # on a wall: either answer
    assert spec.inside(px, py) == bool(arena.inside(px, py))


@pytest.mark.parametrize("corners", [[(0, 0), (5, 8), (10, 0)], [(5, 8), (0, 0), (10, 0)], [(0, 0), (10, 0), (5, 8)]])
def test_a_wall_is_named_by_the_corners_as_given(corners):
    """The "wall k" of a "safety" event's `by` (docs/reference/protocol.md) runs from corner k
    to k + 1 of the arena as written, clockwise too (it named the walls of the polygon turned
    round: the wall from (0, 0) to (5, 8) of a clockwise triangle was "wall 1")."""
    tri = Arena.polygon(corners)
    assert tri.vertices == tuple((float(x), float(y)) for x, y in corners)
    bar = Barriers(radius=0.4, lookahead=0.3, gamma=0.5, arena=tri)
    # near the wall through (0, 0) and (5, 8), heading at it
    x, y, g = np.array([3.2]), np.array([3.0]), np.array([math.atan2(5, -8) + 0.6])
    f = safe_commands(bar, x, y, g, np.array([0.5]), np.array([0.0]), np.array([3.0]), np.ones(1, dtype=bool))
    assert f.changed[0] and not f.infeasible[0]
    k = next(k for k in range(3) if {corners[k], corners[(k + 1) % 3]} == {(0, 0), (5, 8)})
    assert f.reasons(0) == [("wall", k)]
    assert kept(bar, x, y, g, np.array([0.5]), f.u).all()
    # the walls themselves do not depend on the order
    assert sorted(tri.depth(3.2, 3.0).tolist()) == sorted(Arena.polygon(corners[::-1]).depth(3.2, 3.0).tolist())


def test_an_agent_without_a_finite_pose_is_left_out_and_the_others_are_still_filtered():
    """A NaN in one present agent's pose (or speed, or command) made every condition with it
    unknown: never broken, always kept in, joining every agent near it into one group whose QP
    could not be solved, so that the agents next to it got no filtering at all. It is left
    out instead, as an agent not in the world; the least distance is measured without it."""
    from swarm.contracts.scenario_tables import SafetySpec
    from swarm.world.safety_watch import SafetyWatch

    bar = Barriers(radius=0.5, lookahead=0.2, gamma=1.0)
    # agents 0 and 1 close in (a turn keeps them apart); agent 2 near both
    x, y = np.array([0.0, 3.0, 1.5]), np.array([0.0, 0.6, 1.2])
    g, v, u_max = np.array([0.0, np.pi, 0.0]), np.ones(3), np.full(3, 3.0)
    u_law = np.zeros(3)
    good = safe_commands(bar, x, y, g, v, u_law, u_max, np.array([True, True, False]))
    assert good.changed[:2].any() and not good.infeasible.any()
    for bad in ("x", "g", "v", "u"):
        args = {"x": x.copy(), "g": g.copy(), "v": v.copy(), "u": u_law.copy()}
        args[bad][2] = np.nan if bad != "v" else np.inf
        f = safe_commands(bar, args["x"], y, args["g"], args["v"], args["u"], u_max, np.ones(3, dtype=bool))
        assert not f.infeasible.any(), bad
        np.testing.assert_array_equal(f.u[:2], good.u[:2])
        assert not f.changed[2] and (f.u[2] == args["u"][2] or bad == "u")
        assert kept(bar, x[:2], y[:2], g[:2], v[:2], f.u[:2]).all()
    watch = SafetyWatch(SafetySpec(radius=1.0, arena=[-5, -5, 5, 5]), [1, 2, 3])
    watch.measure(
        0, np.array([0.0, 0.5, np.nan]), np.zeros(3), np.ones(3, dtype=bool), np.ones(3, dtype=bool), u_law, u_max
    )
    fig = watch.figures()
    assert fig["min_distance"] == 0.5 and fig["min_distance_pair"] == [1, 2] and fig["collisions"] == 1
    assert fig["boundary_exits"] == 0


@pytest.mark.parametrize("field", ["radius", "lookahead", "gamma"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf, "1"])
def test_barriers_refuse_parameters_that_mean_nothing(field, value):
    """gamma <= 0 asks every barrier to grow (the filter would change almost every command),
    lookahead 0 gives the turn rate no hold on any barrier (and divides by zero with speed =
    true): a clear error naming the field, as the scenario's [safety] table gives."""
    good = {"radius": 0.5, "lookahead": 0.1, "gamma": 1.0}
    Barriers(**good)
    with pytest.raises(ValueError, match=f"Barriers.{field} must be a finite number > 0"):
        Barriers(**{**good, field: value})
