"""The world's inbox: what it does with each message that reaches it.

Commands (admission by claim key, stale or duplicate ticks, fault-plan losses),
liveliness (join and drop), info queries (the live view) and admin queries (pause,
resume); join queries are world/joins.py's. zenoh callbacks only
enqueue; these run on the world's main thread. A mixin of `World` (world/process.py),
whose state it reads and changes.

After the world itself has stalled (SIGSTOP, a starved CPU: more than STALL_S s without
reaching its inbox), every agent's link has timed out on the agent's side and comes back
at once: a token that vanishes then is given REJOIN_WAIT s to come back before the agent
is dropped, so a stalled world does not drop and rejoin every agent. In a lockstep run, any
token lost not by a scripted fault is held LINK_GRACE s the same way (the clock waits for
it), unless the launcher reports the agent's process ended: a link lease that ran out under
load is ridden out, and the run stays what `swarm sim` gives.

Fairness: no identity's messages may cost another's (how messages wait: world/fairness.py).
An agent's join, rejoin and drop events past CHURN_EVENTS (world/roster.py) are counted,
not written, so one identity's churn cannot grow the run's record without bound. The
launcher's reports (agent exits, faults done) are world/reports.py's.
"""

from __future__ import annotations

import os
import queue
import socket
import sys
import time

from swarm.contracts import wire
from swarm.contracts.transport import answer
from swarm.world.core import ACTIVE
from swarm.world.engine import LOST, REFUSED
from swarm.world.fairness import Fairness
from swarm.world.report import run_info
from swarm.world.reports import Reports
from swarm.world.roster import CHURN_EVENTS

STALL_S = 0.8  # s the world's main thread may go without reaching its inbox (the link lease is 1 s)
REJOIN_WAIT = 2.0  # s a token lost just after a stall of the world has to come back
LINK_GRACE = 5.0  # s a token lost in a lockstep run has to come back (`rides_out`)


class Inbox(Fairness, Reports):
    drained_at = 0.0  # monotonic s the main thread last came back from its inbox
    stall_seen = -1e9  # monotonic s a stall of the world itself was last noticed
    disturbed = 0  # stalls of the world and links back: each sends the tick's frames again (lockstep)
    lost_after_stall: dict | None = None  # agent -> monotonic s its drop is due (token lost after a stall)

    def handle(self, item, pending: set[int] | None) -> None:
        kind = item[0]
        if kind == "cmd":
            self._on_cmd(item[1], item[2], pending, item[3] if len(item) > 3 else None)
        elif kind == "alive":
            self._on_alive(item[1], item[2] if len(item) > 2 else self._latest_alive(item[1]), pending)
        elif kind == "join":
            self._on_join(item[1])
        elif kind == "info":
            self._on_info(item[1])
        elif kind == "admin":
            self._on_admin(item[1])
        elif kind == "supervise":
            self._on_supervise(item[1])

    def _garbage_on(self, aid: int | None) -> None:
        """A malformed message: the world's count, and the agent's whose key it came on."""
        self.garbage += 1
        b = self.book.get(aid) if aid is not None else None
        if b is not None:
            b.garbage += 1

    def _on_cmd(self, key: str, payload: bytes, pending: set[int] | None, decoded=None) -> None:
        """`decoded`: (agent id, command) as the callback decoded them (world/fairness.py);
        None: decoded here (a malformed one is garbage)."""
        if decoded is None:
            aid = None
            try:
                aid = wire.agent_of_key(key)
                cmd = wire.decode_cmd(payload)
                if cmd.agent != aid:
                    raise wire.WireError(f"command for agent {cmd.agent} on agent {aid}'s key")
            except wire.WireError:
                self._garbage_on(aid)
                return
        else:
            aid, cmd = decoded
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
            self.count_rogue(aid, 1)
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

    def count_rogue(self, aid: int, n: int) -> None:
        """`n` commands on agent `aid`'s key without its owner's claim key: counted, and a
        `rogue` event at most once a second."""
        b = self.book[aid]
        b.rogue += n
        if time.monotonic() - b.rogue_noted > 1.0:
            b.rogue_noted = time.monotonic()
            self.event("rogue", aid, f"command without the owner's claim key ignored ({b.rogue} so far)")

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
            if waiting.pop(aid, None) is not None:
                self.disturbed += 1  # lockstep: its frame goes again (world/clock.py)
                if self.cfg.progress:
                    print(f"[world] agent {aid}: its link is back", file=sys.stderr, flush=True)
            if self.core.state[k] == ACTIVE:
                return
            b.claim_until = 0.0  # the key stays: a thawed process rejoins with the claim it had
            b.last_cmd_tick = self.core.tick - 1
            self.engine.join(
                aid,
                f"liveliness token appeared (pid {b.pid} on {b.host})",
                b.joins > 0,
                quiet=self._churn_quiet(aid),
                pid=b.pid,
                host=b.host,
            )
            b.joins += 1
            self.unscripted(aid, "joined")
        elif self.core.state[k] == ACTIVE and time.monotonic() - self.stall_seen < REJOIN_WAIT:
            self.lost_after_stall = {**waiting, aid: time.monotonic() + REJOIN_WAIT}
        elif self.core.state[k] == ACTIVE and self.rides_out(aid):
            self.lost_after_stall = {**waiting, aid: time.monotonic() + LINK_GRACE}
        else:
            self._drop(aid, pending)

    def rides_out(self, aid: int) -> bool:
        """Lockstep: a token lost in the started run, not by a scripted fault, is given
        LINK_GRACE s to come back (a link lease run out under load; an agent host's link)
        before the agent is dropped; the launcher's exit report of its process drops it at
        once (`_on_agent_exit`). The clock waits for it meanwhile."""
        return (
            self.cfg.clock == "lockstep"
            and self.started
            and aid != self.carrying
            and aid not in (self.exit_reports or {})
        )  # its exit was reported first: no link to wait for

    def _churn_quiet(self, aid: int) -> bool:
        """One more join, rejoin or drop of `aid`: True when it is past CHURN_EVENTS (counted,
        not written; one `limit` event says so)."""
        b = self.book[aid]
        b.churn += 1
        if b.churn <= CHURN_EVENTS:
            return False
        if b.churn == CHURN_EVENTS + 1:
            self.event(
                "limit",
                aid,
                f"more than {CHURN_EVENTS} joins and drops: later ones are counted "
                "(churn_events_unwritten), not written",
                limit="churn",
            )
        b.churn_unwritten += 1
        self.over_limit["churn"] = self.over_limit.get("churn", 0) + 1
        return True

    def _drop(self, aid: int, pending: set[int] | None, why: str = "liveliness token lost") -> None:
        if self.core.state[self.core.index[aid]] != ACTIVE:
            return
        self.unscripted(aid, "dropped")
        if self.engine.drop(aid, why, quiet=self._churn_quiet(aid)) is not None:
            self.book[aid].drops += 1
            if pending is not None:
                pending.discard(aid)

    def _due_drops(self, pending: set[int] | None) -> None:
        """Tokens held (lost after a stall of the world, or ridden out in lockstep) that did not
        come back in time: dropped now."""
        now = time.monotonic()
        for aid, due in list((self.lost_after_stall or {}).items()):
            if now >= due:
                del self.lost_after_stall[aid]
                self._drop(aid, pending, "liveliness token lost (and not back in time)")

    def limited(self, what: str, reason: str) -> None:
        """Something over a limit: counted each time, one event the first time."""
        self.over_limit[what] = self.over_limit.get(what, 0) + 1
        if self.over_limit[what] == 1:
            self.event("limit", None, reason, limit=what)

    def info(self, sensing: bool = False) -> dict:
        """The world's view of the run, for the CLI (`swarm agents`, `graph`, `watch`)."""
        return run_info(
            self.engine,
            self.book,
            {
                "run": self.cfg.run,
                "scenario": self.core.scenario.name,
                "clock": self.cfg.clock,
                "paused": self.paused,
                "endpoint": self.cfg.listen,
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "ticks": self.ticks,
                "started": self.started,
                "garbage": self.garbage,
                "ignored": self.ignored,
                "over_limit": self.over_limit,
                "added_ids": [self.cfg.scenario.added_id_range.start, self.cfg.scenario.added_id_range.stop - 1],
                "max_added": self.cfg.scenario.added_agents_cap,
                "added": len(self.book) - len(self.cfg.scenario.ids),
            },
            sensing,
        )

    def _on_info(self, query) -> None:
        params = str(query.parameters) if query.parameters is not None else ""
        sensing = any(
            p.split("=", 1)[0] == "sensing" and p.split("=", 1)[-1] not in ("0", "false")
            for p in params.split(";")
            if p
        )
        answer(query, wire.world_info_key(self.cfg.run), wire.encode_info(self.info(sensing)))

    def _on_admin(self, query) -> None:
        """pause / resume the world clock (the operator's)."""
        try:
            req = wire.decode_admin(query.payload.to_bytes() if query.payload else b"", wire.ADMIN_CMDS)
            cmd = req["cmd"]
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

    def drain(self, pending: set[int] | None, timeout: float | None) -> bool:
        """Handle one inbox item, waiting up to `timeout` s; False when none came."""
        t0 = time.monotonic()
        if self.drained_at and t0 - self.drained_at > STALL_S:  # away from the inbox too long
            self.stall_seen = t0
            self.disturbed += 1
        try:
            item = self.inbox.get(timeout=timeout) if timeout is None or timeout > 0 else self.inbox.get_nowait()
        except queue.Empty:
            item = None
        self.drained_at = time.monotonic()
        if item is not None:
            self._taken(item)
        if self.fair.flooded or self.fair.rogue:
            self._note_inbox_dropped()
        if timeout is not None and self.drained_at - t0 > max(timeout, 0.0) + STALL_S:
            self.stall_seen = self.drained_at  # stopped while waiting
            self.disturbed += 1
        if self.lost_after_stall:
            self._due_drops(pending)
        if self.exit_reports:
            self._due_exit_reports()
        if item is None:
            return False
        self.handle(item, pending)
        get = self.inbox.get_nowait
        while pending:  # the commands that came meanwhile, without a clock read each
            try:
                item = get()
            except queue.Empty:
                break
            self._taken(item)
            self.handle(item, pending)
        return True
