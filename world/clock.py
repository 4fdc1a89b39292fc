"""The world's clocks: how ticks are paced and when a tick may end.

`lockstep` waits each tick for every live agent's command (up to the deadline);
`realtime` ticks at dt / time_scale of wall time with whatever commands arrived.
Both hold for pause and for scripted process faults, which the launcher carries out
while the clock waits for the drop or the rejoin. `Clock` gets in its constructor the
run's state (world/state.py), the inbox it drains (world/inbox.py) and the shell that
sends frames and steps the engine (`TickShell`: the world process, world/process.py).

When no agent is left in a started run and no scripted restart or thaw is to bring one
back, the lockstep clock holds (there is nobody to step for) and the realtime clock goes
on; if nobody joins within DESERTED_GRACE s of wall time, the world records a `deserted`
event and ends the run (exit ExitCode.DESERTED; `completed` is false).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from typing import Any, Protocol

from swarm.contracts import wire
from swarm.contracts.lifeline import tie_to_launcher
from swarm.contracts.scenario_tables import FaultSpec
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import AgentState, EventKind, ExitCode
from swarm.world.faults import fault_event
from swarm.world.inbox import Inbox
from swarm.world.memory import Trimmer
from swarm.world.state import RunState
from swarm.world.tick_times import TickTimes

log = logging.getLogger(__name__)

RESUME_HOLD_S = 0.5  # s of wall time robots stand still after a stall (links back, fresh poses) before they drive again
LATE_EVENT_GAP_S = 1.0  # s of wall time between two `late` events (the counts in summary.json keep every one)
DESERTED_GRACE = 5.0  # s of wall time a started run may go on with no agent at all
STALL_GRACE = 3.0  # s the agents get to answer after a stall of the world (their links come back in ~0.5 s)
RESEND_S = 0.25  # s between resends of a tick's frames after a stall of the world

ACTIVE = AgentState.ACTIVE


class TickShell(Protocol):
    """What the clock asks of the world process in a tick (world/process.py)."""

    def publish_frames(self) -> set[int]:
        """Send this tick's frames; the agents that were sent one."""
        ...

    def resend_frames(self, aids: Iterable[int]) -> None: ...

    def record_and_step(self) -> None: ...

    def send_control(self, payload: bytes) -> None:
        """A message to the launcher on world/control (a scripted fault to carry out)."""
        ...


class Clock:
    def __init__(self, state: RunState, inbox: Inbox, shell: TickShell, deadline: float):
        self.state = state
        self.inbox = inbox
        self.shell = shell
        self.deadline = deadline  # lockstep: s each tick waits for the agents' commands
        self.deserted_since: float | None = None  # monotonic s since when no agent is in the started run
        self.restarts = 0  # lockstep: deadlines restarted (a stall of the world, a link back)
        self.held = 0.0  # wall s the clock held for process faults
        self.late: dict[int, int] = {}  # lockstep: commands per agent that missed the deadline
        self.t_start = 0.0
        self.wall_ticks: float | None = None  # wall s from the first tick to the last (set at the end)
        # Each tick's wall duration, from its frames going out to the end of its record and
        # step (lockstep: the tick's critical path; realtime: that includes the wait for the
        # clock), for summary.json's `tick_ms`; pauses, held faults and deserted holds are
        # between ticks, not in any.
        self.tick_times = TickTimes()
        self.trimmer: Trimmer | None = None
        # realtime: ticks that started more than half a period late (the clock re-anchored
        # instead of running them back to back), the whole periods the run fell behind by
        # there, and when the last `late` event was recorded
        self.late_ticks = 0
        self.skipped_ticks = 0
        self.late_event_at: float | None = None

    def answer_pause_waiters(self) -> None:
        """Answer the pause queries that came during a tick, now that it is done, with the
        clock's state now (a resume in the same tick: paused false), and finish them."""
        st = self.state
        for q in st.pause_waiters:
            answer(
                q,
                wire.world_admin_key(st.cfg.run),
                wire.encode_admin_reply(True, paused=st.paused, tick=st.core.tick),
            )
        st.pause_waiters.clear()

    def wait_for_agents(self) -> None:
        st = self.state
        cfg, core = st.cfg, st.core
        ids = cfg.scenario.ids
        t_end = None if cfg.join_timeout is None else time.monotonic() + cfg.join_timeout
        last_note = 0.0
        while True:
            missing = [i for i in ids if core.state[core.index[i]] != ACTIVE]
            if not missing:
                return
            now = time.monotonic()
            if t_end is not None and now > t_end:
                raise TimeoutError(f"agents {', '.join(map(str, missing))} did not join within {cfg.join_timeout} s")
            if cfg.progress and now - last_note > 5.0:
                last_note = now
                log.info(
                    "waiting for agents %s: swarm agent --id N --connect %s", ", ".join(map(str, missing)), cfg.listen
                )
            self.inbox.drain(None, 0.1)

    def _wait(self, cond: Callable[[], bool], timeout: float) -> bool:
        t_end = time.monotonic() + timeout
        while not cond():
            left = t_end - time.monotonic()
            if left <= 0:
                return False
            self.inbox.drain(None, min(left, 0.05))
        return True

    def reproducibility(self) -> dict[str, Any]:
        """summary.json's `reproducible` (bool) and `not_reproducible` (reasons): whether
        `swarm sim` of the same scenario gives this run's trajectories exactly."""
        st = self.state
        reasons = list(st.irreproducible)
        if st.cfg.clock != "lockstep":
            reasons.insert(0, f"clock {st.cfg.clock}: commands are used as they arrive")
        late = {aid: n for aid, n in self.late.items() if n}
        if late:
            n = sum(late.values())
            reasons.insert(
                0,
                f"{n} command{'s' if n > 1 else ''} missed the lockstep deadline (agent"
                f"{'s' if len(late) > 1 else ''} {', '.join(map(str, sorted(late)))}): "
                "the last command was held instead",
            )
        if len(st.book) > len(st.cfg.scenario.ids):
            reasons.append(f"{len(st.book) - len(st.cfg.scenario.ids)} agents added at run time")
        return {"reproducible": not reasons, "not_reproducible": reasons}

    def carry_out(self, index: int, f: FaultSpec) -> None:
        """A scripted fault is due at this tick. Network faults are the fault plan's job;
        process faults are asked of the launcher (it owns the processes) while the clock
        holds, and then, for kill and restart, the world waits to see the drop or the join."""
        if f.kind not in ("kill", "restart", "freeze", "thaw"):
            return
        t_hold = time.monotonic()
        self.state.engine.hold_plant()  # robots stand still while the clock holds
        self.state.carrying = f.agent  # its drop or join is the fault's (RunState.unscripted)
        try:
            self._carry_out(index, f)
        finally:
            self.state.carrying = None
            self.held += time.monotonic() - t_hold

    def _carry_out(self, index: int, f: FaultSpec) -> None:
        st, core = self.state, self.state.core
        st.fault_awaited = index  # the one fault_done the launcher may report now (world/reports.py)
        self.shell.send_control(wire.encode_fault_notice(index, core.tick, fault_event(index, f)))
        done = self._wait(lambda: index in st.faults_done, 5.0)
        st.fault_awaited = None
        if not done:
            st.event(EventKind.FAULT_SKIPPED, f.agent, f"nobody carried out the {f.kind} (no launcher?)")
            st.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {core.tick}")
            return
        assert f.agent is not None  # a process fault names its agent (FaultSpec)
        k = core.index[f.agent]
        # Hold the clock until the fault has taken effect, so that it lands on this tick as
        # in `swarm sim`: a killed process is dropped when its socket closes, a frozen one
        # when its link lease runs out; a restarted or thawed one rejoins.
        if f.kind in ("kill", "freeze"):
            if not self._wait(lambda: core.state[k] != ACTIVE, 3.0 if f.kind == "kill" else 6.0):
                st.event(EventKind.FAULT_LATE, f.agent, f"the {f.kind} did not drop the agent in time")
                st.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {core.tick}")
        elif not self._wait(lambda: core.state[k] == ACTIVE, 20.0):
            st.event(EventKind.FAULT_LATE, f.agent, f"the {f.kind} agent did not rejoin within 20 s")
            st.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {core.tick}")

    def deserted(self) -> bool:
        """No agent in the run, and no scripted restart or thaw to come (see the module)."""
        st, core = self.state, self.state.core
        if ACTIVE in core.state:
            self.deserted_since = None
            return False
        plan = st.engine.fault_plan
        if any(f.kind in ("restart", "thaw") and t >= core.tick for t, f in zip(plan.tick_of, plan.faults)):
            return False
        now = time.monotonic()
        if self.deserted_since is None:
            self.deserted_since = now
            if st.cfg.progress:
                log.info(
                    "no agent left at tick %d; ending the run unless one joins within %g s", core.tick, DESERTED_GRACE
                )
        return now - self.deserted_since > DESERTED_GRACE

    def lockstep_tick(self) -> None:
        """Frames out, then every live agent's command in, up to the deadline. The deadline
        is the agents': a stall of the world itself (SIGSTOP, a starved CPU), or an agent's
        link coming back, restarts it (STALL_GRACE at least) and sends this tick's frames
        again, every RESEND_S, to those that have not answered (the first ones may have gone
        with the links); an agent whose token is being ridden out (world/inbox.py,
        `rides_out`) is waited for until it is back or dropped; whatever reached the inbox
        before the deadline counts."""
        st, inbox = self.state, self.inbox
        pending = self.shell.publish_frames()
        t_end = time.monotonic() + self.deadline
        seen: int = inbox.disturbed
        resent: float | None = None
        while pending:
            now = time.monotonic()
            if inbox.disturbed != seen:  # not the agents' fault
                seen, resent = inbox.disturbed, now
                t_end = now + max(self.deadline, STALL_GRACE)
                self.restarts += 1
                self.shell.resend_frames(pending)
            elif resent is not None and now - resent >= RESEND_S:
                resent = now
                self.shell.resend_frames(pending)
            left = t_end - now
            if left <= 0:
                while pending and inbox.drain(pending, 0):  # already here: not missed
                    pass
                if not pending or inbox.disturbed != seen:
                    continue
                if inbox.lost_after_stall and pending & inbox.lost_after_stall.keys():
                    inbox.drain(pending, RESEND_S)  # held: back (a disturbance) or dropped (not pending)
                    continue
                for aid in pending:
                    st.book[aid].missed += 1
                    self.late[aid] = self.late.get(aid, 0) + 1
                st.engine.miss(len(pending))
                break
            inbox.drain(pending, left if resent is None else min(left, RESEND_S))
        while inbox.drain(None, 0):  # joins/drops that arrived meanwhile take effect now
            pass

    def keep_time(self, t_next: float, period: float) -> float:
        """Realtime: when this tick starts more than half a period late (the world stalled:
        SIGSTOP, a starved CPU, a long garbage collection), the clock re-anchors on now
        instead of running the missed ticks back to back: no two ticks' commands go out less
        than half a period apart, and none is computed from poses the stall made stale. The
        simulated time goes on from where it was (the run lasts longer in wall time). A
        re-anchoring that skipped at least one whole period records a `late` event (at most
        one per LATE_EVENT_GAP_S of wall time; summary.json counts every one), and a plant
        (robots) gets a zero twist and starts the tick from its latest poses. A stall after a
        tick's frames went out makes its commands stale: the engine finds it when it would send
        them (`Engine.send_by`). Either way the plant then holds for RESUME_HOLD_S of steps
        (`Engine.held_steps`: zero twists, fresh poses) before it drives the robots again.
        Returns the time this tick ends."""
        now = time.monotonic()
        behind = now - (t_next - period)  # how late this tick starts
        if behind <= period / 2:
            return t_next
        skipped = int(behind // period)
        self.late_ticks += 1
        self.skipped_ticks += skipped
        if skipped:
            if not self.state.engine.held_steps:  # (already holding: the stall fell within the last tick)
                self.state.engine.resync_plant()
            self.hold_robots(period)
            if self.late_event_at is None or now - self.late_event_at >= LATE_EVENT_GAP_S:
                self.late_event_at = now
                self.state.event(
                    EventKind.LATE,
                    None,
                    f"the clock fell {behind:.3f} s ({skipped} tick{'s' if skipped > 1 else ''}) behind: "
                    "re-anchored, no tick run late",
                    behind_s=round(behind, 6),
                    skipped=skipped,
                )
        return time.monotonic() + period

    @staticmethod
    def hold_ticks(period: float) -> int:
        return max(1, round(RESUME_HOLD_S / period))

    def hold_robots(self, period: float) -> None:
        """After a stall, a plant (robots) holds for RESUME_HOLD_S of steps: zero twists and
        fresh poses, no command computed before or during the stall."""
        engine = self.state.engine
        if engine.plant is not None:
            engine.held_steps = max(engine.held_steps, self.hold_ticks(period))

    def realtime_tick(self, t_next: float) -> None:
        st, inbox = self.state, self.inbox
        tick = st.core.tick
        self.shell.publish_frames()
        while True:
            left = t_next - time.monotonic()
            if left <= 0:
                break
            inbox.drain(None, left)
        # Behind the clock (a starved world catching up) the loop above takes nothing: what
        # came meanwhile is handled all the same, or the inbox (and the native memory under
        # it, world/memory.py) grows with every tick until the world has caught up.
        for _ in range(inbox.queue.qsize()):
            if not inbox.drain(None, 0):
                break
        for aid in st.core.active_ids():
            b = st.book[aid]
            stale = tick - b.last_cmd_tick if b.last_cmd_tick >= 0 else tick + 1
            b.stale_sum += stale
            b.stale_max = max(b.stale_max, stale)

    def run(self) -> int:
        """The run from the first join to the last tick; its exit code (OK, or DESERTED)."""
        st, inbox = self.state, self.inbox
        cfg, core = st.cfg, st.core
        tie_to_launcher()  # started by `swarm up`: SIGTERM (results written) when the launcher dies
        self.t_start = time.monotonic()
        period = core.dt / cfg.time_scale
        last_note = time.monotonic()
        t0_ticks = time.monotonic()
        self.wait_for_agents()
        st.engine.start_plant()  # robots (world/plant.py): the poses of tick 0
        st.event(
            EventKind.START,
            None,
            f"all {len(st.book)} agents joined; clock {cfg.clock}",
            startup_s=time.monotonic() - self.t_start,
        )
        st.started = True
        t_next = time.monotonic() + period
        t0_ticks = time.monotonic()
        self.trimmer = trimmer = Trimmer()  # freed native memory back to the system (world/memory.py)
        add_tick = self.tick_times.add
        while core.tick < st.ticks:
            if self.deserted():
                st.event(
                    EventKind.DESERTED,
                    None,
                    f"no agent process for {DESERTED_GRACE:g} s of wall time; the run ends here",
                )
                self.wall_ticks = time.monotonic() - t0_ticks
                return ExitCode.DESERTED
            if cfg.clock == "lockstep" and self.deserted_since is not None:
                t_hold = time.monotonic()
                inbox.drain(None, 0.1)  # nobody to step for: hold (a join ends the hold)
                t0_ticks += time.monotonic() - t_hold
                continue
            self.answer_pause_waiters()  # a pause (and a resume) asked during the last tick
            if st.paused:
                st.engine.hold_plant()  # robots stand still while the clock holds
                t_pause = time.monotonic()
                while st.paused:
                    inbox.drain(None, 0.1)
                t_next += time.monotonic() - t_pause
                t0_ticks += time.monotonic() - t_pause
            due = st.engine.due()
            if due:
                held = self.held
                for i, f in due:
                    self.carry_out(i, f)
                t_next += self.held - held  # realtime: the hold is not lateness
                t0_ticks += self.held - held
            st.ticking = True
            t_tick = time.perf_counter()
            if cfg.clock == "lockstep":
                self.lockstep_tick()
            else:
                t_next = self.keep_time(t_next, period)
                self.realtime_tick(t_next)
                if st.engine.plant is not None:  # commands sent later than this were computed before a stall
                    st.engine.send_by = t_next + period
                    st.engine.hold_after_stall = self.hold_ticks(period)
                t_next += period
            self.shell.record_and_step()
            add_tick(time.perf_counter() - t_tick)
            st.ticking = False
            now = time.monotonic()
            trimmer.maybe(now)
            if cfg.progress and now - last_note > 2.0:
                last_note = now
                rate = core.tick / max(now - t0_ticks, 1e-9)
                log.info("tick %d/%d t=%.2fs %.0f ticks/s", core.tick, st.ticks, core.time, rate)
        self.wall_ticks = time.monotonic() - t0_ticks
        return ExitCode.OK
