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
from world.core import ACTIVE, WorldCore
from world.faults import FaultPlan, fault_event


def run_sim(scenario: Scenario, duration: float | None = None,
            progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Run `scenario` for `duration` simulated seconds (default: the scenario's).

    Scripted faults: network faults exactly as the world process applies them; process
    faults modelled in-process (kill: the agent drops; restart: it rejoins with a fresh
    brain; freeze: it stops deciding and its last command is held; thaw: it decides again).
    """
    dt = scenario.run.dt
    ticks = int(round((duration if duration is not None else scenario.run.duration) / dt))
    world = WorldCore(scenario)
    n = len(scenario.agents)

    def brain(a):
        return AgentBrain(a, scenario.gains, scenario.sensing, dt, n)

    brains = {a.id: brain(a) for a in scenario.agents}
    plan = FaultPlan(scenario.faults, dt, scenario.run.seed)
    network = plan.affects_network()  # frames go through the fault plan (delay keeps history)
    frozen: set[int] = set()
    rec = Recorder(scenario, ticks)
    events: list[dict] = []
    out = np.full(n, -1, dtype=np.int64)
    every = max(1, ticks // 200)

    def event(kind, aid, reason, **more):
        events.append({"tick": world.tick, "time": world.time, "agent": aid, "kind": kind,
                       "reason": reason, **more})

    for k in range(ticks):
        for i, f in plan.due(k):
            event("fault", f.agent, f"scripted {f.kind}", fault=fault_event(i, f))
            if f.kind == "kill" and world.state[world.index[f.agent]] == ACTIVE:
                world.drop(f.agent)
                out[world.index[f.agent]] = -1
                event("drop", f.agent, "fault: kill")
            elif f.kind == "restart" and world.state[world.index[f.agent]] != ACTIVE:
                world.join(f.agent)
                brains[f.agent] = brain(scenario.agent(f.agent))
                frozen.discard(f.agent)
                event("rejoin", f.agent, "fault: restart")
            elif f.kind == "freeze":
                frozen.add(f.agent)
            elif f.kind == "thaw":
                frozen.discard(f.agent)
        missed = 0
        hops_sent = world.hops.copy()
        for aid, frame in world.frames().items():
            if aid in frozen:
                missed += 1
                continue
            frame = plan.sense(frame) if network else frame
            if frame is None:
                missed += 1
                continue
            d = brains[aid].decide(frame)
            if network and plan.command_lost(k, aid):
                missed += 1
                continue
            world.set_command(aid, d.u, d.hops)
            col = world.index[aid]
            new = -1 if d.out is None else d.out
            if new != out[col] and not brains[aid].is_leader:
                old = None if out[col] < 0 else int(out[col])
                event("switch", aid, world.switch_reason(aid, old, d.out, hops_sent),
                      **{"from": old, "to": d.out})
            out[col] = new
        rec.record(k, world.time, world.x, world.y, world.heading, world.applied(), out,
                   world.alive_mask(), missed)
        world.step()
        if progress is not None and (k % every == 0):
            progress(k, ticks)
    rec.record(ticks, world.time, world.x, world.y, world.heading,
               np.full(len(out), np.nan), out, world.alive_mask())
    if progress is not None:
        progress(ticks, ticks)
    return RunResult(scenario, rec, events, {"engine": "sim", "rejected_commands": world.rejected,
                                             "lost_frames": plan.lost_sense, "lost_commands": plan.lost_cmd})
