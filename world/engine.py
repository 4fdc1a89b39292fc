"""One tick of a run, the same for both shells: faults due -> frames -> commands ->
events -> record -> integrate.

`Engine` owns everything a tick changes: ground truth (`WorldCore`), the scripted fault
plan, each agent's chosen out-neighbour, the events and the recording. A shell decides
only how frames reach the agents and how their commands come back:

- `swarm sim` (swarm/offline/sim.py): in-process `AgentBrain`s, called in scenario order;
- the world process (world/process.py): agent processes over zenoh, with a lockstep
  deadline or the wall clock.

Both call the same methods in the same order, so `swarm up --clock lockstep` equals
`swarm sim` by construction, faults included. Process faults (kill, restart, freeze,
thaw) are due here; carrying them out is the shell's job, and both end in `drop` /
`join`: a kill or a freeze drops the agent at the fault's tick (a frozen process is
dropped when its link lease runs out, and the lockstep clock holds until it is), a
restart or a thaw brings it back (a restart with a fresh brain, a thaw with the one it had).

A scenario's [safety] table puts the safety filter (world/safety_watch.py) between the
commands latched and step 6: the turn rates (and speeds) it gives are the ones recorded and
integrated (or sent to the robots), and it counts what it changed and what came too close.

A plant (world/plant.py: real robots) replaces the integration of step 6; the world
process starts it before tick 0 (`start_plant`) and stops it however the run ends
(`stop_plant`). Without one nothing differs.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from swarm.contracts.frames import SensorFrame
from swarm.contracts.scenario import Scenario
from swarm.contracts.scenario_tables import AgentSpec
from swarm.contracts.vocabulary import EventKind, FollowState
from swarm.contracts.wire import FOLLOW_CODE
from swarm.world.core import ACTIVE, WorldCore
from swarm.world.faults import FaultPlan, fault_event
from swarm.world.plant import Plant
from swarm.world.recording import Recorder, RunResult, StreamRecorder, TickRecorder
from swarm.world.safety_watch import SafetyWatch

# What became of a command (`Engine.command`).
LATCHED, LOST, REFUSED = "latched", "lost", "refused"


class Engine:
    def __init__(
        self,
        scenario: Scenario,
        ticks: int,
        *,
        joined: bool = True,
        wall_clock: Callable[[], float] | None = None,
        on_event: Callable[[dict], None] | None = None,
        recording: Path | None = None,
        plant: Plant | None = None,
        keep: bool = False,
        keep_max: int | None = None,
    ):
        """ticks: steps to record; joined: agents start in the world (sim) or join later
        (the world process); wall_clock: stamps events with `wall_time`; on_event: told of
        every event as it happens (the world publishes and prints them); recording: the
        recording.mcap to stream ticks and events to (None: keep them in memory); plant:
        what moves the agents instead of the kinematics (world/plant.py); keep: the recorded
        ticks are also kept in memory (`StreamRecorder`), for a shell that returns them or
        writes its results from them, up to keep_max agent-ticks (None: however many)."""
        self.core = WorldCore(scenario, joined=joined, plant=plant)
        self.plant = plant
        self.plant_stopped = False
        # steps the plant holds for instead of driving the robots (world/clock.py): the tick a
        # stall fell in (its commands came from stale poses) and those right after a stall,
        # while the links to the robots come back (a zero twist sent into a link the stall
        # broke is lost)
        self.held_steps = 0
        self.held_total = 0  # steps the plant held for, over the run
        self.first_held_tick: int | None = None  # the first of them (None: the plant never held)
        # realtime with a plant (world/clock.py): the monotonic time past which this tick's
        # commands are stale (a stall of a tick or more since they were computed), and how
        # many steps to hold for then
        self.send_by: float | None = None
        self.hold_after_stall = 1
        self.fault_plan = FaultPlan(scenario.faults, scenario.run.dt, scenario.run.seed)
        self.network = self.fault_plan.affects_network()  # frames and commands go through the fault plan
        self.ticks = ticks
        self.rec: TickRecorder = (
            Recorder(scenario, ticks)
            if recording is None
            else StreamRecorder(scenario, ticks, recording, keep, keep_max)
        )
        self.events: list[dict] = []
        self.out = np.full(len(scenario.agents), -1, dtype=np.int64)  # chosen out-neighbour ids
        # each agent's follow state as its last latched command said it (wire.FOLLOW_STATES codes)
        self.follow = np.zeros(len(scenario.agents), dtype=np.int8)
        self.hops_sent = self.core.hops.copy()  # hop counts this tick's frames advertise
        self.missed_now = 0  # live agents whose command is held at this tick
        self.wall_clock = wall_clock
        self.on_event = on_event
        # [safety]: the filter between the latched commands and the integration, and its figures
        self.safety = None if scenario.safety is None else SafetyWatch(scenario.safety, scenario.ids)

    @property
    def tick(self) -> int:
        return self.core.tick

    @property
    def time(self) -> float:
        return self.core.time

    @property
    def scenario(self) -> Scenario:
        return self.core.scenario

    def event(self, kind: str, agent: int | None, reason: str, **more: Any) -> dict:
        ev: dict[str, Any] = {"tick": self.core.tick, "time": self.core.time}
        if self.wall_clock is not None:
            ev["wall_time"] = self.wall_clock()
        ev.update(agent=agent, kind=kind, reason=reason, **more)
        self.events.append(ev)
        self.rec.event(ev)
        if self.on_event is not None:
            self.on_event(ev)
        return ev

    # -- the plant -----------------------------------------------------------------------------
    def start_plant(self) -> None:
        """Before tick 0: the plant sets the poses the first frames are built from."""
        if self.plant is not None:
            self.plant.start(self.core, self.event)

    def hold_plant(self) -> None:
        """The clock holds (a pause, a scripted fault carried out): the plant stands still."""
        if self.plant is not None and not self.plant_stopped:
            self.plant.hold()

    def resync_plant(self) -> None:
        """The clock could not keep time (a stall): the plant stands still first (a zero
        twist), then the next tick starts from its latest poses, not from the stalled ones."""
        if self.plant is not None and not self.plant_stopped:
            self.plant.hold()
            self.plant.start(self.core, self.event)

    def stop_plant(self) -> None:
        """However the run ends: the plant stops what it moves (once; later calls do nothing)."""
        if self.plant is not None and not self.plant_stopped:
            self.plant_stopped = True
            self.plant.stop()

    # -- 1. faults due -------------------------------------------------------------------------
    def due(self) -> list:
        """Scripted faults that start at this tick, each logged as a "fault" event; the
        shell carries out the process faults among them."""
        due = self.fault_plan.due(self.core.tick)
        for i, f in due:
            self.event(EventKind.FAULT, f.agent, f"scripted {f.kind}", fault=fault_event(i, f))
        return due

    def drop(self, agent: int, reason: str, quiet: bool = False) -> str | None:
        """The agent's process is gone (killed, frozen past its lease): it leaves the world
        or coasts. None if it was not active. `quiet`: no event (counted by the shell)."""
        k = self.core.index[agent]
        if self.core.state[k] != ACTIVE:
            return None
        state = self.core.drop(agent)
        self.out[k] = -1
        self.follow[k] = 0
        if not quiet:
            self.event(EventKind.DROP, agent, reason, now=state)
        return state

    def join(self, agent: int, reason: str, rejoin: bool, quiet: bool = False, **more: Any) -> bool:
        """The agent's process is (back) in the world, controlled from its current pose.
        `quiet`: no event (counted by the shell)."""
        if self.core.state[self.core.index[agent]] == ACTIVE:
            return False
        self.core.join(agent)
        if not quiet:
            self.event(EventKind.REJOIN if rejoin else EventKind.JOIN, agent, reason, **more)
        return True

    def add_agent(self, spec: AgentSpec) -> None:
        """A new agent (not in the scenario file) enters the run, not joined yet."""
        self.core.add_agent(spec)
        self.rec.add_agent(self.core.scenario)
        self.out = np.append(self.out, -1)
        self.follow = np.append(self.follow, np.int8(0))
        if self.safety is not None:
            self.safety.add_agent(spec.id)

    # -- 2. frames -------------------------------------------------------------------------------
    def frames(self) -> dict[int, SensorFrame]:
        """This tick's frames as the active agents receive them: through the fault plan
        (delay, noise), lost ones left out and counted as missed."""
        self.hops_sent = self.core.hops.copy()
        frames = self.core.frames()
        if not self.network:
            return frames
        delivered = {}
        for aid, frame in frames.items():
            got = self.fault_plan.sense(frame)
            if got is None:
                self.missed_now += 1
            else:
                delivered[aid] = got
        return delivered

    def frames_exact(self) -> bool:
        """True when this tick's frames are exactly what the core builds (no network fault
        in the scenario), so a shell may encode them straight from the core's arrays; it
        then calls `mark_frames` instead of `frames`."""
        return not self.network

    def mark_frames(self) -> None:
        self.hops_sent = self.core.hops.copy()

    # -- 3. commands and 4. events ---------------------------------------------------------------
    def command(
        self, agent: int, tick: int, u: float, out: int | None, hops: int | None, follow: str = FollowState.NONE
    ) -> str:
        """Agent `agent`'s answer to its frame of `tick` (this tick): lost on the way by the
        fault plan (its last command is held), refused when not finite, or latched; a new
        out-neighbour is a "switch" event. follow: its FollowState, recorded with its out."""
        if self.network and tick == self.core.tick and self.fault_plan.command_lost(tick, agent):
            self.missed_now += 1
            return LOST
        c = self.core
        if not c.set_command(agent, u, hops):
            return REFUSED
        k = c.index[agent]
        self.follow[k] = FOLLOW_CODE[follow]
        new = -1 if out is None else out
        was = self.out.item(k)  # a Python int: numpy scalars are slow to compare
        if new != was:
            if not c.is_leader.item(k):
                old = None if was < 0 else was
                self.event(
                    EventKind.SWITCH,
                    agent,
                    c.switch_reason(agent, old, out, self.hops_sent),
                    **{"from": old, "to": out},
                )
            self.out[k] = new
        return LATCHED

    def miss(self, n: int = 1) -> None:
        """`n` live agents' commands are held at this tick for the shell's own reasons
        (a lockstep deadline passed)."""
        self.missed_now += n

    # -- 5. record and 6. integrate --------------------------------------------------------------
    def end_tick(self, observe: Callable[[np.ndarray], None] | None = None) -> None:
        """Record this tick and step the world; `observe(u)` sees the recorded state with
        the turn rates about to be integrated (the world publishes it as ground truth)."""
        c = self.core
        u = c.applied()
        speed = None
        if self.safety is not None:  # the safety filter: the turn rates (and speeds) to apply instead
            alive, present = c.alive_mask(), c.present_mask()
            u, speed = self.safety.command(c.x, c.y, c.heading, c.speed, u, c.limit, present, alive, self.event)
            self.safety.measure(c.tick, c.x, c.y, present, alive, u, c.limit)
        self.rec.record(c.tick, c.time, c.x, c.y, c.heading, u, self.out, c.alive_mask(), self.missed_now, self.follow)
        self.missed_now = 0
        if observe is not None:
            observe(u)
        if self.send_by is not None and time.monotonic() > self.send_by:  # stalled since the frames went out
            self.held_steps = max(self.held_steps, self.hold_after_stall)
        if self.held_steps > 0 and self.plant is not None and not self.plant_stopped:
            self.held_steps -= 1
            self.held_total += 1
            if self.first_held_tick is None:
                self.first_held_tick = c.tick
            self.resync_plant()  # a zero twist instead of commands computed from stale poses; fresh poses in
            c.advance_held()
            return
        if self.safety is None:
            c.step()
        else:
            c.step(u, speed)

    def close(self) -> None:
        """Record the final state (no command: u is NaN), once."""
        c = self.core
        if c.tick <= self.ticks and self.rec.rows <= c.tick:
            nan = np.full(len(c.ids), np.nan)
            if self.safety is not None:
                self.safety.measure(c.tick, c.x, c.y, c.present_mask(), c.alive_mask(), nan, c.limit)
            self.rec.record(c.tick, c.time, c.x, c.y, c.heading, nan, self.out, c.alive_mask(), 0, self.follow)

    def result(self, extra: dict, agent_extra: dict | None = None) -> RunResult:
        """The run's results; with [safety], its figures in summary.json ("safety", and each
        agent's) whatever the shell."""
        agent_extra = dict(agent_extra or {})
        if self.safety is not None:
            extra = {**extra, "safety": self.safety.figures()}
            for aid, figs in self.safety.agent_figures().items():
                agent_extra[aid] = {**agent_extra.get(aid, {}), **figs}
        return RunResult(self.core.scenario, self.rec, self.events, extra, agent_extra)
