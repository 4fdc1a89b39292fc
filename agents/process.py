"""One agent process: one unicycle's brain on the bus.

Connects to the run's endpoint as a client, claims its id with the world's join query
(which also hands it its configuration: only the id is needed), declares its liveliness
token, and then answers each of its own sensor frames with a command. It never reads
ground truth. It publishes its status (role, out-neighbour, path to a leader and hops,
leader phase, counters) on change and a few times per second.

Callbacks only enqueue; the main thread decides and publishes. Exit codes:
0 the run ended, 3 refused (id live, unknown, no world), 4 the world vanished,
128+signal when stopped by a signal.
"""

from __future__ import annotations

import os
import queue
import signal
import socket
import sys
import time

from swarm.contracts import wire
from swarm.contracts.transport import open_client

STATUS_PERIOD = 0.2  # s of wall time between periodic status messages
EXIT_OK, EXIT_REFUSED, EXIT_WORLD_GONE = 0, 3, 4


class AgentExit(BaseException):  # also raised by signal handlers: never swallowed by `except Exception`
    def __init__(self, code: int, message: str = ""):
        super().__init__(message)
        self.code = code
        self.message = message


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def find_run(session, timeout: float = 2.0) -> str:
    """The one run whose world is reachable through `session`."""
    runs = sorted({wire.run_of_key(str(r.ok.key_expr))
                   for r in session.liveliness().get(wire.ANY_WORLD_ALIVE, timeout=timeout) if r.ok})
    if not runs:
        raise AgentExit(EXIT_REFUSED, "no world is running on this endpoint")
    if len(runs) > 1:
        raise AgentExit(EXIT_REFUSED, f"several runs on this endpoint ({', '.join(runs)}): pick one with --run")
    return runs[0]


def claim(session, run: str, agent_id: int, timeout: float = 5.0, spec: dict | None = None) -> dict:
    """Ask the world for agent_id (a new agent brings its spec); returns the reply or raises AgentExit."""
    req = wire.encode_join_request(agent_id, os.getpid(), socket.gethostname(), spec)
    replies = list(session.get(wire.world_join_key(run), payload=req, timeout=timeout))
    for r in replies:
        if r.ok is None:
            continue
        try:
            rep = wire.decode_join_reply(r.ok.payload.to_bytes())
        except wire.WireError as e:
            raise AgentExit(EXIT_REFUSED, f"agent {agent_id}: bad join reply: {e}") from None
        if not rep["ok"]:
            raise AgentExit(EXIT_REFUSED, f"agent {agent_id} refused: {rep['error']}")
        return rep
    raise AgentExit(EXIT_REFUSED, f"agent {agent_id}: no world answered on run {run!r}")


class AgentNode:
    """The process shell around an AgentBrain."""

    def __init__(self, session, run: str, agent_id: int, reply: dict, wait_world: bool):
        import zenoh

        from swarm.contracts.brain_config import BrainConf

        self.zenoh = zenoh
        self.session = session
        self.run = run
        self.id = agent_id
        self.wait_world = wait_world
        try:
            self.conf = BrainConf.from_json(reply.get("brain"))
            if self.conf.agent.id != agent_id:
                raise ValueError(f"agent.id: {self.conf.agent.id}, asked for {agent_id}")
            self.brain = self.new_brain()
        except (ValueError, AttributeError, TypeError) as e:
            raise AgentExit(EXIT_REFUSED, f"agent {agent_id}: unusable join reply: {e}") from None
        self.spec = self.conf.agent
        self.key = reply["key"]  # checked by wire.decode_join_reply
        if self.brain.is_leader:
            import agents.leader  # noqa: F401  (load numpy and the planner before the first frame)
        self.inbox: queue.SimpleQueue = queue.SimpleQueue()
        self.commands = 0
        self.garbage = 0
        self.last_tick = -1
        self.last = None  # last Decision
        self.world_alive = True
        self.status_sent = 0.0
        self.last_status: tuple | None = None
        self.stalled = 0.0  # s this process was not running before the current batch

    def new_brain(self):
        from agents.brain import AgentBrain

        c = self.conf
        return AgentBrain(c.agent, c.gains, c.sensing, c.dt, c.n_agents)

    def open(self) -> None:
        ses, run, put = self.session, self.run, self.inbox.put
        self.cmd_pub = ses.declare_publisher(wire.agent_key(run, self.id, "cmd"), express=True)
        self.status_pub = ses.declare_publisher(wire.agent_key(run, self.id, "status"))
        self.subs = [
            ses.declare_subscriber(wire.agent_key(run, self.id, "sense"),
                                   lambda s: put(("sense", s.payload.to_bytes()))),
            ses.declare_subscriber(wire.world_control_key(run),
                                   lambda s: put(("control", s.payload.to_bytes()))),
            ses.declare_subscriber(wire.agent_key(run, self.id, "ctl"),
                                   lambda s: put(("ctl", s.payload.to_bytes()))),
            ses.declare_queryable(wire.agent_key(run, self.id, "status"), lambda q: put(("query", q))),
            ses.liveliness().declare_subscriber(wire.world_alive_key(run),
                                                lambda s: put(("world", s.kind)), history=True),
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
            "id": self.id, "role": self.spec.role, "pid": os.getpid(), "host": socket.gethostname(),
            "out": None if d is None else d.out, "rooted": hops is not None, "hops": hops,
            "phase": None if d is None else d.phase,
            "fallback": False if d is None else d.fallback,
            "pinned": self.spec.follow,
            "u": None if d is None else d.u,
            "commands": self.commands, "last_tick": self.last_tick, "garbage": self.garbage,
        }

    def maybe_publish_status(self, force: bool = False) -> None:
        """Publish on change of what others rely on, and every STATUS_PERIOD s anyway."""
        now = time.monotonic()
        d = self.last
        key = (None, None, False) if d is None else (d.out, d.phase, d.fallback)
        key = (*key, self.hops())
        if force or key != self.last_status or now - self.status_sent >= STATUS_PERIOD:
            self.status_pub.put(wire.encode_status(self.status()))
            self.status_sent = now
            self.last_status = key

    # -- main loop -------------------------------------------------------------------------------
    def decode_frame(self, payload: bytes):
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

    def on_sense(self, frame) -> None:
        if frame.tick <= self.last_tick:
            return  # duplicate or old frame
        d = self.brain.decide(frame)
        self.cmd_pub.put(wire.encode_cmd(wire.Command(self.id, frame.tick, d.u, d.out, d.phase, d.hops,
                                                      self.key)))
        self.commands += 1
        self.last_tick = frame.tick
        if self.last is None or d.out != self.last.out or d.phase != self.last.phase:
            if self.last is not None and d.out != self.last.out:
                why = ("pinned out-neighbour not sensed, nearest used" if d.fallback
                       else f"selection = {self.conf.sensing.selection}")
                _log(f"[agent {self.id}] tick {frame.tick}: out-neighbour {self.last.out} -> {d.out} ({why})")
        self.last = d

    def on_world(self, kind) -> None:
        if kind == self.zenoh.SampleKind.PUT:
            if not self.world_alive:
                # A world came back (--wait-world): its ticks start afresh, and so does the brain.
                self.brain = self.new_brain()
                self.last_tick, self.last = -1, None
                _log(f"[agent {self.id}] the world is back; rejoining")
                self.key = claim(self.session, self.run, self.id).get("key", 0)
            self.world_alive = True
            return
        # A DELETE also comes when only our own link dropped (after a stall: SIGSTOP, a
        # starved CPU): ask again before concluding; a dead world is still noticed within ~0.6 s.
        if self._world_still_there(3.0 if self.stalled else 0.6):
            _log(f"[agent {self.id}] lost the world's token but the world is still there "
                 f"(stalled {self.stalled:.1f} s before): carrying on")
            return
        self.world_alive = False
        if not self.wait_world:
            raise AgentExit(EXIT_WORLD_GONE, f"agent {self.id}: the world of run {self.run} vanished; exiting "
                                             "(use --wait-world to wait for it)")
        _log(f"[agent {self.id}] the world vanished; waiting for it to come back")

    def _world_still_there(self, timeout: float) -> bool:
        """Wait up to `timeout` s for a link to the hub and the world's token on it."""
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            if list(self.session.info.routers_zid()):
                left = max(0.1, t_end - time.monotonic())
                replies = self.session.liveliness().get(wire.world_alive_key(self.run), timeout=min(left, 0.5))
                if any(r.ok is not None for r in replies):
                    return True
            time.sleep(0.05)
        return False

    def on_ctl(self, payload: bytes) -> None:
        """`swarm kill` from a machine that cannot signal this process: end abruptly."""
        try:
            name = wire.decode_ctl(payload)
        except wire.WireError:
            self.garbage += 1
            return
        sig = {"KILL": signal.SIGKILL, "TERM": signal.SIGTERM, "STOP": signal.SIGSTOP}[name]
        _log(f"[agent {self.id}] asked over zenoh to take SIG{name}")
        os.kill(os.getpid(), sig)

    def loop(self) -> int:
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
            while True:  # take whatever else is waiting: only the newest frame is answered
                try:
                    batch.append(self.inbox.get_nowait())
                except queue.Empty:
                    break
            newest = None
            for item in batch:
                kind = item[0]
                if kind == "sense":
                    frame = self.decode_frame(item[1])  # garbage after a frame must not hide it
                    if frame is not None and (newest is None or frame.tick >= newest.tick):
                        newest = frame
                elif kind == "world":
                    self.on_world(item[1])
                elif kind == "query":
                    item[1].reply(wire.agent_key(self.run, self.id, "status"), wire.encode_status(self.status()))
                elif kind == "ctl":
                    self.on_ctl(item[1])
                elif kind == "control":
                    try:
                        msg = wire.decode_control(item[1])
                    except wire.WireError:
                        self.garbage += 1
                        continue
                    if isinstance(msg, int):  # the end of the run (fault notices are the launcher's)
                        return EXIT_OK
            if newest is not None:
                self.on_sense(newest)
            self.maybe_publish_status()


def _raise_exit(signum, _frame):
    raise AgentExit(128 + signum, "")


def run_agent(agent_id: int, connect: str, run: str | None = None, wait_world: bool = False,
              spec: dict | None = None) -> int:
    """Entry point of an agent process; returns its exit code."""
    signal.signal(signal.SIGTERM, _raise_exit)
    signal.signal(signal.SIGINT, _raise_exit)
    try:
        session = open_client(connect)
    except Exception as e:
        _log(f"swarm agent {agent_id}: cannot connect to {connect}: {e}")
        return EXIT_REFUSED
    try:
        run = run or find_run(session)
        reply = claim(session, run, agent_id, spec=spec)
        node = AgentNode(session, run, agent_id, reply, wait_world)
        node.open()
        return node.loop()
    except AgentExit as e:
        if e.message:
            _log(f"swarm agent: {e.message}")
        return e.code
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        session.close()


def main(argv: list[str] | None = None) -> None:
    """Lean entry for launchers: `python -m agents.process ID ENDPOINT [RUN [SPEC_JSON]]` (no typer/rich)."""
    import json

    args = sys.argv[1:] if argv is None else argv
    spec = json.loads(args[3]) if len(args) > 3 else None
    sys.exit(run_agent(int(args[0]), args[1], args[2] if len(args) > 2 and args[2] else None, spec=spec))


if __name__ == "__main__":
    main()
