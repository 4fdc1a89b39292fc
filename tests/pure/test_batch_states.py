"""The batch engine's sticky rule decides as the scalar machine does, state by state.

agents/batch.py `BatchBrains` under selection = "sticky" keeps the plain keeps over arrays
(agents/batch_sticky.py `BatchSticky.keep`: selection.keeps_out and feasible_kept on arrays) and
steps every other follower-tick through the follower's own StickyFollower. Here one
StickyFollower per follower, on its own, is fed the same contacts: random sensing
sequences (agents walking about, sensed within the range and field of view, or not, at
random; hop counts held for a while, then redrawn, -1 often), so that followers keep,
hold, coast, lose, shadow and search. Every tick, every follower: the same out-neighbour,
the same follow state and the same advertised hops as the scalar machine. The turn rates
are tests/pure/test_batch_decisions.py's: the scalar side is given the batch's last one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm.agents.batch import BatchBrains
from swarm.agents.sticky_follower import StickyFollower
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import Contact
from swarm.contracts.scenario import parse_scenario
from swarm.contracts.vocabulary import FollowState
from swarm.world.kinematics import wrap


class Frames:
    """One tick's frames of one member (B = 1) with a sensing matrix of its own: the protocol
    agents/batch.py reads (world/batch.py BatchFrames is the real one)."""

    def __init__(self, ids, x, y, heading, hops, sensed):
        self.ids, self.ids_sorted = ids[None, :], bool(np.all(np.diff(ids) > 0))
        self.x, self.y = x[None, :], y[None, :]
        self.heading, self.hops = heading[None, :], hops[None, :]
        self.sensed = sensed  # (N, N), i senses j
        self.rng = np.hypot(x[None, :] - x[:, None], y[None, :] - y[:, None])

    def _take(self, a, j):
        return a[np.arange(a.shape[0])[:, None], np.maximum(j, 0)]

    def target(self, b, i):
        return -self.x[b, i], -self.y[b, i]

    def offsets(self, j):
        return self._take(self.x, j) - self.x, self._take(self.y, j) - self.y

    def sensed_pairs(self, j):
        i = np.arange(j.shape[1])[None, :]
        return (j >= 0) & self.sensed[i, np.maximum(j, 0)]

    def bearing_pairs(self, j):
        dx, dy = self.offsets(j)
        return np.arctan2(dy, dx)

    def matrices(self, m):
        return self.sensed[None, ...].repeat(len(m), 0), self.rng[None, ...].repeat(len(m), 0)

    def contacts(self, b, i, sensed_row, rng_row) -> tuple[Contact, ...]:
        x, y, ids, heading, hops = self.x[b], self.y[b], self.ids[b], self.heading[b], self.hops[b]
        return tuple(
            Contact(
                int(ids[a]),
                float(np.arctan2(y[a] - y[i], x[a] - x[i])),
                float(heading[a]),
                float(rng_row[a]),
                int(hops[a]),
            )
            for a in np.flatnonzero(sensed_row).tolist()
        )


@st.composite
def runs(draw):
    """(scenario, per tick: (x, y, heading, hops, dropped)): a random sensing sequence."""
    n = draw(st.integers(2, 7))
    ids = draw(st.permutations(draw(st.lists(st.integers(1, 40), min_size=n, max_size=n, unique=True))))
    agents = [{"id": ids[0], "role": "leader", "speed": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0, "orbit_radius": 5.0}]
    agents += [{"id": a, "role": "follower", "speed": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0} for a in ids[1:]]
    sensing: dict = {"selection": "sticky"}
    if draw(st.booleans()):
        sensing["range"] = draw(st.floats(4.0, 20.0))
    if draw(st.booleans()):
        sensing["fov"] = draw(st.floats(1.0, 2 * math.pi))
    dt = draw(st.sampled_from([0.1, 0.5, 1.0]))
    ticks = draw(st.integers(3, 40))
    scenario = parse_scenario(
        {
            "run": {"dt": dt, "duration": dt * ticks},
            "target": {"x": 0.0, "y": 0.0},
            "gains": {"c1": 0.5, "c2": 0.5},
            "sensing": sensing,
            "agents": agents,
        }
    )
    seed = draw(st.integers(0, 2**32 - 1))
    drop = draw(st.sampled_from([0.0, 0.05, 0.3]))  # how often a pair in sight is not sensed
    redraw = draw(st.sampled_from([0.05, 0.2, 1.0]))  # how often the hop counts change
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)
    heading = rng.uniform(-math.pi, math.pi, n)
    hops = rng.integers(-1, n, n)
    steps = []
    for _ in range(ticks):
        x, y = x + rng.normal(0, 1.0, n), y + rng.normal(0, 1.0, n)
        heading = wrap(heading + rng.normal(0, 0.5, n))
        if rng.random() < redraw:
            hops = np.where(rng.random(n) < 0.3, -1, rng.integers(-1, n, n))
        hops[0] = 0
        steps.append((x.copy(), y.copy(), heading.copy(), hops.copy(), rng.random((n, n)) < drop))
    return scenario, steps


def sensing_matrix(x, y, heading, rng, sense_range, fov, dropped):
    """i senses j: in range, in its field of view, and not dropped."""
    n = len(x)
    s = ~np.eye(n, dtype=bool) & ~dropped
    if sense_range is not None:
        s &= rng <= sense_range
    if fov is not None:
        bearing = np.arctan2(y[None, :] - y[:, None], x[None, :] - x[:, None])
        s &= np.abs(wrap(bearing - heading[:, None])) <= 0.5 * fov
    return s


def decisions(scenario, steps, kept: list | None = None):
    """Per tick and follower ((out, state, hops) of the scalar machine, the same of the batch).
    kept: appended to, the number of followers each tick kept over arrays (BatchSticky.keep)."""
    n, dt = len(scenario.agents), scenario.run.dt
    confs = [BrainConf.from_scenario(scenario, a.id) for a in scenario.agents]
    ids = np.array([c.agent.id for c in confs])
    g, sens = confs[0].gains, confs[0].sensing
    batch = BatchBrains([[c.agent for c in confs]], [g], [sens], dt, n)
    scalar = {i: StickyFollower(c.agent, g, sens, dt, n) for i, c in enumerate(confs) if i > 0}
    last_u = np.zeros(n)
    if kept is not None:
        keep = batch.sticky.keep

        def counted(frames, follower):
            k = keep(frames, follower)
            kept.append(int(k.sum()))
            return k

        batch.sticky.keep = counted
    for tick, (x, y, heading, hops, dropped) in enumerate(steps):
        rng = np.hypot(x[None, :] - x[:, None], y[None, :] - y[:, None])
        sensed = sensing_matrix(x, y, heading, rng, sens.range, sens.fov, dropped)
        frames = Frames(ids, x, y, heading, hops, sensed)
        got = batch.decide(tick, frames)
        follow = batch.follow_states()[0]
        for i, f in scalar.items():
            contacts = frames.contacts(0, i, sensed[i], rng[i])
            ch, _ = f.step(contacts, float(heading[i]), tick * dt, float(last_u[i]), tick)
            c = ch.contact
            want_hops = c.hops + 1 if c is not None and ch.rooted and 0 <= c.hops < n else None
            out = int(got.out[0, i])
            yield (
                (tick, ids[i], ch.out, str(f.state), want_hops),
                (
                    tick,
                    ids[i],
                    None if out < 0 else int(ids[out]),
                    follow[i],
                    None if got.hops[0, i] < 0 else int(got.hops[0, i]),
                ),
            )
        last_u = got.u[0].copy()


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(runs())
def test_batch_sticky_decides_as_the_scalar_machine(case):
    scenario, steps = case
    for mine, batch in decisions(scenario, steps):
        assert batch == mine, (scenario.sensing, [a.id for a in scenario.agents])


@pytest.mark.slow
def test_the_random_sequences_reach_every_state():
    """The generator is not idle: over a fixed set of runs, the scalar machines pass through
    KEEP, HOLD, COAST, and LOST or SEARCH, and the batch keeps over arrays."""
    seen: set[str] = set()
    kept: list[int] = []
    for seed in range(40):
        n = 6
        rng = np.random.default_rng(seed)
        agents = [{"id": 1, "role": "leader", "speed": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0, "orbit_radius": 5.0}]
        agents += [
            {"id": k, "role": "follower", "speed": 1.0, "x": 0.0, "y": 0.0, "heading": 0.0} for k in range(2, n + 1)
        ]
        scenario = parse_scenario(
            {
                "run": {"dt": 0.5, "duration": 15.0},
                "target": {"x": 0.0, "y": 0.0},
                "gains": {"c1": 0.5, "c2": 0.5},
                "sensing": {"selection": "sticky", "range": 12.0},
                "agents": agents,
            }
        )
        x, y, heading = rng.uniform(-8, 8, n), rng.uniform(-8, 8, n), rng.uniform(-3, 3, n)
        hops = rng.integers(-1, n, n)
        steps = []
        for _ in range(30):
            x, y = x + rng.normal(0, 1.0, n), y + rng.normal(0, 1.0, n)
            if rng.random() < 0.2:
                hops = np.where(rng.random(n) < 0.3, -1, rng.integers(-1, n, n))
            hops[0] = 0
            steps.append((x.copy(), y.copy(), heading.copy(), hops.copy(), rng.random((n, n)) < 0.05))
        for mine, batch in decisions(scenario, steps, kept):
            assert batch == mine
            seen.add(mine[3])
    assert sum(kept) > 0
    assert {str(FollowState.KEEP), str(FollowState.HOLD), str(FollowState.COAST)} <= seen, seen
    assert seen & {str(FollowState.LOST), str(FollowState.SEARCH)}, seen
