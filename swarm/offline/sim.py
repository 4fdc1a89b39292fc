"""`swarm sim`: the in-process shell around the engine.

Runs a scenario in one process: `swarm.world.engine.Engine` does the tick (faults due ->
frames -> commands -> events -> record -> integrate) exactly as it does inside the world
process, and each agent's `AgentBrain` answers its frame in scenario order. It is the
reference that `swarm up --clock lockstep` equals, and a fast tool for studies.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from swarm.agents.brain import AgentBrain
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.world.engine import Engine
from swarm.world.recording import RunResult


def run_sim(
    scenario: Scenario,
    duration: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    recording: Path | None = None,
) -> RunResult:
    """Run `scenario` for `duration` simulated seconds (default: the scenario's), streaming
    the recording to `recording` (a recording.mcap) if given, else keeping it in memory.

    Process faults as the world process carries them out: kill drops the agent; restart
    brings it back with a fresh brain; freeze drops it (in `swarm up` when its link lease
    runs out, with the clock held) and keeps its brain; thaw brings it back with that brain.
    A law that raises is what an agent process dying of it is under `swarm up`: a "crash"
    event (with its `cause`), the agent dropped, the run goes on (and is not converged).
    """
    dt = scenario.run.dt
    ticks = int(round((duration if duration is not None else scenario.run.duration) / dt))
    # the ticks also kept in memory: the caller gets the arrays (no reading the recording back)
    engine = Engine(scenario, ticks, recording=recording, keep=True)

    def brain(aid: int) -> AgentBrain:
        return AgentBrain(BrainConf.from_scenario(scenario, aid))

    brains = {a.id: brain(a.id) for a in scenario.agents}
    frozen: set[int] = set()  # frozen processes: dropped, brain kept for the thaw
    every = max(1, ticks // 200)
    for k in range(ticks):
        for _, f in engine.due():
            aid = f.agent
            if f.kind == "kill":
                frozen.discard(aid)
                engine.drop(aid, "fault: kill")
            elif f.kind == "restart":
                frozen.discard(aid)
                if engine.join(aid, "fault: restart", rejoin=True):
                    brains[aid] = brain(aid)
            elif f.kind == "freeze":
                if engine.drop(aid, "fault: freeze") is not None:
                    frozen.add(aid)
            elif f.kind == "thaw" and aid in frozen:
                frozen.discard(aid)
                engine.join(aid, "fault: thaw", rejoin=True)
        for aid, frame in engine.frames().items():
            try:
                d = brains[aid].decide(frame)
            except Exception as e:  # its law raised: as `swarm up` reports an agent process that died of it
                cause = f"{type(e).__name__}: {e}"
                engine.event(EventKind.CRASH, aid, f"its law raised: {cause}", cause=cause)
                engine.drop(aid, "its law raised (crash)")
                frozen.discard(aid)
                continue
            engine.command(aid, k, d.u, d.out, d.hops, d.follow)
        engine.end_tick()
        if progress is not None and (k % every == 0):
            progress(k, ticks)
    engine.close()
    if progress is not None:
        progress(ticks, ticks)
    return engine.result(
        {
            "engine": "sim",
            "rejected_commands": engine.core.rejected,
            "lost_frames": engine.fault_plan.lost_sense,
            "lost_commands": engine.fault_plan.lost_cmd,
        },
        {str(aid): b.figures() for aid, b in brains.items()},
    )
