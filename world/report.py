"""The world's view of a live run, as `world/info` answers it (`swarm agents`, `graph`,
`watch`; docs/reference/protocol.md#info): per agent its pose, state, process, chosen
out-neighbour, root, hops, expected radius and errors. Pure: the world process passes in
what it holds.
"""

from __future__ import annotations

import math
import time

import numpy as np

from swarm.contracts.orbits import expected_radius, root_of
from swarm.contracts.wire import FOLLOW_STATES
from swarm.world.core import ACTIVE
from swarm.world.engine import Engine


def run_info(engine: Engine, books: dict, header: dict, sensing: bool = False) -> dict:
    """header: run, scenario, clock, paused, endpoint, pid, host, ticks, garbage, ignored."""
    c = engine.core
    s = c.scenario
    leaders = {a.id for a in s.agents if a.role == "leader"}
    live = set(c.active_ids())
    out = {int(i): (int(o) if o >= 0 else None) for i, o in zip(c.ids, engine.out)}
    now = time.monotonic()
    agents = {}
    for a in s.agents:
        k = c.index[a.id]
        b = books[a.id]
        root, hops = root_of(a.id, out, leaders & live) if a.id in live else (None, None)
        dist = math.hypot(c.x[k] - c.target[0], c.y[k] - c.target[1])
        expected: float | None = None
        err: float | None = None
        if root is not None:
            L = s.agent(root)
            assert L.orbit_radius is not None  # a root is a leader, which has one (swarm/contracts/scenario_tables.py)
            expected = expected_radius(a.speed, L.speed, L.orbit_radius)
            err = abs(dist - expected)
        agents[str(a.id)] = {
            "id": a.id,
            "role": a.role,
            "state": c.state[k],
            "alive": c.state[k] == ACTIVE,
            "pid": b.pid,
            "host": b.host,
            "x": float(c.x[k]),
            "y": float(c.y[k]),
            "heading": float(c.heading[k]),
            "speed": a.speed,
            "u": float(c.u[k]),
            "out": out[a.id],
            "follow": str(FOLLOW_STATES[engine.follow[k]]),  # of its last latched command (none when not active)
            "root": root,
            "hops": hops,
            "distance": dist,
            "expected_radius": expected,
            "radial_error": err,
            "relative_error": None if err is None or expected is None else err / expected,
            "orbit_radius": a.orbit_radius,
            "last_command_age": (now - b.last_cmd_wall) if b.last_cmd_wall else None,
            "missed": b.missed,
            "commands": b.commands,
            "joins": b.joins,
            "drops": b.drops,
            "garbage": b.garbage,
            "rogue_commands": b.rogue,
        }
    info = {
        **header,
        "tick": c.tick,
        "time": c.time,
        "dt": c.dt,
        "target": [c.target[0], c.target[1]],
        "agents": agents,
    }
    if engine.safety is not None:  # the [safety] filter's figures so far (docs/reference/outputs.md#safety)
        info["safety"] = engine.safety.figures()
    if sensing:
        sensed, _, _ = c.sensing()
        info["sensing"] = [[int(c.ids[i]), int(c.ids[j])] for i, j in zip(*np.nonzero(sensed))]
    return info
