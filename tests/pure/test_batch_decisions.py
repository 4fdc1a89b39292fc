"""The batch brains decide as the per-agent brains do, decision by decision, to the bit.

agents/batch.py `BatchBrains` (B = 1 member) and one agents/brain.py `AgentBrain` per agent
are fed the same frames of random small swarms (positions, headings, speeds, gains,
turn-rate limits, sensing range and field of view, every selection rule, ids in any order,
leaders on their CC paths or on their orbits), tick after tick, with the hop counts of the
frames now and then replaced by arbitrary ones (so that the rooted and sticky rules hold,
coast, shadow and search). Every tick, every agent: the same turn rate u (exactly), the
same out-neighbour, the same phase and the same advertised hops. What the two forms do
not share (agents/ops.py says what they do) is checked here; tests/pure/test_batch.py checks
whole runs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarm.agents.batch import BatchBrains
from swarm.agents.brain import AgentBrain
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.scenario import parse_scenario
from swarm.world.batch import BatchWorld
from swarm.world.sensing import build_frames

RULES = ("sticky", "nearest", "rooted", "fixed")


@st.composite
def swarms(draw):
    """(scenario, ticks, hop counts per tick or None): a random small swarm to step."""
    n = draw(st.integers(2, 6))
    leaders = draw(st.integers(1, min(2, n - 1)))
    ids = draw(st.permutations(draw(st.lists(st.integers(1, 60), min_size=n, max_size=n, unique=True))))
    roles = draw(st.permutations(["leader"] * leaders + ["follower"] * (n - leaders)))
    rule = draw(st.sampled_from(RULES))
    coord = st.floats(-25.0, 25.0)
    tx, ty = draw(coord), draw(coord)
    agents = []
    for k, (aid, role) in enumerate(zip(ids, roles)):
        speed = draw(st.floats(0.3, 2.0))
        limit = draw(st.none() | st.floats(0.3, 3.0))
        a = {"id": aid, "role": role, "speed": speed, "heading": draw(st.floats(-math.pi, math.pi))}
        a["x"], a["y"] = draw(coord), draw(coord)
        if limit is not None:
            a["max_turn_rate"] = limit
        if role == "leader":
            radius = draw(st.floats(2.0, 15.0))
            if limit is not None:
                radius = max(radius, 1.01 * speed / limit)
            direction = draw(st.sampled_from(["ccw", "cw"]))
            a.update(orbit_radius=radius, direction=direction)
            if draw(st.booleans()):  # on its orbit already, heading along it
                t = draw(st.floats(-math.pi, math.pi))
                s = 1 if direction == "ccw" else -1
                a.update(x=tx + radius * math.cos(t), y=ty + radius * math.sin(t), heading=t + s * math.pi / 2)
        elif rule == "fixed":  # a leader or an agent earlier in the list: no follower-only cycle
            a["follow"] = draw(st.sampled_from([b for j, b in enumerate(ids) if j < k or roles[j] == "leader"]))
        agents.append(a)
    sensing: dict = {"selection": rule, "hysteresis": draw(st.sampled_from([0.0, 0.0, 0.1, 0.4]))}
    if draw(st.booleans()):
        sensing["range"] = draw(st.floats(5.0, 50.0))
    if draw(st.booleans()):
        sensing["fov"] = draw(st.floats(0.5, 2 * math.pi))
    dt = draw(st.sampled_from([0.05, 0.1, 0.5]))
    ticks = draw(st.integers(1, 14))
    scenario = parse_scenario(
        {
            "run": {"dt": dt, "duration": dt * ticks},
            "target": {"x": tx, "y": ty},
            "gains": {"c1": draw(st.floats(0.05, 2.0)), "c2": draw(st.floats(0.05, 2.0))},
            "sensing": sensing,
            "agents": agents,
        }
    )
    hops = st.none() | st.lists(st.integers(-1, n), min_size=n, max_size=n)
    return scenario, ticks, draw(st.lists(hops, min_size=ticks, max_size=ticks))


def step_both(scenario, ticks, hops_per_tick):
    """Step AgentBrains and BatchBrains side by side on one world; yield, per tick and agent,
    ((u, out, phase, hops) of AgentBrain, the same of BatchBrains)."""
    world = BatchWorld([scenario])
    n, dt = len(scenario.agents), scenario.run.dt
    confs = [BrainConf.from_scenario(scenario, a.id) for a in scenario.agents]
    batch = BatchBrains([[c.agent for c in confs]], [confs[0].gains], [confs[0].sensing], dt, n)
    brains = [AgentBrain(c) for c in confs]
    ids = [a.id for a in scenario.agents]
    target = np.array([scenario.target.x, scenario.target.y])
    sens = scenario.sensing
    for tick in range(ticks):
        if hops_per_tick[tick] is not None:  # arbitrary advertisements (both see them)
            world.hops = np.array([hops_per_tick[tick]], dtype=np.int64)
        frames = world.frames()
        mine = build_frames(
            tick,
            tick * dt,
            world.ids[0],
            world.x[0],
            world.y[0],
            world.heading[0],
            np.ones(n, dtype=bool),
            range(n),
            world.is_leader[0],
            target,
            sens.range,
            sens.fov,
            frames.hops[0],
        )
        got = batch.decide(tick, frames)
        phases, follow = batch.phases()[0], batch.follow_states()[0]
        for i, brain in enumerate(brains):
            d = brain.decide(mine[ids[i]])
            out = int(got.out[0, i])
            yield (
                (tick, ids[i], d.u, d.out, d.phase, d.hops, d.follow),
                (
                    tick,
                    ids[i],
                    float(got.u[0, i]),
                    None if out < 0 else ids[out],
                    phases[i],
                    _none(got.hops[0, i]),
                    follow[i],
                ),
            )
        world.latch(got.u, got.hops)
        world.step()


def _none(h) -> int | None:
    return None if h < 0 else int(h)


@pytest.mark.slow
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(swarms())
def test_batch_brains_decide_as_agent_brains(case):
    scenario, ticks, hops = case
    for mine, batch in step_both(scenario, ticks, hops):
        assert batch == mine, (scenario.sensing, scenario.agents)
