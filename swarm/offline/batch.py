"""The batch engine: many fault-free runs of the in-process engine stepped as arrays.

`run_batch` runs B scenarios (members) of N agents each as (B, N) arrays: the world's
physics and sensors from world/batch.py, every agent's brain from agents/batch.py,
in the order of world/engine.Engine's tick (frames -> commands -> switch events ->
record -> integrate). Each member's result is a swarm.world.recording.RunResult like
swarm.offline.sim.run_sim's, with the same trajectory (to the bit on this project's
machines; tests/pure/test_batch.py checks 1e-9 m), the same "switch" events with the same
reasons, and the same summary, "engine" excepted ("sim-batch").

A member with a [safety] table has its own `SafetyWatch` (world/safety_watch.py), called as
Engine.end_tick calls it (after the switch events, before the record and the step), so its
filtered turn rates, "safety" events and figures are sim's too.

What it runs: the built-in "bearing" law, every selection rule, sensing range and field
of view, turn-rate limits, leaders' CC paths and orbit hold. What it refuses (`refusal`
says why, and `run_batch` raises BatchRefused): scripted faults, follower or leader laws of
one's own (a law is Python per agent: `swarm sim` runs it). One batch needs one dt, one
tick count, one number of agents and one selection rule (`batch_key`); gains, sensing
range and field of view may differ per member.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from swarm.agents.batch import BatchBrains, vectorised
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.laws import GAINS, resolve_law
from swarm.contracts.scenario import Scenario
from swarm.contracts.vocabulary import EventKind
from swarm.world.batch import BatchWorld
from swarm.world.recording import RunResult, StreamRecorder, static_arrays
from swarm.world.safety_watch import SafetyWatch

ENGINE = "sim-batch"


class BatchRefused(ValueError):
    """A scenario the batch engine does not run; the message says why."""


def refusal(s: Scenario) -> str | None:
    """Why the batch engine cannot run `s` exactly as `swarm sim` does, or None."""
    if s.faults:
        return "it has scripted faults ([[faults]]): the batch engine has no fault plan"
    if s.law.follower != "bearing" or (s.gains.law != "bearing" and not vectorised(resolve_law(s.gains.law, GAINS))):
        name = s.gains.law if s.gains.law != "bearing" else s.law.follower
        return (
            f"its follower law is {name!r}: only the built-in 'bearing' law and `[gains] law`s declared "
            "vectorised are batched"
        )
    if s.law.leader != "cc":
        return f"its leader law is {s.law.leader!r}: only the built-in 'cc' law (CC path, then orbit hold) is batched"
    return None


def batch_key(s: Scenario, duration: float | None = None) -> tuple:
    """Scenarios with equal keys can share a batch: (dt, ticks, agents, selection)."""
    ticks = int(round((duration if duration is not None else s.run.duration) / s.run.dt))
    return s.run.dt, ticks, len(s.agents), s.sensing.selection


class MemberRecording:
    """One member's recorded arrays (views into the batch's), as RunResult reads them."""

    torn = False

    def __init__(self, scenario: Scenario, arrays: dict[str, np.ndarray]):
        self.scenario = scenario
        self._arrays = arrays
        self.rows = len(arrays["t"])

    def arrays(self) -> dict[str, np.ndarray]:
        return {**static_arrays(self.scenario), **self._arrays}


def run_batch(
    scenarios: list[Scenario],
    duration: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    recording: Path | None = None,
    lean: bool = False,
) -> list[RunResult]:
    """Run every scenario for `duration` simulated seconds (default: their own), one
    RunResult each, in order. recording: stream the one member's recording.mcap there
    (a batch of one); lean: keep only what summaries read (x, y, out; no headings or
    turn rates: NaN), for studies. Raises BatchRefused (with the reason) for a scenario
    the batch engine does not run, ValueError for scenarios that cannot share a batch."""
    for s in scenarios:
        why = refusal(s)
        if why is not None:
            raise BatchRefused(f"{s.name or 'scenario'}: {why}")
    keys = {batch_key(s, duration) for s in scenarios}
    if len(keys) != 1:
        raise ValueError(f"one batch needs one (dt, ticks, agents, selection), got {sorted(keys)}")
    if recording is not None and len(scenarios) != 1:
        raise ValueError("a streamed recording is for a batch of one")
    dt, ticks, n, mode = keys.pop()
    world = BatchWorld(scenarios)
    confs = [[BrainConf.from_scenario(s, a.id) for a in s.agents] for s in scenarios]  # as each agent's brain
    brains = BatchBrains(
        [[c.agent for c in row] for row in confs], [r[0].gains for r in confs], [r[0].sensing for r in confs], dt, n
    )
    B = len(scenarios)
    rec = None if recording is None else StreamRecorder(scenarios[0], ticks, recording)
    keep = ("x", "y", "out", "follow") if lean else ("x", "y", "heading", "u", "out", "follow")
    fills = {"out": (-1, np.int64), "follow": (0, np.int8)}
    hist = {} if rec is not None else {k: np.full((B, ticks + 1, n), *fills.get(k, (np.nan, float))) for k in keep}
    pinned = brains.pinned if mode == "fixed" else None
    events: list[list[dict]] = [[] for _ in range(B)]
    out = np.full((B, n), -1, dtype=np.int64)  # Engine.out, as columns
    follow = np.zeros((B, n), dtype=np.int8)  # Engine.follow
    alive = np.ones(n, dtype=bool)
    rows = np.arange(B)[:, None]
    every = max(1, ticks // 200)
    watches = {b: SafetyWatch(s.safety, s.ids) for b, s in enumerate(scenarios) if s.safety is not None}

    def safety(k: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Each member's safety filter, as Engine.end_tick runs it: the (B, N) turn rates (and
        speeds, None when no member's may change) to record and step."""
        if not watches:
            return world.u, None
        u, v = world.u.copy(), None
        for b, w in watches.items():
            ub, vb = w.command(
                world.x[b],
                world.y[b],
                world.heading[b],
                world.speed[b],
                world.u[b],
                world.limit[b],
                alive,
                alive,
                _sink(k, dt, world.ids[b], events[b], rec),
            )
            w.measure(k, world.x[b], world.y[b], alive, alive, ub, world.limit[b])
            u[b] = ub
            if vb is not None:
                v = world.speed.copy() if v is None else v
                v[b] = vb
        return u, v

    def record(k: int, u: np.ndarray) -> None:
        out_ids = np.where(out >= 0, world.ids[rows, np.maximum(out, 0)], -1)
        if rec is not None:
            rec.record(k, k * dt, world.x[0], world.y[0], world.heading[0], u[0], out_ids[0], alive, 0, follow[0])
            return
        per_tick = (("x", world.x), ("y", world.y), ("heading", world.heading), ("u", u), ("out", out_ids))
        for key, v in per_tick + (("follow", follow),):
            if key in hist:
                hist[key][:, k, :] = v

    for k in range(ticks):
        frames = world.frames()
        d = brains.decide(k, frames)
        ok = world.latch(d.u, d.hops)
        new = np.where(ok, d.out, out)  # a refused command changes nothing (Engine.command)
        follow = np.where(ok, d.follow, follow)
        changed = (new != out) & ~world.is_leader
        if changed.any():
            for b, ev in _switches(k, dt, world, frames, out, new, changed, pinned):
                events[b].append(ev)
                if rec is not None:
                    rec.event(ev)
        out = new
        u, v = safety(k)
        record(k, u)
        world.step(u, v)
        if progress is not None and k % every == 0:
            progress(k, ticks)
    nan = np.full((B, n), np.nan)
    for b, w in watches.items():
        w.measure(ticks, world.x[b], world.y[b], alive, alive, nan[b], world.limit[b])
    record(ticks, nan)
    if progress is not None:
        progress(ticks, ticks)
    return [_result(s, b, rec, hist, events[b], world, brains, ticks, watches.get(b)) for b, s in enumerate(scenarios)]


def _sink(k: int, dt: float, ids: np.ndarray, events: list[dict], rec):
    """An event sink of member events at tick k, as Engine.event writes them (no wall time)."""

    def event(kind: str, agent: int | None, reason: str, **more) -> dict:
        ev = {"tick": k, "time": k * dt, "agent": agent, "kind": kind, "reason": reason, **more}
        events.append(ev)
        if rec is not None:
            rec.event(ev)
        return ev

    return event


def _switches(k: int, dt: float, world: BatchWorld, frames, out, new, changed, pinned):
    """(member, "switch" event) for each follower whose out-neighbour changed at tick k,
    as Engine.command writes them (member by member, agents in scenario order)."""
    for b, i in np.argwhere(changed).tolist():
        old, to = int(out[b, i]), int(new[b, i])
        ids = world.ids[b]
        reason = world.switch_reason(frames, b, i, old, to, None if pinned is None else int(pinned[b, i]))
        yield (
            b,
            {
                "tick": k,
                "time": k * dt,
                "agent": int(ids[i]),
                "kind": EventKind.SWITCH,
                "reason": reason,
                "from": None if old < 0 else int(ids[old]),
                "to": None if to < 0 else int(ids[to]),
            },
        )


def _result(
    s: Scenario,
    b: int,
    rec,
    hist: dict,
    events: list[dict],
    world: BatchWorld,
    brains: BatchBrains,
    ticks: int,
    watch: SafetyWatch | None = None,
) -> RunResult:
    extra: dict = {"engine": ENGINE, "rejected_commands": int(world.rejected[b]), "lost_frames": 0, "lost_commands": 0}
    agent_extra = {str(a.id): brains.figures(b, i) for i, a in enumerate(s.agents)}
    if watch is not None:  # as Engine.result adds them
        extra["safety"] = watch.figures()
        for aid, figs in watch.agent_figures().items():
            agent_extra[aid] = {**agent_extra.get(aid, {}), **figs}
    if rec is None:
        shape = (ticks + 1, len(s.agents))
        arrays = {k: hist[k][b] if k in hist else np.broadcast_to(np.nan, shape) for k in ("x", "y", "heading", "u")}
        arrays.update(
            t=np.arange(ticks + 1) * world.dt,
            out=hist["out"][b],
            follow=hist["follow"][b],
            alive=np.broadcast_to(True, shape),
            missed=np.zeros(ticks + 1, dtype=np.int64),
        )
        rec = MemberRecording(s, arrays)
    return RunResult(s, rec, events, extra, agent_extra)
