"""The launcher's supervision reports to the world (`world/supervise`: only the launcher's
`supervisor` identity reaches it, swarm/contracts/access.py): a scripted fault carried out,
an agent process that exited. Part of the inbox (world/inbox.py). Each report is checked
against what the world knows: only the fault the clock waits for can be done; an exit is
written only for an agent that has left (its token gone); one that comes first waits
EXIT_REPORT_WAIT s for that, and is then refused (counted as `supervise` in over_limit).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from swarm.contracts import wire
from swarm.contracts.lifeline import exit_status
from swarm.contracts.transport import answer
from swarm.contracts.vocabulary import AgentState, EventKind
from swarm.world.state import RunState

EXIT_REPORT_WAIT = 10.0  # s an agent_exit report waits for its agent to leave the world


class Reports:
    """The launcher's reports. `release_held(aid)`: the inbox's, drops agent `aid` at once
    if its lost token is being held (world/inbox.py), since its process is known to be gone."""

    def __init__(self, state: RunState, release_held: Callable[[int], None]):
        self.state = state
        self.release_held = release_held
        # agent -> (agent_exit report, monotonic s it is kept until)
        self.exit_reports: dict[int, tuple[dict[str, Any], float]] = {}

    def on_supervise(self, query: Any) -> None:
        """The launcher's reports (only its `supervisor` identity reaches this key): a
        scripted fault carried out, an agent process that exited. Each is checked against
        what the world knows: only the fault the clock is waiting for can be done; an exit
        is written only for an agent that has left (its token gone)."""
        st = self.state
        try:
            req = wire.decode_admin(query.payload.to_bytes() if query.payload else b"", wire.SUPERVISE_CMDS)
            if req["cmd"] == "fault_done":
                if req["index"] != st.fault_awaited:
                    raise wire.WireError(f"fault_done: fault {req['index']} is not being carried out")
                st.faults_done.add(req["index"])
            else:
                self._on_agent_exit(req)
            reply = wire.encode_admin_reply(True)
        except wire.WireError as e:
            st.limited("supervise", f"a supervision report refused: {e}")
            reply = wire.encode_admin_reply(False, error=str(e))
        answer(query, wire.world_supervise_key(st.cfg.run), reply)

    def _on_agent_exit(self, req: dict[str, Any]) -> None:
        """The launcher saw an agent process it started exit by itself: a `crash` event (a
        failure of the agent: the run does not count as converged) or an `exit` event. An
        agent still in the world (the report came before its token went) has its report
        kept until it drops, for EXIT_REPORT_WAIT s at most."""
        core = self.state.core
        aid = req["id"]
        if aid not in core.index:
            raise wire.WireError(f"agent_exit: agent {aid} is not in the run")
        self.release_held(aid)
        if core.state[core.index[aid]] == AgentState.ACTIVE:
            self.exit_reports = {**self.exit_reports, aid: (req, time.monotonic() + EXIT_REPORT_WAIT)}
            return
        self._exit_event(req)

    def _exit_event(self, req: dict[str, Any]) -> None:
        status = exit_status(req["code"])
        self.state.event(
            EventKind.CRASH if req["crash"] else EventKind.EXIT,
            req["id"],
            f"process {req['pid']} ended ({status})" + (f": {req['cause']}" if req["cause"] else ""),
            code=req["code"],
            pid=req["pid"],
            cause=req["cause"],
            log=req["log"],
        )

    def due(self) -> None:
        """Exit reports kept for agents still in the world: written once they have left;
        refused (counted) when they are still there EXIT_REPORT_WAIT s later."""
        core = self.state.core
        now = time.monotonic()
        for aid, (req, until) in list(self.exit_reports.items()):
            if core.state[core.index[aid]] != AgentState.ACTIVE:
                del self.exit_reports[aid]
                self._exit_event(req)
            elif now > until:
                del self.exit_reports[aid]
                self.state.limited(
                    "supervise",
                    f"a supervision report refused: agent {aid} reported ended "
                    f"but still in the world after {EXIT_REPORT_WAIT:g} s",
                )
