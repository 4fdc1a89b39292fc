"""What `swarm up`'s launcher (swarm/runtime/launcher.py) does while a run goes, beside starting
and observing it: agent processes that exit by themselves reported (to the world, and as
lines), and the world's scripted process faults (kill, freeze, thaw, restart an agent) carried
out. `Oversight` is `Launcher`'s base: these methods use the launcher's fields, declared here.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarm.contracts import wire
from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.supervision import AgentExitReport, agent_exit, send_report, world_failure


class Oversight:
    """Agent exits and scripted faults (the launcher's fields they use are declared here)."""

    cfg: Any  # UpConfig
    say: Callable[[str], None]
    world: subprocess.Popen | None
    agents: dict[int, subprocess.Popen]
    logs: Path
    failed: bool
    notices: list[bytes]
    dropped_notices: int
    dropped_noted: float
    started: bool
    procs: list[tuple[int, subprocess.Popen]]
    seen_exit: set[int]
    scripted: set[int]
    exits: list[AgentExitReport]
    failure: str | None

    def world_exit_code(self) -> int | None:  # (Launcher's)
        raise NotImplementedError

    def start_agent(self, agent_id: int) -> subprocess.Popen:  # (Launcher's)
        raise NotImplementedError

    def supervise(self, session) -> bool:
        """Report agent processes that exited by themselves; True when the run must stop (an
        agent could not start). `session` None: the world has ended, nothing is sent."""
        for aid, p in self.procs:
            code = p.poll()
            if code is None or p.pid in self.seen_exit:
                continue
            self.seen_exit.add(p.pid)
            if code == ExitCode.OK or p.pid in self.scripted:
                continue  # the end of the run, or a scripted fault (the world has its event)
            r = agent_exit(aid, p.pid, code, self.logs / f"agent-{aid}.log", before_start=not self.started)
            if session is None and not r.crash:
                continue  # after the world ended: agents that saw it go are no news
            self.exits.append(r)
            if r.before_start and self.world_exit_code() is None:
                self.failure = r.line()  # said once, by `swarm up` at the end
                self.failed = True
            else:
                self.say(f"swarm up: {r.line()}")
        if session is not None:
            for r in self.exits:
                if not r.sent and not send_report(session, self.cfg.run, r):
                    break  # the world does not answer now: again on the next round
        return self.failed

    def crashed(self) -> list[AgentExitReport]:
        return [r for r in self.exits if r.crash]

    def world_failure(self) -> str:
        """One line: why the world exited with a failure (the last line of its log)."""
        code = self.world.returncode if self.world is not None and self.world.returncode is not None else -1
        return world_failure(code, self.started, self.logs / "world.log")

    def carry_out_faults(self, session) -> None:
        """Scripted process faults the world asks for (it holds its clock meanwhile)."""
        while self.notices:
            try:
                msg = wire.decode_control(self.notices.pop(0))
                if isinstance(msg, int):
                    continue  # the end of the run: the world process exits by itself
                if msg.agent not in self.cfg.scenario.ids:
                    raise wire.WireError(f"control: fault for agent {msg.agent}, not in the scenario")
            except wire.WireError as e:  # malformed (or forged): dropped (docs/reference/protocol.md#versioning)
                self.dropped_notices += 1
                if time.monotonic() - self.dropped_noted > 1.0:  # at most one line a second
                    self.dropped_noted = time.monotonic()
                    self.say(f"swarm up: ignored a malformed fault notice ({e}; {self.dropped_notices} so far)")
                continue
            index, kind, aid = msg.index, msg.kind, msg.agent
            p = self.agents.get(aid)
            running = p is not None and p.poll() is None
            if kind == "restart":
                if not running:
                    self.start_agent(aid)
            elif p is not None and running and kind in ("kill", "freeze", "thaw"):
                sig = {"kill": signal.SIGKILL, "freeze": signal.SIGSTOP, "thaw": signal.SIGCONT}[kind]
                if kind == "kill":
                    self.scripted.add(p.pid)  # its exit is the fault's, not a crash
                try:
                    os.kill(p.pid, sig)
                except ProcessLookupError:
                    pass
            if session is not None:
                list(
                    session.get(
                        wire.world_supervise_key(self.cfg.run),
                        timeout=2.0,
                        payload=wire.encode_admin("fault_done", index=index),
                    )
                )
