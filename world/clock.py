"""The world's clocks: how ticks are paced and when a tick may end.

`lockstep` waits each tick for every live agent's command (up to the deadline);
`realtime` ticks at dt / time_scale of wall time with whatever commands arrived.
Both hold for pause and for scripted process faults, which the launcher carries out
while the clock waits for the drop or the rejoin. A mixin of `World`
(world/process.py).

When no agent is left in a started run and no scripted restart or thaw is to bring one
back, the lockstep clock holds (there is nobody to step for) and the realtime clock goes
on; if nobody joins within DESERTED_GRACE s of wall time, the world records a `deserted`
event and ends the run (exit EXIT_DESERTED; `completed` is false).
"""

from __future__ import annotations

import sys
import time

from swarm.contracts import wire
from swarm.contracts.lifeline import tie_to_launcher
from swarm.contracts.transport import answer
from swarm.world.core import ACTIVE
from swarm.world.faults import fault_event
from swarm.world.memory import Trimmer

DESERTED_GRACE = 5.0  # s of wall time a started run may go on with no agent at all
STALL_GRACE = 3.0  # s the agents get to answer after a stall of the world (their links come back in ~0.5 s)
RESEND_S = 0.25  # s between resends of a tick's frames after a stall of the world
MAX_REASONS = 20  # reasons kept for `not_reproducible`
EXIT_DESERTED = 5


class Clock:
    deserted_since: float | None = None  # monotonic s since when no agent is in the started run
    restarts: int = 0  # lockstep: deadlines restarted (a stall of the world, a link back)
    carrying: int | None = None  # the agent a scripted fault is being carried out on

    def answer_pause_waiters(self) -> None:
        """Answer the pause queries that came during a tick, now that it is done, with the
        clock's state now (a resume in the same tick: paused false), and finish them."""
        for q in self.pause_waiters:
            answer(
                q,
                wire.world_admin_key(self.cfg.run),
                wire.encode_admin_reply(True, paused=self.paused, tick=self.core.tick),
            )
        self.pause_waiters.clear()

    def wait_for_agents(self) -> None:
        ids = self.cfg.scenario.ids
        t_end = None if self.cfg.join_timeout is None else time.monotonic() + self.cfg.join_timeout
        last_note = 0.0
        while True:
            missing = [i for i in ids if self.core.state[self.core.index[i]] != ACTIVE]
            if not missing:
                return
            now = time.monotonic()
            if t_end is not None and now > t_end:
                raise TimeoutError(
                    f"agents {', '.join(map(str, missing))} did not join within {self.cfg.join_timeout} s"
                )
            if self.cfg.progress and now - last_note > 5.0:
                last_note = now
                print(
                    f"[world] waiting for agents {', '.join(map(str, missing))}: "
                    f"swarm agent --id N --connect {self.cfg.listen}",
                    file=sys.stderr,
                    flush=True,
                )
            self.drain(None, 0.1)

    def _wait(self, cond, timeout: float) -> bool:
        t_end = time.monotonic() + timeout
        while not cond():
            left = t_end - time.monotonic()
            if left <= 0:
                return False
            self.drain(None, min(left, 0.05))
        return True

    def unscripted(self, aid: int, what: str) -> None:
        """Agent `aid` joined or left the started run, not by a scripted fault: `swarm sim`
        cannot do the same, so the run is no longer reproducible (its reasons say why)."""
        if self.started and aid != self.carrying:
            self.not_reproducible(f"agent {aid} {what} at tick {self.core.tick}, not by a scripted fault")

    def not_reproducible(self, reason: str) -> None:
        if len(self.irreproducible) < MAX_REASONS:
            self.irreproducible.append(reason)
        elif len(self.irreproducible) == MAX_REASONS:
            self.irreproducible.append("... and more")

    def reproducibility(self) -> dict:
        """summary.json's `reproducible` (bool) and `not_reproducible` (reasons): whether
        `swarm sim` of the same scenario gives this run's trajectories exactly."""
        reasons = list(self.irreproducible)
        if self.cfg.clock != "lockstep":
            reasons.insert(0, f"clock {self.cfg.clock}: commands are used as they arrive")
        late = {aid: n for aid, n in self.late.items() if n}
        if late:
            n = sum(late.values())
            reasons.insert(
                0,
                f"{n} command{'s' if n > 1 else ''} missed the lockstep deadline (agent"
                f"{'s' if len(late) > 1 else ''} {', '.join(map(str, sorted(late)))}): "
                "the last command was held instead",
            )
        if len(self.book) > len(self.cfg.scenario.ids):
            reasons.append(f"{len(self.book) - len(self.cfg.scenario.ids)} agents added at run time")
        return {"reproducible": not reasons, "not_reproducible": reasons}

    def carry_out(self, index: int, f) -> None:
        """A scripted fault is due at this tick. Network faults are the fault plan's job;
        process faults are asked of the launcher (it owns the processes) while the clock
        holds, and then, for kill and restart, the world waits to see the drop or the join."""
        if f.kind not in ("kill", "restart", "freeze", "thaw"):
            return
        t_hold = time.monotonic()
        self.carrying = f.agent  # its drop or join is the fault's (see `unscripted`)
        try:
            self._carry_out(index, f)
        finally:
            self.carrying = None
            self.held += time.monotonic() - t_hold

    def _carry_out(self, index: int, f) -> None:
        self.fault_awaited = index  # the one fault_done the launcher may report now (world/inbox.py)
        self.control_pub.put(wire.encode_fault_notice(index, self.core.tick, fault_event(index, f)))
        done = self._wait(lambda: index in self.faults_done, 5.0)
        self.fault_awaited = None
        if not done:
            self.event("fault_skipped", f.agent, f"nobody carried out the {f.kind} (no launcher?)")
            self.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {self.core.tick}")
            return
        k = self.core.index[f.agent]
        # Hold the clock until the fault has taken effect, so that it lands on this tick as
        # in `swarm sim`: a killed process is dropped when its socket closes, a frozen one
        # when its link lease runs out; a restarted or thawed one rejoins.
        if f.kind in ("kill", "freeze"):
            if not self._wait(lambda: self.core.state[k] != ACTIVE, 3.0 if f.kind == "kill" else 6.0):
                self.event("fault_late", f.agent, f"the {f.kind} did not drop the agent in time")
                self.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {self.core.tick}")
        elif not self._wait(lambda: self.core.state[k] == ACTIVE, 20.0):
            self.event("fault_late", f.agent, f"the {f.kind} agent did not rejoin within 20 s")
            self.not_reproducible(f"the scripted {f.kind} of agent {f.agent} did not land on tick {self.core.tick}")

    def deserted(self) -> bool:
        """No agent in the run, and no scripted restart or thaw to come (see the module)."""
        if ACTIVE in self.core.state:
            self.deserted_since = None
            return False
        plan = self.engine.fault_plan
        if any(f.kind in ("restart", "thaw") and t >= self.core.tick for t, f in zip(plan.tick_of, plan.faults)):
            return False
        now = time.monotonic()
        if self.deserted_since is None:
            self.deserted_since = now
            if self.cfg.progress:
                print(
                    f"[world] no agent left at tick {self.core.tick}; ending the run unless one joins within "
                    f"{DESERTED_GRACE:g} s",
                    file=sys.stderr,
                    flush=True,
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
        pending = self.publish_frames()
        t_end = time.monotonic() + self.deadline
        seen, resent = self.disturbed, None
        while pending:
            now = time.monotonic()
            if self.disturbed != seen:  # not the agents' fault
                seen, resent = self.disturbed, now
                t_end = now + max(self.deadline, STALL_GRACE)
                self.restarts += 1
                self.resend_frames(pending)
            elif resent is not None and now - resent >= RESEND_S:
                resent = now
                self.resend_frames(pending)
            left = t_end - now
            if left <= 0:
                while pending and self.drain(pending, 0):  # already here: not missed
                    pass
                if not pending or self.disturbed != seen:
                    continue
                if self.lost_after_stall and pending & self.lost_after_stall.keys():
                    self.drain(pending, RESEND_S)  # held: back (a disturbance) or dropped (not pending)
                    continue
                for aid in pending:
                    self.book[aid].missed += 1
                    self.late[aid] = self.late.get(aid, 0) + 1
                self.engine.miss(len(pending))
                break
            self.drain(pending, left if resent is None else min(left, RESEND_S))
        while self.drain(None, 0):  # joins/drops that arrived meanwhile take effect now
            pass

    def realtime_tick(self, t_next: float) -> None:
        tick = self.core.tick
        self.publish_frames()
        while True:
            left = t_next - time.monotonic()
            if left <= 0:
                break
            self.drain(None, left)
        # Behind the clock (a starved world catching up) the loop above takes nothing: what
        # came meanwhile is handled all the same, or the inbox (and the native memory under
        # it, world/memory.py) grows with every tick until the world has caught up.
        for _ in range(self.inbox.qsize()):
            if not self.drain(None, 0):
                break
        for aid in self.core.active_ids():
            b = self.book[aid]
            stale = tick - b.last_cmd_tick if b.last_cmd_tick >= 0 else tick + 1
            b.stale_sum += stale
            b.stale_max = max(b.stale_max, stale)

    def run(self) -> int:
        tie_to_launcher()  # started by `swarm up`: SIGTERM (results written) when the launcher dies
        self.t_start = time.monotonic()
        period = self.core.dt / self.cfg.time_scale
        last_note = time.monotonic()
        t0_ticks = time.monotonic()
        self.wait_for_agents()
        self.event(
            "start",
            None,
            f"all {len(self.book)} agents joined; clock {self.cfg.clock}",
            startup_s=time.monotonic() - self.t_start,
        )
        self.started = True
        t_next = time.monotonic() + period
        t0_ticks = time.monotonic()
        self.trimmer = Trimmer()  # freed native memory back to the system (world/memory.py)
        while self.core.tick < self.ticks:
            if self.deserted():
                self.event(
                    "deserted", None, f"no agent process for {DESERTED_GRACE:g} s of wall time; the run ends here"
                )
                self.wall_ticks = time.monotonic() - t0_ticks
                return EXIT_DESERTED
            if self.cfg.clock == "lockstep" and self.deserted_since is not None:
                t_hold = time.monotonic()
                self.drain(None, 0.1)  # nobody to step for: hold (a join ends the hold)
                t0_ticks += time.monotonic() - t_hold
                continue
            self.answer_pause_waiters()  # a pause (and a resume) asked during the last tick
            if self.paused:
                t_pause = time.monotonic()
                while self.paused:
                    self.drain(None, 0.1)
                t_next += time.monotonic() - t_pause
                t0_ticks += time.monotonic() - t_pause
            due = self.engine.due()
            if due:
                held = self.held
                for i, f in due:
                    self.carry_out(i, f)
                t_next += self.held - held  # realtime: the hold is not lateness
                t0_ticks += self.held - held
            self.ticking = True
            if self.cfg.clock == "lockstep":
                self.lockstep_tick()
            else:
                self.realtime_tick(t_next)
                t_next += period
            self.record_and_step()
            self.ticking = False
            now = time.monotonic()
            self.trimmer.maybe(now)
            if self.cfg.progress and now - last_note > 2.0:
                last_note = now
                rate = self.core.tick / max(now - t0_ticks, 1e-9)
                print(
                    f"[world] tick {self.core.tick}/{self.ticks} t={self.core.time:.2f}s {rate:.0f} ticks/s",
                    file=sys.stderr,
                    flush=True,
                )
        self.wall_ticks = time.monotonic() - t0_ticks
        return 0
