"""The world process: hub of a run, ground truth, physics, sensors, the recording.

It opens the run's zenoh endpoint (router mode, so a local run needs no router
binary), answers join queries, watches the agents' liveliness tokens, and each tick
sends every live agent its own sensor frame, collects commands, steps `WorldCore`
and records the tick. At the end (or on SIGTERM/SIGINT) it writes trajectory.npz
and summary.json into its output directory, announces the end and closes.

All zenoh callbacks only put (kind, ...) tuples on one inbox queue; everything else
happens on the main thread.
"""

from __future__ import annotations

import os
import queue
import signal
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarm.contracts import wire
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.scenario import Scenario
from swarm.contracts.transport import open_hub, socket_path
from world.core import ACTIVE
from world.engine import LOST, REFUSED, Engine
from world.faults import fault_event
from world.recording import write_run
from world.report import run_info
from world.roster import AgentBook, admit, agent_figures, new_agent_spec

TRUTH_PERIOD = 0.02  # s of wall time between ground-truth messages (observers, not the recording)


class Stop(BaseException):
    """Raised on the main thread by SIGTERM/SIGINT (a BaseException, so that no
    `except Exception` around publishing can swallow it)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


@dataclass
class WorldConfig:
    scenario: Scenario
    run: str
    listen: str
    out_dir: Path | None  # where the results go (None: nowhere)
    clock: str = "lockstep"
    time_scale: float = 1.0  # realtime clock: simulated s per wall s
    duration: float | None = None
    join_timeout: float | None = None  # s to wait for every agent before tick 0; None = forever
    deadline: float | None = None  # lockstep deadline override (s)
    progress: bool = True


@dataclass
class World:
    cfg: WorldConfig
    inbox: queue.SimpleQueue = field(default_factory=queue.SimpleQueue)

    def __post_init__(self):
        s = self.cfg.scenario
        self.ticks = int(round((self.cfg.duration or s.run.duration) / s.run.dt))
        # The tick itself (faults, frames, commands, events, record, step) is the engine's,
        # the same one `swarm sim` drives; this class is its zenoh shell.
        self.engine = Engine(s, self.ticks, joined=False, wall_clock=time.time, on_event=self._announce)
        self.core = self.engine.core
        self.book = {i: AgentBook() for i in s.ids}
        self.garbage = 0  # malformed or foreign messages on keys the world listens to
        self.ignored = 0
        self.deadline = self.cfg.deadline or s.run.lockstep_deadline
        self.stopped_by: int | None = None
        self.truth_sent = 0.0
        self.faults_done: set[int] = set()
        self.held = 0.0  # wall s the clock held for process faults
        self.paused = False
        self.ticking = False  # between the first frame of a tick and its step
        self.pause_waiters: list = []
        self.t_start = 0.0

    # -- zenoh plumbing (callbacks: enqueue only) -----------------------------------------
    def _open(self, session=None):
        """Declare the world's keys on `session` (default: a new hub on cfg.listen; tests
        pass a fake one, tests/fakes.py)."""
        run = self.cfg.run
        self.session = session if session is not None else open_hub(self.cfg.listen)
        ses = self.session
        put = self.inbox.put
        self._subs = [
            ses.declare_subscriber(wire.agent_key(run, "*", "cmd"),
                                   lambda s: put(("cmd", str(s.key_expr), s.payload.to_bytes()))),
            ses.liveliness().declare_subscriber(wire.agent_key(run, "*", "alive"),
                                                lambda s: put(("alive", str(s.key_expr), s.kind)),
                                                history=True),
            ses.declare_queryable(wire.world_join_key(run), lambda q: put(("join", q))),
            ses.declare_queryable(wire.world_info_key(run), lambda q: put(("info", q))),
            ses.declare_queryable(wire.world_admin_key(run), lambda q: put(("admin", q))),
        ]
        self.sense_pub = {i: ses.declare_publisher(wire.agent_key(run, i, "sense"), express=True)
                          for i in self.cfg.scenario.ids}
        self.truth_pub = ses.declare_publisher(wire.truth_key(run))
        self.events_pub = ses.declare_publisher(wire.events_key(run))
        self.control_pub = ses.declare_publisher(wire.world_control_key(run))
        self.token = ses.liveliness().declare_token(wire.world_alive_key(run))

    def _close(self):
        try:
            self.control_pub.put(wire.encode_end(self.core.tick))
        except Exception:
            pass
        self.session.close()

    # -- events -----------------------------------------------------------------------------
    def event(self, kind: str, agent: int | None, reason: str, **more) -> None:
        self.engine.event(kind, agent, reason, **more)

    def _announce(self, ev: dict) -> None:
        """Every event, as it happens: to observers over zenoh, and to the log."""
        kind, agent, reason = ev["kind"], ev["agent"], ev["reason"]
        try:
            self.events_pub.put(wire.encode_event(ev))
        except Exception:
            pass
        if self.cfg.progress:
            print(f"[world] t={self.core.time:8.2f}s tick {self.core.tick}: {kind} agent {agent}: {reason}",
                  file=sys.stderr, flush=True)

    # -- inbox handling ----------------------------------------------------------------------
    def handle(self, item, pending: set[int] | None) -> None:
        kind = item[0]
        if kind == "cmd":
            self._on_cmd(item[1], item[2], pending)
        elif kind == "alive":
            self._on_alive(item[1], item[2], pending)
        elif kind == "join":
            self._on_join(item[1])
        elif kind == "info":
            self._on_info(item[1])
        elif kind == "admin":
            self._on_admin(item[1])

    def _on_cmd(self, key: str, payload: bytes, pending: set[int] | None) -> None:
        try:
            aid = wire.agent_of_key(key)
            cmd = wire.decode_cmd(payload)
            if cmd.agent != aid:
                raise wire.WireError(f"command for agent {cmd.agent} on agent {aid}'s key")
        except wire.WireError:
            self.garbage += 1
            return
        if cmd.out is not None and (cmd.out == aid or cmd.out not in self.core.index):
            self.garbage += 1
            return
        k = self.core.index.get(aid)
        if k is None or self.core.state[k] != ACTIVE or cmd.tick > self.core.tick:
            self.ignored += 1
            return
        b = self.book[aid]
        if b.key is None or cmd.key != b.key:
            # Not from the process that claimed this id (a rogue session, or a stale process).
            b.rogue += 1
            if time.monotonic() - b.rogue_noted > 1.0:
                b.rogue_noted = time.monotonic()
                self.event("rogue", aid, f"command without the owner's claim key ignored ({b.rogue} so far)")
            return
        if cmd.tick <= b.last_cmd_tick:
            self.ignored += 1  # duplicate or late
            return
        done = self.engine.command(aid, cmd.tick, cmd.u, cmd.out, cmd.hops)
        if done == LOST:  # a network fault lost it: its last command is held
            b.last_cmd_tick = cmd.tick
            b.missed += 1
            if pending is not None:
                pending.discard(aid)
            return
        if done == REFUSED:
            b.garbage += 1
            return
        b.commands += 1
        b.last_cmd_tick = cmd.tick
        b.last_cmd_wall = time.monotonic()
        if pending is not None and cmd.tick == self.core.tick:
            pending.discard(aid)

    def _on_alive(self, key: str, kind, pending: set[int] | None) -> None:
        import zenoh

        try:
            aid = wire.agent_of_key(key)
        except wire.WireError:
            self.garbage += 1
            return
        if aid not in self.core.index:
            self.ignored += 1
            return
        k = self.core.index[aid]
        b = self.book[aid]
        if kind == zenoh.SampleKind.PUT:
            if self.core.state[k] == ACTIVE:
                return
            b.claim_until = 0.0  # the key stays: a thawed process rejoins with the claim it had
            b.last_cmd_tick = self.core.tick - 1
            self.engine.join(aid, f"liveliness token appeared (pid {b.pid} on {b.host})", b.joins > 0,
                             pid=b.pid, host=b.host)
            b.joins += 1
        elif self.engine.drop(aid, "liveliness token lost") is not None:
            b.drops += 1
            if pending is not None:
                pending.discard(aid)

    def _on_join(self, query) -> None:
        try:
            req = wire.decode_join_request(query.payload.to_bytes() if query.payload else b"")
            aid = req["id"]
            if aid not in self.core.index:
                if req.get("spec") is None:
                    raise wire.WireError(f"agent {aid} is not in scenario {self.cfg.scenario.name!r} "
                                         f"(ids: {', '.join(map(str, self.core.scenario.ids))}); "
                                         "a new agent needs a spec (swarm spawn --role --x --y ...)")
                self.add_agent(aid, req["spec"])
            key = admit(self.core, self.book[aid], req, time.monotonic())
            x, y, h = self.core.pose(aid)
            reply = wire.encode_join_reply(True, run=self.cfg.run, agent=aid, tick=self.core.tick, key=key,
                                           clock=self.cfg.clock, pose=[x, y, h],
                                           brain=BrainConf.from_scenario(self.core.scenario, aid).to_json())
        except wire.WireError as e:
            reply = wire.encode_join_reply(False, error=str(e))
        query.reply(wire.world_join_key(self.cfg.run), reply)

    def add_agent(self, aid: int, spec: dict) -> None:
        """A new agent joins the run with its own spec (`swarm spawn`); raises WireError."""
        a = new_agent_spec(aid, spec, self.core)
        self.engine.add_agent(a)
        self.book[aid] = AgentBook()
        self.sense_pub[aid] = self.session.declare_publisher(wire.agent_key(self.cfg.run, aid, "sense"),
                                                             express=True)
        self.event("add", aid, f"new {a.role} at ({a.x:g}, {a.y:g}) m, {a.speed:g} m/s")

    def info(self, sensing: bool = False) -> dict:
        """The world's view of the run, for the CLI (`swarm agents`, `graph`, `watch`)."""
        return run_info(self.engine, self.book, {
            "run": self.cfg.run, "scenario": self.core.scenario.name, "clock": self.cfg.clock,
            "paused": self.paused, "endpoint": self.cfg.listen, "pid": os.getpid(), "host": socket.gethostname(),
            "ticks": self.ticks, "garbage": self.garbage, "ignored": self.ignored}, sensing)

    def _on_info(self, query) -> None:
        params = str(query.parameters) if query.parameters is not None else ""
        sensing = any(p.split("=", 1)[0] == "sensing" and p.split("=", 1)[-1] not in ("0", "false")
                      for p in params.split(";") if p)
        query.reply(wire.world_info_key(self.cfg.run), wire.encode_info(self.info(sensing)))

    def _on_admin(self, query) -> None:
        """pause / resume the world clock."""
        try:
            req = wire.decode_admin(query.payload.to_bytes() if query.payload else b"")
            cmd = req["cmd"]
            if cmd == "fault_done":
                self.faults_done.add(req["index"])
                query.reply(wire.world_admin_key(self.cfg.run), wire.encode_admin_reply(True))
                return
            if (cmd == "pause") != self.paused:
                self.paused = cmd == "pause"
                self.event(cmd, None, "asked by " + str(req.get("by", "a client")))
            if self.paused and self.ticking:
                self.pause_waiters.append(query)  # answered once the tick in progress is done
                return
            reply = wire.encode_admin_reply(True, paused=self.paused, tick=self.core.tick)
        except wire.WireError as e:
            self.garbage += 1
            reply = wire.encode_admin_reply(False, error=str(e))
        query.reply(wire.world_admin_key(self.cfg.run), reply)

    def drain(self, pending: set[int] | None, timeout: float | None) -> bool:
        """Handle one inbox item, waiting up to `timeout` s; False when none came."""
        try:
            item = self.inbox.get(timeout=timeout) if timeout is None or timeout > 0 else self.inbox.get_nowait()
        except queue.Empty:
            return False
        self.handle(item, pending)
        return True

    # -- the run ---------------------------------------------------------------------------------
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
                raise TimeoutError(f"agents {', '.join(map(str, missing))} did not join within "
                                   f"{self.cfg.join_timeout} s")
            if self.cfg.progress and now - last_note > 5.0:
                last_note = now
                print(f"[world] waiting for agents {', '.join(map(str, missing))}: "
                      f"swarm agent --id N --connect {self.cfg.listen}", file=sys.stderr, flush=True)
            self.drain(None, 0.1)

    def publish_frames(self) -> set[int]:
        """Send every active agent its frame of this tick (the same numbers as WorldCore.frames)."""
        c = self.core
        if not self.engine.frames_exact():  # through the fault plan: partition, loss, delay, noise
            frames = self.engine.frames()
            for aid in c.active_ids():
                if aid not in frames:
                    self.book[aid].missed += 1  # its frame was lost
            for aid, frame in frames.items():
                self.sense_pub[aid].put(wire.encode_sense(frame))
            return set(frames)
        self.engine.mark_frames()  # the same numbers, encoded straight from the arrays
        sensed, bearing, rng = c.sensing()
        sent = set()
        tx, ty = c.target
        for aid in c.active_ids():
            k = c.index[aid]
            js = np.flatnonzero(sensed[k])
            target = (float(tx - c.x[k]), float(ty - c.y[k])) if c.is_leader[k] else None
            self.sense_pub[aid].put(wire.encode_sense_arrays(
                c.tick, c.time, aid, float(c.heading[k]), target, c.ids[js], bearing[k, js],
                c.heading[js], rng[k, js], c.hops[js]))
            sent.add(aid)
        return sent

    def record_and_step(self) -> None:
        self.engine.end_tick(observe=self.publish_truth)

    def publish_truth(self, u, force: bool = False) -> None:
        """Ground truth for observers, at most every TRUTH_PERIOD s (the world itself
        records every tick; observers only draw and report)."""
        now = time.monotonic()
        if not force and now - self.truth_sent < TRUTH_PERIOD:
            return
        c = self.core
        self.truth_sent = now
        try:
            self.truth_pub.put(wire.encode_truth(c.tick, c.time, c.ids, c.x, c.y, c.heading,
                                                 u, self.engine.out, c.state))
        except Exception:  # an observer's problem never stops the world
            pass

    def _wait(self, cond, timeout: float) -> bool:
        t_end = time.monotonic() + timeout
        while not cond():
            left = t_end - time.monotonic()
            if left <= 0:
                return False
            self.drain(None, min(left, 0.05))
        return True

    def carry_out(self, index: int, f) -> None:
        """A scripted fault is due at this tick. Network faults are the fault plan's job;
        process faults are asked of the launcher (it owns the processes) while the clock
        holds, and then, for kill and restart, the world waits to see the drop or the join."""
        if f.kind not in ("kill", "restart", "freeze", "thaw"):
            return
        t_hold = time.monotonic()
        self.control_pub.put(wire.encode_fault_notice(index, self.core.tick, fault_event(index, f)))
        if not self._wait(lambda: index in self.faults_done, 5.0):
            self.event("fault_skipped", f.agent, f"nobody carried out the {f.kind} (no launcher?)")
            return
        k = self.core.index[f.agent]
        # Hold the clock until the fault has taken effect, so that it lands on this tick as
        # in `swarm sim`: a killed process is dropped when its socket closes, a frozen one
        # when its link lease runs out; a restarted or thawed one rejoins.
        if f.kind in ("kill", "freeze"):
            if not self._wait(lambda: self.core.state[k] != ACTIVE, 3.0 if f.kind == "kill" else 6.0):
                self.event("fault_late", f.agent, f"the {f.kind} did not drop the agent in time")
        elif not self._wait(lambda: self.core.state[k] == ACTIVE, 20.0):
            self.event("fault_late", f.agent, f"the {f.kind} agent did not rejoin within 20 s")
        self.held += time.monotonic() - t_hold

    def lockstep_tick(self) -> None:
        pending = self.publish_frames()
        t_end = time.monotonic() + self.deadline
        while pending:
            left = t_end - time.monotonic()
            if left <= 0:
                for aid in pending:
                    self.book[aid].missed += 1
                self.engine.miss(len(pending))
                break
            self.drain(pending, left)
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
        for aid in self.core.active_ids():
            b = self.book[aid]
            stale = tick - b.last_cmd_tick if b.last_cmd_tick >= 0 else tick + 1
            b.stale_sum += stale
            b.stale_max = max(b.stale_max, stale)

    def run(self) -> int:
        self.t_start = time.monotonic()
        period = self.core.dt / self.cfg.time_scale
        last_note = time.monotonic()
        t0_ticks = time.monotonic()
        self.wait_for_agents()
        self.event("start", None, f"all {len(self.book)} agents joined; clock {self.cfg.clock}",
                   startup_s=time.monotonic() - self.t_start)
        t_next = time.monotonic() + period
        t0_ticks = time.monotonic()
        while self.core.tick < self.ticks:
            if self.paused:
                t_pause = time.monotonic()
                for q in self.pause_waiters:
                    q.reply(wire.world_admin_key(self.cfg.run),
                            wire.encode_admin_reply(True, paused=True, tick=self.core.tick))
                self.pause_waiters.clear()
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
            if self.cfg.progress and now - last_note > 2.0:
                last_note = now
                rate = self.core.tick / max(now - t0_ticks, 1e-9)
                print(f"[world] tick {self.core.tick}/{self.ticks} t={self.core.time:.2f}s {rate:.0f} ticks/s",
                      file=sys.stderr, flush=True)
        self.wall_ticks = time.monotonic() - t0_ticks
        return 0

    def agent_garbage(self, timeout: float = 1.0) -> dict[int, int]:
        """Malformed messages each live agent dropped (from its status), for the summary."""
        from swarm.contracts.transport import query_statuses

        counts: dict[int, int] = {}
        try:
            for aid, st in query_statuses(self.session, self.cfg.run, timeout).items():
                g = st.get("garbage")
                if aid in self.book and type(g) is int and g >= 0:
                    counts[aid] = g
        except Exception:  # the summary is written whatever the agents do
            pass
        return counts

    def finish(self) -> dict | None:
        """Record the final state row and write the results; returns the summary."""
        c = self.core
        if c.tick <= self.ticks and self.engine.rec.rows <= c.tick:
            self.engine.close()
            self.publish_truth(np.full(len(c.ids), np.nan), force=True)
        if self.cfg.out_dir is None:
            return None
        own = self.agent_garbage()
        agent_extra = {str(aid): agent_figures(b, c.tick, self.cfg.clock == "realtime", own.get(aid, 0))
                       for aid, b in self.book.items()}
        wall = getattr(self, "wall_ticks", None)
        result = self.engine.result({
            "engine": "up", "run": self.cfg.run, "endpoint": self.cfg.listen, "clock": self.cfg.clock,
            "time_scale": self.cfg.time_scale, "completed": self.stopped_by is None and c.tick >= self.ticks,
            "stopped_by_signal": self.stopped_by, "garbage_messages": self.garbage,
            "ignored_messages": self.ignored, "rejected_commands": c.rejected,
            "wall_time": wall, "ticks_per_second": (c.tick / wall) if wall else None,
        }, agent_extra)
        return write_run(result, self.cfg.out_dir)


def _raise_stop(signum, _frame):
    raise Stop(signum)


def run_world(cfg: WorldConfig) -> int:
    """Run a world to the end; exit code 0 when the run completed, 128+signal when stopped."""
    world = World(cfg)
    sock = socket_path(cfg.listen)
    if sock is not None and sock.exists():
        # A stale socket from a crashed run blocks listening; a live one belongs to a run.
        import socket as so

        s = so.socket(so.AF_UNIX, so.SOCK_STREAM)
        try:
            s.connect(str(sock))
            s.close()
            print(f"swarm world: {cfg.listen} is in use by another run", file=sys.stderr)
            return 2
        except OSError:
            sock.unlink(missing_ok=True)
    old = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    code = 0
    try:
        try:
            world._open()
        except Exception as e:  # zenoh.ZError: endpoint unusable
            print(f"swarm world: cannot listen on {cfg.listen}: {e}", file=sys.stderr)
            return 2
        if cfg.progress:
            print(f"[world] run {cfg.run} listening on {cfg.listen}", file=sys.stderr, flush=True)
        try:
            code = world.run()
        except Stop as s:
            world.stopped_by = s.signum
            code = 128 + s.signum
        except TimeoutError as e:
            print(f"swarm world: {e}", file=sys.stderr)
            code = 3
        except Exception:  # a bug: say so, but still write what was recorded and close cleanly
            import traceback

            traceback.print_exc()
            print("swarm world: internal error; results so far are written", file=sys.stderr)
            world.stopped_by = -1
            code = 1
        # Results are written even when stopped: nothing recorded is lost.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        world.finish()
        world._close()
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
        if sock is not None:
            sock.unlink(missing_ok=True)
    return code
