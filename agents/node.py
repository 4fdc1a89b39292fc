"""The agent process's shell around its brain (`AgentNode`): zenoh plumbing, frames in,
commands and status out (agents/process.py connects and claims the id first).

It declares the agent's keys and liveliness token, and then answers each of its own
sensor frames with a command. It never reads ground truth. It publishes its status
(role, out-neighbour, path to a leader and hops, leader phase, counters) on change and
a few times per second.

A sensor frame is answered in the zenoh callback that delivers it (decode, decide,
publish, under one lock), with no hand-over to another thread: that hand-over cost as
much CPU per tick as all the rest (benchmarks/bare_client.py --handler direct vs
callback). Frames that queued up while the process was stalled are each answered, in
order; the world keeps the newest. An exception there (a follower law that raises) is
handed to the main thread, which ends the process with its traceback. Everything else
only enqueues, and the main thread handles it: status (on change, at most every 50 ms,
and a few times per second), queries, control, the world's token. When the world stops
answering it waits up to --world-grace s for it (agents/world_link.py); a new world is
joined again, with a new brain.
"""

from __future__ import annotations

import logging
import os
import queue
import signal
import socket
import threading
import time
from typing import Any

from swarm.agents.brain import AgentBrain, Decision
from swarm.agents.joining import AgentExit, claim
from swarm.agents.world_link import NEW_WORLD, WorldLink
from swarm.contracts import wire
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import SensorFrame
from swarm.contracts.laws import LawError, check_trusted, trusted_laws
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import ExitCode

log = logging.getLogger(__name__)
STATUS_PERIOD = 0.2  # s of wall time between periodic status messages
STATUS_MIN_GAP = 0.05  # s: a change is published at once, but not more often than this (the
# rest wait for the next periodic one): a follower switching every tick sent one per tick
NONFINITE_NOTE_S = 5.0  # at most one log line per this many s about non-finite law outputs


class AgentNode:
    """The process shell around an AgentBrain."""

    def __init__(
        self,
        session: Any,
        run: str,
        agent_id: int,
        reply: dict,
        wait_world: bool,
        endpoint: str | None = None,
        world_grace: float = 0.0,
        trusted: set[str] | None = None,
    ) -> None:
        import zenoh  # lazy: only a process that opens a session loads zenoh's native library (not the fork server)

        self.zenoh = zenoh
        self.session = session
        self.run = run
        self.id = agent_id
        self.wait_world = wait_world
        try:
            brain = reply.get("brain")
            if not isinstance(brain, dict):
                raise TypeError("brain: expected an object")
            self.conf = BrainConf.from_json(brain)
            if self.conf.agent.id != agent_id:
                raise ValueError(f"agent.id: {self.conf.agent.id}, asked for {agent_id}")
        except (ValueError, AttributeError, TypeError) as e:
            raise AgentExit(ExitCode.REFUSED, f"agent {agent_id}: unusable join reply: {e}") from None
        try:
            for name in self.conf.law_names():
                check_trusted(name, trusted_laws() if trusted is None else trusted)
        except LawError as e:
            raise AgentExit(ExitCode.REFUSED, f"agent {agent_id}: {e}") from None
        try:
            self.brain = self.new_brain()
        except (ValueError, AttributeError, TypeError) as e:
            raise AgentExit(ExitCode.REFUSED, f"agent {agent_id}: unusable join reply: {e}") from None
        self.spec = self.conf.agent
        self.key = reply["key"]  # checked by wire.decode_join_reply
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.commands = 0
        self.garbage = 0
        self.last_tick = -1
        self.last_cmd: bytes | None = None  # the command answering frame `last_tick`
        self.last: Decision | None = None
        self.link = WorldLink(session, run, agent_id, endpoint, world_grace, wait_world)
        self.nonfinite_before = 0  # non-finite law outputs of earlier brains (a new world)
        self.nonfinite_noted = 0.0
        self.status_sent = 0.0
        self.last_status: tuple | None = None
        self.stalled = 0.0  # s this process was not running before the current batch
        self.lock = threading.Lock()  # the brain and its counters: frames are answered in zenoh's thread
        self.answering = True  # False while (re)claiming the id of a new world, and after a crash

    def new_brain(self) -> AgentBrain:
        return AgentBrain(self.conf)

    def open(self) -> None:
        ses, run, put = self.session, self.run, self.inbox.put
        self.cmd_pub = ses.declare_publisher(wire.agent_key(run, self.id, "cmd"), express=True)
        self.status_pub = ses.declare_publisher(wire.agent_key(run, self.id, "status"))
        self.subs = [
            ses.declare_subscriber(wire.agent_key(run, self.id, "sense"), self.on_sense_sample),
            ses.declare_subscriber(wire.world_control_key(run), lambda s: put(("control", s.payload.to_bytes()))),
            ses.declare_subscriber(wire.agent_key(run, self.id, "ctl"), lambda s: put(("ctl", s.payload.to_bytes()))),
            ses.declare_queryable(wire.agent_key(run, self.id, "status"), lambda q: put(("query", q))),
            ses.liveliness().declare_subscriber(
                wire.world_alive_key(run), lambda s: put(("world", s.kind)), history=True
            ),
        ]
        self.token = ses.liveliness().declare_token(wire.agent_key(run, self.id, "alive"))

    # -- status ----------------------------------------------------------------------------------
    def hops(self) -> int | None:
        """Hops to a leader: 0 for leaders, else 1 + what the out-neighbour advertised."""
        if self.brain.is_leader:
            return 0
        return None if self.last is None else self.last.hops

    def status(self) -> dict:
        d = self.last
        hops = self.hops()
        return {
            "id": self.id,
            "role": self.spec.role,
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "out": None if d is None else d.out,
            "rooted": hops is not None,
            "hops": hops,
            "phase": None if d is None else d.phase,
            "follow": None if d is None else d.follow,  # a FollowState (docs/reference/protocol.md#status)
            "fallback": False if d is None else d.fallback,
            "pinned": self.spec.follow,
            "u": None if d is None else d.u,
            "commands": self.commands,
            "last_tick": self.last_tick,
            "garbage": self.garbage,
            "nonfinite": self.nonfinite(),
            **self.brain.figures_of_selection(),
        }

    def nonfinite(self) -> int:
        """Ticks on which the law returned NaN or inf (its last turn rate held)."""
        return self.nonfinite_before + self.brain.nonfinite

    def status_key(self) -> tuple:
        """What others rely on in the status: a change is published at once."""
        d = self.last
        return (None, None, False, self.hops(), None) if d is None else (d.out, d.phase, d.fallback, d.hops, d.follow)

    def maybe_publish_status(self, force: bool = False) -> None:
        """Publish on change of what others rely on, and every STATUS_PERIOD s anyway."""
        now = time.monotonic()
        key = self.status_key()
        if force or key != self.last_status or now - self.status_sent >= STATUS_PERIOD:
            self.status_pub.put(wire.encode_status(self.status()))
            self.status_sent = now
            self.last_status = key

    # -- main loop -------------------------------------------------------------------------------
    def decode_frame(self, payload: bytes) -> SensorFrame | None:
        """The frame in `payload`, or None (counted as garbage) when it is not a valid one for us."""
        try:
            frame = wire.decode_sense(payload)
            if frame.agent != self.id:
                raise wire.WireError(f"frame for agent {frame.agent}")
            if self.brain.is_leader and frame.target is None:
                raise wire.WireError("leader frame without target")
        except wire.WireError:
            self.garbage += 1
            return None
        return frame

    def on_sense_sample(self, sample: Any) -> None:
        """zenoh's callback for a sensor frame: answer it here and now. A change of status
        wakes the main thread to publish it; an exception (a law that raises) is handed to
        the main thread, which ends the process with it, and no frame is answered after it."""
        try:
            payload = sample.payload.to_bytes()
            with self.lock:
                if not self.answering:
                    return
                frame = self.decode_frame(payload)
                if frame is not None and self.on_sense(frame) and time.monotonic() - self.status_sent >= STATUS_MIN_GAP:
                    self.inbox.put(("status", None))
        except BaseException as e:  # noqa: BLE001 (re-raised in the main thread)
            self.answering = False
            self.inbox.put(("crash", e))

    def on_sense(self, frame: SensorFrame) -> bool:
        """Answer `frame` (not an older or repeated one); True when what the status says
        changed (out-neighbour, phase, fallback, hops or follow state)."""
        if frame.tick <= self.last_tick:
            if frame.tick == self.last_tick and self.last_cmd is not None:
                self.cmd_pub.put(self.last_cmd)  # sent again by a world after its stall: the same answer
            return False  # duplicate or old frame: the brain does not step twice
        brain = self.brain
        bad = brain.nonfinite
        d = brain.decide(frame)
        if brain.nonfinite != bad and time.monotonic() - self.nonfinite_noted > NONFINITE_NOTE_S:
            self.nonfinite_noted = time.monotonic()
            log.info(
                "tick %d: the law %r returned %s; the last turn rate is held (%d so far)",
                frame.tick,
                self.conf.law_names()[0],
                brain.last_nonfinite,
                self.nonfinite(),
            )
        self.last_cmd = wire.encode_cmd_fields(self.id, frame.tick, d.u, d.out, d.phase, d.hops, self.key, d.follow)
        self.cmd_pub.put(self.last_cmd)
        self.commands += 1
        self.last_tick = frame.tick
        last, self.last = self.last, d
        if last is None:
            return True
        if d.out != last.out:
            why = (
                "pinned out-neighbour not sensed, nearest used"
                if d.fallback
                else f"selection = {self.conf.sensing.selection}"
            )
            log.info("tick %d: out-neighbour %s -> %s (%s)", frame.tick, last.out, d.out, why)
            return True
        return d.phase != last.phase or d.fallback != last.fallback or d.hops != last.hops or d.follow != last.follow

    def on_world(self, kind: Any) -> None:
        """The world's token came or went (agents/world_link.py says what that means)."""
        if kind != self.zenoh.SampleKind.PUT:
            self.link.on_delete(self.stalled)  # raises AgentExit when the world is gone
        elif self.link.on_put() == NEW_WORLD:
            # A new world (--wait-world, or one restarted meanwhile): its ticks start afresh,
            # and so does the brain. No frame is answered until the id is claimed again.
            with self.lock:
                self.answering = False
                self.nonfinite_before = self.nonfinite()
                self.brain = self.new_brain()
                self.last_tick, self.last, self.last_cmd = -1, None, None
            log.info("a world is back; rejoining")
            key = claim(self.session, self.run, self.id).get("key", 0)
            with self.lock:
                self.key, self.answering = key, True

    def on_ctl(self, payload: bytes) -> None:
        """`swarm kill` from a machine that cannot signal this process: end abruptly."""
        try:
            name = wire.decode_ctl(payload)
        except wire.WireError:
            with self.lock:
                self.garbage += 1
            return
        sig = {"KILL": signal.SIGKILL, "TERM": signal.SIGTERM, "STOP": signal.SIGSTOP}[name]
        log.info("asked over zenoh to take SIG%s", name)
        os.kill(os.getpid(), sig)

    def loop(self) -> int:
        with self.lock:
            self.maybe_publish_status(force=True)
        woke = time.monotonic()
        while True:
            try:
                batch = [self.inbox.get(timeout=STATUS_PERIOD)]
            except queue.Empty:
                batch = []
            now = time.monotonic()
            gap = now - woke - STATUS_PERIOD  # time beyond the longest wait: we were not running
            self.stalled = gap if gap > 0.5 else 0.0
            woke = now
            while True:  # take whatever else is waiting
                try:
                    batch.append(self.inbox.get_nowait())
                except queue.Empty:
                    break
            for item in batch:
                kind = item[0]
                if kind == "crash":
                    raise item[1]
                if kind == "world":
                    self.on_world(item[1])
                elif kind == "query":
                    with self.lock:
                        status = wire.encode_status(self.status())
                    answer(item[1], wire.agent_key(self.run, self.id, "status"), status)
                elif kind == "ctl":
                    self.on_ctl(item[1])
                elif kind == "control":
                    try:
                        msg = wire.decode_control(item[1])
                    except wire.WireError:
                        with self.lock:
                            self.garbage += 1
                        continue
                    if isinstance(msg, int):  # the end of the run (fault notices are the launcher's)
                        with self.lock:
                            self.answering = False
                        return ExitCode.OK  # the run ended
            self.link.check()  # raises AgentExit past the grace
            with self.lock:
                self.maybe_publish_status()
