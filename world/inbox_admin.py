"""The operator's admin queries on the world's inbox (world/admin): pause, resume and stop,
as `AdminQueries`, which world/inbox.py's `Inbox` is made of.

Only the operator and the launcher may query world/admin. Pause and resume each take effect,
but their events are written within a budget (ADMIN_RATE a second, ADMIN_BURST at once);
those beyond it are counted (`over_limit.admin`, one `limit` event the first time), and once
the budget allows, one event says the clock's state then and how many requests it stands
for. A run is stopped once: a second stop is answered, not recorded. Who asked (`by`) comes
bounded and escaped from the wire's decoder (swarm/contracts/freetext.py).
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from typing import Any

from swarm.contracts import wire
from swarm.contracts.freetext import Budget
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import EventKind
from swarm.world.state import RunState

ADMIN_RATE = 2.0  # pause/resume events written a second, at most (beyond: counted, coalesced)
ADMIN_BURST = 10  # ... and at most this many at once


class AdminQueries:
    """Pause, resume and stop (`on_admin`), with the events' budget; `Inbox` sets the
    attributes below in its constructor."""

    state: RunState
    admin_budget: Budget  # pause/resume events written
    admin_clock: Callable[[], float]  # the budget's clock (a test's own)
    admin_held: int  # pause/resume requests since the last such event, not written
    admin_by: str  # who asked the last of those
    paused_written: bool  # the clock's state the last pause/resume event wrote
    stop_taken: int | None  # the tick a stop was asked at (a second one is not recorded)

    def on_admin(self, query: Any) -> None:
        """pause / resume the world clock, or stop the run (the operator's)."""
        st = self.state
        try:
            req = wire.decode_admin(query.payload.to_bytes() if query.payload else b"", wire.ADMIN_CMDS)
            cmd, by = req["cmd"], req["by"]  # by: bounded and escaped (wire.decode_admin)
            if cmd == "stop":
                self.stop_asked(query, by)
                return
            if (cmd == "pause") != st.paused:
                st.paused = cmd == "pause"
                self.admin_event(by)
            if st.paused and st.ticking:
                st.pause_waiters.append(query)  # answered once the tick in progress is done
                return
            reply = wire.encode_admin_reply(True, paused=st.paused, tick=st.core.tick)
        except wire.WireError as e:
            st.garbage += 1
            reply = wire.encode_admin_reply(False, error=str(e))
        answer(query, wire.world_admin_key(st.cfg.run), reply)

    def admin_event(self, by: str) -> None:
        """The clock was just paused or resumed (`state.paused`), asked by `by`: its event, if
        the budget allows; otherwise held back and counted (`over_limit.admin`), and said later
        by `admin_due` (module docstring)."""
        self.admin_held += 1
        self.admin_by = by
        if self.admin_budget.take(self.admin_clock()):
            self._write_admin_event(by)
            return
        self.state.limited(
            "admin",
            f"more than {ADMIN_BURST} pauses and resumes at once or {ADMIN_RATE:g} a second: later ones "
            "take effect but are counted (over_limit.admin) and written as one event each time the budget allows",
        )

    def _write_admin_event(self, by: str) -> None:
        """The clock's state now, as a pause or resume event; when it stands for more than one
        request (those held back since the last such event), it says how many (`requests`)."""
        st = self.state
        n, self.admin_held = self.admin_held, 0
        self.paused_written = st.paused
        reason = f"asked by {by}"
        if n > 1:
            reason += f" (the last of {n} pause and resume requests since the previous such event)"
        st.event(EventKind.PAUSE if st.paused else EventKind.RESUME, None, reason, **({"requests": n} if n > 1 else {}))

    def admin_due(self, now: bool = False) -> None:
        """Pause/resume requests held back (`admin_event`): once the budget allows (`now`: at
        once, the run is ending), one event with the clock's state then, if it is not the
        state last written (else they stay only counted)."""
        if not now and not self.admin_budget.ready(self.admin_clock()):
            return
        if self.admin_held and self.state.paused != self.paused_written:
            self.admin_budget.take(self.admin_clock())
            self._write_admin_event(self.admin_by)
        else:
            self.admin_held = 0

    def stop_asked(self, query: Any, by: str) -> None:
        """`swarm stop`: a `stop` event (the launcher of `swarm up` watches for it and ends
        the run as on Ctrl-C), the reply, then SIGINT to this process: the run ends here as
        on Ctrl-C, its results written (`stopped_by_signal` 2, `completed` false). A stop
        asked again meanwhile is answered the same, and neither recorded nor signalled again."""
        st = self.state
        if self.stop_taken is not None:
            reply = wire.encode_admin_reply(True, stopping=True, tick=self.stop_taken)
            answer(query, wire.world_admin_key(st.cfg.run), reply)
            return
        self.stop_taken = st.core.tick
        self.admin_due(now=True)  # the record ends with the clock's state as it was
        st.event(EventKind.STOP, None, f"asked by {by}")
        answer(query, wire.world_admin_key(st.cfg.run), wire.encode_admin_reply(True, stopping=True, tick=st.core.tick))
        os.kill(os.getpid(), signal.SIGINT)  # world/main.py's Stop, on this (the main) thread
