"""The world's inbox: what it does with each message that reaches it.

Commands (admission by claim key, stale or duplicate ticks, fault-plan losses),
liveliness (join and drop), info queries (the live view) and admin queries (pause,
resume, stop: world/inbox_admin.py, `AdminQueries`); join queries are world/joins.py's,
the launcher's reports world/reports.py's.
zenoh callbacks only enqueue (world/fairness.py, `FairQueue`); `Inbox` takes the messages
off that queue on the world's main thread, with the run's state (world/state.py) and the
joins in its constructor.

After the world itself has stalled (SIGSTOP, a starved CPU: more than STALL_S s without
reaching its inbox), every agent's link has timed out on the agent's side and comes back
at once: a token that vanishes then is given REJOIN_WAIT s to come back before the agent
is dropped, so a stalled world does not drop and rejoin every agent. In a lockstep run, any
token lost not by a scripted fault is held LINK_GRACE s the same way (the clock waits for
it), unless the launcher reports the agent's process ended: a link lease that ran out under
load is ridden out, and the run stays what `swarm sim` gives.

Fairness: no identity's messages may cost another's (how messages wait: world/fairness.py).
An agent's join, rejoin and drop events past CHURN_EVENTS (world/roster.py) are counted,
not written, so one identity's churn cannot grow the run's record without bound. The same
for the operator's pause and resume (only the operator and the launcher may query
world/admin): each takes effect, but their events are written within a budget (ADMIN_RATE a
second, ADMIN_BURST at once); those beyond it are counted (`over_limit.admin`, one `limit`
event the first time), and once the budget allows, one event says the clock's state then
and how many requests it stands for. A run is stopped once: a second stop is answered, not
recorded. Who asked (`by`) comes bounded and escaped from the wire's decoder
(swarm/contracts/freetext.py).
"""

from __future__ import annotations

import logging
import os
import socket
import time
from typing import Any

import zenoh

from swarm.contracts import wire
from swarm.contracts.freetext import Budget
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import AgentState, EventKind
from swarm.world.engine import LOST, REFUSED
from swarm.world.fairness import INBOX_MAX, PER_KEY_MAX, FairQueue
from swarm.world.inbox_admin import ADMIN_BURST, ADMIN_RATE, AdminQueries
from swarm.world.inbox_messages import (
    Admin,
    Command,
    Garbage,
    Ignored,
    Info,
    Item,
    Join,
    Rejection,
    Rogue,
    Supervise,
    Token,
    Verdict,
)
from swarm.world.joins import Joins
from swarm.world.report import run_info
from swarm.world.reports import Reports
from swarm.world.roster import CHURN_EVENTS
from swarm.world.state import RunState

log = logging.getLogger(__name__)

STALL_S = 0.8  # s the world's main thread may go without reaching its inbox (the link lease is 1 s)
REJOIN_WAIT = 2.0  # s a token lost just after a stall of the world has to come back
LINK_GRACE = 5.0  # s a token lost in a lockstep run has to come back (`rides_out`)

ACTIVE = AgentState.ACTIVE


class Inbox(AdminQueries):
    """The main thread's side of the world's inbox: `drain` takes messages off `queue` and
    handles each. `joins` answers join queries; `reports` (made here) the launcher's."""

    def __init__(self, state: RunState, queue: FairQueue, joins: Joins):
        self.state = state
        self.queue = queue
        self.classifier = queue.classifier  # the callbacks' own checks (world/inbox_messages.py)
        self.admit = self.classifier.admit
        self.joins = joins
        self.reports = Reports(state, self.release_held)
        self.drained_at = 0.0  # monotonic s the main thread last came back from its inbox
        self.stall_seen = -1e9  # monotonic s a stall of the world itself was last noticed
        self.disturbed = 0  # stalls of the world and links back: each sends the tick's frames again (lockstep)
        self.lost_after_stall: dict[int, float] = {}  # agent -> monotonic s its drop is due (token held)
        self.admin_budget = Budget(ADMIN_RATE, ADMIN_BURST)  # pause/resume events written
        self.admin_clock = time.monotonic  # the budget's clock (a test's own)
        self.admin_held = 0  # pause/resume requests since the last such event, not written
        self.admin_by = ""  # who asked the last of those
        self.paused_written = False  # the clock's state the last pause/resume event wrote
        self.stop_taken: int | None = None  # the tick a stop was asked at (a second one is not recorded)

    def handle(self, item: Item, pending: set[int] | None) -> None:
        """One item taken off the queue (world/inbox_messages.py), by its type."""
        match item:
            case Command():  # decoded in the callback: admitted against the run's state now
                self.latch(self.admit(item), pending)
            case Token(key):
                self.on_alive(key, self.queue.latest_alive(key), pending)
            case Garbage():
                self.reject(item)
            case Join(query):
                self.joins.on_join(query)
            case Info(query):
                self.on_info(query)
            case Admin(query):
                self.on_admin(query)
            case Supervise(query):
                self.reports.on_supervise(query)

    def reject(self, why: Rejection) -> None:
        """A message the run does not take (world/inbox_messages.py), counted: garbage to the
        world and the agent whose key it came on, ignored to the world, rogue to the agent."""
        match why:
            case Garbage(aid=aid):
                self._garbage_on(aid)
            case Ignored():
                self.state.ignored += 1
            case Rogue(aid=aid):
                self.count_rogue(aid, 1)

    def _garbage_on(self, aid: int | None) -> None:
        """A malformed message: the world's count, and the agent's whose key it came on."""
        st = self.state
        st.garbage += 1
        b = st.book.get(aid) if aid is not None else None
        if b is not None:
            b.garbage += 1

    def on_cmd(self, key: str, payload: bytes, pending: set[int] | None) -> None:
        """A command sample handled at once, not through the queue: classified here."""
        self.latch(self.classifier.classify(key, payload), pending)

    def latch(self, verdict: Verdict, pending: set[int] | None) -> None:
        """A command the run takes goes to the engine (a fault-plan loss holds the last one);
        anything else is counted (`reject`). `pending`: the agents whose command for this
        tick is awaited (lockstep), less this one once its command is in."""
        if not isinstance(verdict, Command):
            self.reject(verdict)
            return
        st = self.state
        _, aid, cmd = verdict
        b = st.book[aid]
        done = st.engine.command(aid, cmd.tick, cmd.u, cmd.out, cmd.hops, cmd.follow)
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
        if pending is not None and cmd.tick == st.engine.core.tick:
            pending.discard(aid)

    def count_rogue(self, aid: int, n: int) -> None:
        """`n` commands on agent `aid`'s key without its owner's claim key: counted, and a
        `rogue` event at most once a second."""
        b = self.state.book[aid]
        b.rogue += n
        if time.monotonic() - b.rogue_noted > 1.0:
            b.rogue_noted = time.monotonic()
            self.state.event(EventKind.ROGUE, aid, f"command without the owner's claim key ignored ({b.rogue} so far)")

    def on_alive(self, key: str, kind: zenoh.SampleKind, pending: set[int] | None) -> None:
        st, core = self.state, self.state.core
        aid = self.classifier.token(key)
        if not isinstance(aid, int):
            self.reject(aid)
            return
        k = core.index[aid]
        b = st.book[aid]
        waiting = self.lost_after_stall
        if kind == zenoh.SampleKind.PUT:
            if waiting.pop(aid, None) is not None:
                self.disturbed += 1  # lockstep: its frame goes again (world/clock.py)
                if st.cfg.progress:
                    log.info("agent %d: its link is back", aid)
            if core.state[k] == ACTIVE:
                return
            b.claim_until = 0.0  # the key stays: a thawed process rejoins with the claim it had
            b.last_cmd_tick = core.tick - 1
            st.engine.join(
                aid,
                f"liveliness token appeared (pid {b.pid} on {b.host})",
                b.joins > 0,
                quiet=self._churn_quiet(aid),
                pid=b.pid,
                host=b.host,
            )
            b.joins += 1
            st.unscripted(aid, "joined")
        elif core.state[k] == ACTIVE and time.monotonic() - self.stall_seen < REJOIN_WAIT:
            self.lost_after_stall = {**waiting, aid: time.monotonic() + REJOIN_WAIT}
        elif core.state[k] == ACTIVE and self.rides_out(aid):
            self.lost_after_stall = {**waiting, aid: time.monotonic() + LINK_GRACE}
        else:
            self._drop(aid, pending)

    def rides_out(self, aid: int) -> bool:
        """Lockstep: a token lost in the started run, not by a scripted fault, is given
        LINK_GRACE s to come back (a link lease run out under load; an agent host's link)
        before the agent is dropped; the launcher's exit report of its process drops it at
        once (world/reports.py). The clock waits for it meanwhile."""
        st = self.state
        return (
            st.cfg.clock == "lockstep" and st.started and aid != st.carrying and aid not in self.reports.exit_reports
        )  # its exit was reported first: no link to wait for

    def release_held(self, aid: int) -> None:
        """Agent `aid`'s process is known to be gone (the launcher said so): a lost token of
        its being held (`lost_after_stall`) is a drop now."""
        if self.lost_after_stall and self.lost_after_stall.pop(aid, None) is not None:
            self._drop(aid, None, "liveliness token lost (its process exited)")

    def _churn_quiet(self, aid: int) -> bool:
        """One more join, rejoin or drop of `aid`: True when it is past CHURN_EVENTS (counted,
        not written; one `limit` event says so)."""
        st = self.state
        b = st.book[aid]
        b.churn += 1
        if b.churn <= CHURN_EVENTS:
            return False
        if b.churn == CHURN_EVENTS + 1:
            st.event(
                EventKind.LIMIT,
                aid,
                f"more than {CHURN_EVENTS} joins and drops: later ones are counted "
                "(churn_events_unwritten), not written",
                limit="churn",
            )
        b.churn_unwritten += 1
        st.over_limit["churn"] = st.over_limit.get("churn", 0) + 1
        return True

    def _drop(self, aid: int, pending: set[int] | None, why: str = "liveliness token lost") -> None:
        st, core = self.state, self.state.core
        if core.state[core.index[aid]] != ACTIVE:
            return
        st.unscripted(aid, "dropped")
        if st.engine.drop(aid, why, quiet=self._churn_quiet(aid)) is not None:
            st.book[aid].drops += 1
            if pending is not None:
                pending.discard(aid)

    def _due_drops(self, pending: set[int] | None) -> None:
        """Tokens held (lost after a stall of the world, or ridden out in lockstep) that did not
        come back in time: dropped now."""
        now = time.monotonic()
        for aid, due in list(self.lost_after_stall.items()):
            if now >= due:
                del self.lost_after_stall[aid]
                self._drop(aid, pending, "liveliness token lost (and not back in time)")

    def note_dropped(self) -> None:
        """Messages the zenoh callbacks dropped (world/fairness.py): counted to the agent whose
        key they came on, and one `limit` event per key the first time; rogue commands the
        callbacks counted, counted here (`count_rogue`)."""
        st, fair = self.state, self.queue
        flooded, rogue = fair.take_dropped()
        for aid, n in rogue.items():
            self.count_rogue(aid, n)
        if not flooded:
            return
        st.over_limit["inbox"] = fair.dropped
        for key, n in flooded.items():
            kid: int | None
            try:
                kid = wire.agent_of_key(key)
            except wire.WireError:
                kid = None
            b = st.book.get(kid) if kid is not None else None
            if b is not None:
                b.flooded += n
            if key not in fair.noted:
                fair.noted.add(key)
                st.event(
                    EventKind.LIMIT,
                    kid,
                    f"more than {PER_KEY_MAX} messages waiting on {key} (or {INBOX_MAX} in "
                    "all): its messages dropped, no one else's",
                    limit="inbox",
                    key=key,
                )

    def info(self, sensing: bool = False) -> dict[str, Any]:
        """The world's view of the run, for the CLI (`swarm agents`, `graph`, `watch`), with
        where its results go (`out`, absolute; None without --out): `swarm spawn` puts an
        agent's log in its `logs/`."""
        st = self.state
        cfg = st.cfg
        d = run_info(
            st.engine,
            st.book,
            {
                "run": cfg.run,
                "scenario": st.core.scenario.name,
                "clock": cfg.clock,
                "paused": st.paused,
                "endpoint": cfg.listen,
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "ticks": st.ticks,
                "started": st.started,
                "garbage": st.garbage,
                "ignored": st.ignored,
                "over_limit": st.over_limit,
                "added_ids": [cfg.scenario.added_id_range.start, cfg.scenario.added_id_range.stop - 1],
                "max_added": cfg.scenario.added_agents_cap,
                "added": len(st.book) - len(cfg.scenario.ids),
            },
            sensing,
        )
        d["out"] = str(cfg.out_dir.resolve()) if cfg.out_dir is not None else None
        return d

    def on_info(self, query: Any) -> None:
        params = str(query.parameters) if query.parameters is not None else ""
        sensing = any(
            p.split("=", 1)[0] == "sensing" and p.split("=", 1)[-1] not in ("0", "false")
            for p in params.split(";")
            if p
        )
        answer(query, wire.world_info_key(self.state.cfg.run), wire.encode_info(self.info(sensing)))

    def drain(self, pending: set[int] | None, timeout: float | None) -> bool:
        """Handle one inbox item, waiting up to `timeout` s; False when none came."""
        t0 = time.monotonic()
        if self.drained_at and t0 - self.drained_at > STALL_S:  # away from the inbox too long
            self.stall_seen = t0
            self.disturbed += 1
        item = self.queue.get(timeout)
        self.drained_at = time.monotonic()
        if item is not None:
            self.queue.taken(item)
        if self.queue.has_dropped():
            self.note_dropped()
        if timeout is not None and self.drained_at - t0 > max(timeout, 0.0) + STALL_S:
            self.stall_seen = self.drained_at  # stopped while waiting
            self.disturbed += 1
        if self.lost_after_stall:
            self._due_drops(pending)
        if self.reports.exit_reports:
            self.reports.due()
        if self.admin_held:
            self.admin_due()
        if item is None:
            return False
        self.handle(item, pending)
        get = self.queue.get_nowait
        while pending:  # the commands that came meanwhile, without a clock read each
            item = get()
            if item is None:
                break
            self.queue.taken(item)
            self.handle(item, pending)
        return True
