"""The world's inbox: what it does with each message that reaches it.

Commands (admission by claim key, stale or duplicate ticks, fault-plan losses),
liveliness (join and drop), info queries (the live view) and admin queries (pause,
resume, fault done, agent exit); join queries are world/joins.py's. zenoh callbacks only
enqueue; these run on the world's main thread. A mixin of `World` (world/process.py),
whose state it reads and changes.

After the world itself has stalled (SIGSTOP, a starved CPU: more than STALL_S s without
reaching its inbox), every agent's link has timed out on the agent's side and comes back
at once: a token that vanishes then is given REJOIN_WAIT s to come back before the agent
is dropped, so a stalled world does not drop and rejoin every agent.
"""

from __future__ import annotations

import os
import queue
import socket
import sys
import time

from swarm.contracts import wire
from swarm.contracts.lifeline import exit_status
from swarm.contracts.transport import answer
from world.core import ACTIVE
from world.engine import LOST, REFUSED
from world.report import run_info

STALL_S = 0.8  # s the world's main thread may go without reaching its inbox (the link lease is 1 s)
REJOIN_WAIT = 2.0  # s a token lost just after a stall of the world has to come back
INBOX_MAX = 100_000  # messages waiting for the main thread; commands and queries past it are dropped


class Inbox:
    inbox_dropped = 0  # messages dropped by the callbacks with the inbox full
    drained_at = 0.0  # monotonic s the main thread last came back from its inbox
    stall_seen = -1e9  # monotonic s a stall of the world itself was last noticed
    lost_after_stall: dict | None = None  # agent -> monotonic s its drop is due (token lost after a stall)

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

    def _garbage_on(self, aid: int | None) -> None:
        """A malformed message: the world's count, and the agent's whose key it came on."""
        self.garbage += 1
        b = self.book.get(aid) if aid is not None else None
        if b is not None:
            b.garbage += 1

    def _on_cmd(self, key: str, payload: bytes, pending: set[int] | None) -> None:
        aid = None
        try:
            aid = wire.agent_of_key(key)
            cmd = wire.decode_cmd(payload)
            if cmd.agent != aid:
                raise wire.WireError(f"command for agent {cmd.agent} on agent {aid}'s key")
        except wire.WireError:
            self._garbage_on(aid)
            return
        if cmd.out is not None and (cmd.out == aid or cmd.out not in self.core.index):
            self._garbage_on(aid)
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
        waiting = self.lost_after_stall if self.lost_after_stall is not None else {}
        if kind == zenoh.SampleKind.PUT:
            if waiting.pop(aid, None) is not None and self.cfg.progress:
                print(f"[world] agent {aid}: its link is back after the world's stall", file=sys.stderr, flush=True)
            if self.core.state[k] == ACTIVE:
                return
            b.claim_until = 0.0  # the key stays: a thawed process rejoins with the claim it had
            b.last_cmd_tick = self.core.tick - 1
            self.engine.join(aid, f"liveliness token appeared (pid {b.pid} on {b.host})", b.joins > 0,
                             pid=b.pid, host=b.host)
            b.joins += 1
        elif self.core.state[k] == ACTIVE and time.monotonic() - self.stall_seen < REJOIN_WAIT:
            self.lost_after_stall = {**waiting, aid: time.monotonic() + REJOIN_WAIT}
        else:
            self._drop(aid, pending)

    def _drop(self, aid: int, pending: set[int] | None, why: str = "liveliness token lost") -> None:
        if self.engine.drop(aid, why) is not None:
            self.book[aid].drops += 1
            if pending is not None:
                pending.discard(aid)

    def _due_drops(self, pending: set[int] | None) -> None:
        """Tokens lost after a stall of the world that did not come back in time: dropped now."""
        now = time.monotonic()
        for aid, due in list((self.lost_after_stall or {}).items()):
            if now >= due:
                del self.lost_after_stall[aid]
                self._drop(aid, pending, f"liveliness token lost (not back {REJOIN_WAIT:g} s after the world's stall)")

    def _note_inbox_dropped(self) -> None:
        """Messages the zenoh callbacks dropped because the inbox was full (counted there)."""
        first = "inbox" not in self.over_limit
        self.over_limit["inbox"] = self.inbox_dropped
        if first:
            self.event("limit", None, f"more than {INBOX_MAX} messages waiting: commands and queries dropped",
                       limit="inbox")

    def enqueue(self, item, droppable: bool = True) -> None:
        """What a zenoh callback does with a message: queue it for the main thread; past
        INBOX_MAX waiting, a command or a query is dropped and counted (liveliness never)."""
        if droppable and self.inbox.qsize() >= INBOX_MAX:
            self.inbox_dropped += 1
            return
        self.inbox.put(item)

    def limited(self, what: str, reason: str) -> None:
        """Something over a limit: counted each time, one event the first time."""
        self.over_limit[what] = self.over_limit.get(what, 0) + 1
        if self.over_limit[what] == 1:
            self.event("limit", None, reason, limit=what)

    def info(self, sensing: bool = False) -> dict:
        """The world's view of the run, for the CLI (`swarm agents`, `graph`, `watch`)."""
        return run_info(self.engine, self.book, {
            "run": self.cfg.run, "scenario": self.core.scenario.name, "clock": self.cfg.clock,
            "paused": self.paused, "endpoint": self.cfg.listen, "pid": os.getpid(), "host": socket.gethostname(),
            "ticks": self.ticks, "started": self.started, "garbage": self.garbage, "ignored": self.ignored,
            "over_limit": self.over_limit, "added_ids": [self.cfg.scenario.added_id_range.start,
                                                         self.cfg.scenario.added_id_range.stop - 1],
            "max_added": self.cfg.scenario.added_agents_cap, "added": len(self.book) - len(self.cfg.scenario.ids)},
            sensing)

    def _on_info(self, query) -> None:
        params = str(query.parameters) if query.parameters is not None else ""
        sensing = any(p.split("=", 1)[0] == "sensing" and p.split("=", 1)[-1] not in ("0", "false")
                      for p in params.split(";") if p)
        answer(query, wire.world_info_key(self.cfg.run), wire.encode_info(self.info(sensing)))

    def _on_admin(self, query) -> None:
        """pause / resume the world clock; fault done and agent exit (from the launcher)."""
        try:
            req = wire.decode_admin(query.payload.to_bytes() if query.payload else b"")
            cmd = req["cmd"]
            if cmd == "fault_done":
                self.faults_done.add(req["index"])
                answer(query, wire.world_admin_key(self.cfg.run), wire.encode_admin_reply(True))
                return
            if cmd == "agent_exit":
                self._on_agent_exit(req)
                answer(query, wire.world_admin_key(self.cfg.run), wire.encode_admin_reply(True))
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
        answer(query, wire.world_admin_key(self.cfg.run), reply)

    def _on_agent_exit(self, req: dict) -> None:
        """The launcher saw an agent process it started exit by itself: a `crash` event (a
        failure of the agent: the run does not count as converged) or an `exit` event."""
        aid = req["id"]
        if aid not in self.core.index:
            raise wire.WireError(f"agent_exit: agent {aid} is not in the run")
        status = exit_status(req["code"])
        if self.lost_after_stall and self.lost_after_stall.pop(aid, None) is not None:
            self._drop(aid, None, "liveliness token lost (its process exited)")
        self.event("crash" if req["crash"] else "exit", aid,
                   f"process {req['pid']} ended ({status})" + (f": {req['cause']}" if req["cause"] else ""),
                   code=req["code"], pid=req["pid"], cause=req["cause"], log=req["log"])

    def drain(self, pending: set[int] | None, timeout: float | None) -> bool:
        """Handle one inbox item, waiting up to `timeout` s; False when none came."""
        t0 = time.monotonic()
        if self.drained_at and t0 - self.drained_at > STALL_S:  # away from the inbox too long
            self.stall_seen = t0
        try:
            item = self.inbox.get(timeout=timeout) if timeout is None or timeout > 0 else self.inbox.get_nowait()
        except queue.Empty:
            item = None
        self.drained_at = time.monotonic()
        if self.inbox_dropped:
            self._note_inbox_dropped()
        if timeout is not None and self.drained_at - t0 > max(timeout, 0.0) + STALL_S:
            self.stall_seen = self.drained_at  # stopped while waiting
        if self.lost_after_stall:
            self._due_drops(pending)
        if item is None:
            return False
        self.handle(item, pending)
        get = self.inbox.get_nowait
        while pending:  # the commands that came meanwhile, without a clock read each
            try:
                item = get()
            except queue.Empty:
                break
            self.handle(item, pending)
        return True
