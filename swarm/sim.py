"""`swarm sim`: the in-process engine.

Runs a scenario in one process with the same pieces the distributed runtime uses
(WorldCore for physics and sensors, AgentBrain for each agent's decisions), in the
same order: frames of tick k -> every agent decides -> the world steps. It is the
reference that `swarm up --clock lockstep` must match, and a fast tool for studies.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from agents.brain import AgentBrain
from swarm.recording import Recorder, RunResult
from swarm.scenario import Scenario
from world.core import WorldCore


def run_sim(scenario: Scenario, duration: float | None = None,
            progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run `scenario` for `duration` simulated seconds (default: the scenario's)."""
    dt = scenario.run.dt
    ticks = int(round((duration if duration is not None else scenario.run.duration) / dt))
    world = WorldCore(scenario)
    n = len(scenario.agents)
    brains = {a.id: AgentBrain(a, scenario.gains, scenario.sensing, dt, n) for a in scenario.agents}
    rec = Recorder(scenario, ticks)
    events: list[dict] = []
    out = np.full(len(scenario.agents), -1, dtype=np.int64)
    every = max(1, ticks // 200)
    for k in range(ticks):
        for aid, frame in world.frames().items():
            d = brains[aid].decide(frame)
            world.set_command(aid, d.u, d.hops)
            col = world.index[aid]
            new = -1 if d.out is None else d.out
            if new != out[col] and not brains[aid].is_leader:
                events.append({"tick": k, "time": world.time, "agent": aid, "kind": "switch",
                               "from": None if out[col] < 0 else int(out[col]),
                               "to": d.out, "reason": "pinned out-neighbour not sensed"
                               if d.fallback else "nearest sensed agent"})
            out[col] = new
        rec.record(k, world.time, world.x, world.y, world.heading, world.applied(), out,
                   world.alive_mask())
        world.step()
        if progress is not None and (k % every == 0):
            progress(k, ticks)
    rec.record(ticks, world.time, world.x, world.y, world.heading,
               np.full(len(out), np.nan), out, world.alive_mask())
    if progress is not None:
        progress(ticks, ticks)
    return RunResult(scenario, rec, events, {"engine": "sim", "rejected_commands": world.rejected})
