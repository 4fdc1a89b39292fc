"""What `swarm up` makes of a child process that exits by itself (swarm/launcher.py).

An agent process that exits while the run goes is an `AgentExitReport`: its exit
status, one line of cause (the last line of its log: for an exception, the traceback's
last line) and the last lines of its log. It is a *crash* (the run does not count as
converged, and `swarm up` exits 4) unless it ended for a reason that is not its own
failure: the end of the run (0), the world gone or silent past the grace (4, 5), a
signal from outside (SIGKILL, SIGTERM, SIGINT, SIGHUP; `swarm kill`), or a scripted
fault the launcher carried out (not reported at all). Every other status is a crash:
1 (an exception, e.g. in a follower law), 3 (refused or unusable configuration: an
agent the launcher starts must be admitted), and crash signals (SIGSEGV, SIGABRT, ...).
"""

from __future__ import annotations

import re
import signal
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts import wire
from swarm.contracts.lifeline import exit_status

LOG_TAIL_LINES = 20  # (wire.EXIT_LOG_LINES at most)
# Exits that are not the agent's own failure (agents/process.py, agents/world_link.py).
NOT_A_CRASH = {4: "the world vanished", 5: "the world did not answer within the grace"}
OUTSIDE_SIGNALS = (signal.SIGKILL, signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
_RUST_SOURCE = re.compile(r"\s+at /\S+?\.rs:\d+\.?")  # zenoh errors name their source line


@dataclass
class AgentExitReport:
    agent: int
    pid: int
    code: int  # exit status; negative: killed by that signal
    crash: bool
    cause: str  # one line
    log: list[str]  # the last lines of its output
    before_start: bool  # it exited before the run started (every agent joined)
    sent: bool = False  # the world has it (an event in summary.json)

    def status(self) -> str:
        return exit_status(self.code)

    def line(self) -> str:
        """One line for the terminal."""
        what = "could not start" if self.before_start else ("crashed" if self.crash else "exited")
        return f"agent {self.agent} (pid {self.pid}) {what} ({self.status()}): {self.cause}"


def is_crash(code: int) -> bool:
    """Whether an exit status (not caused by the launcher) is the agent's own failure."""
    if code == 0 or code in NOT_A_CRASH:
        return False
    if code < 0:
        return -code not in OUTSIDE_SIGNALS
    return not (code > 128 and code - 128 in OUTSIDE_SIGNALS)


def tail(path: Path, lines: int = LOG_TAIL_LINES, max_bytes: int = 16384) -> list[str]:
    """The last non-empty lines of a log file (empty when there is none)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - max_bytes))
            text = f.read().decode("utf-8", errors="replace")
    except OSError:
        return []
    return [ln.rstrip() for ln in text.splitlines() if ln.strip()][-lines:]


def cause_of(log: list[str], code: int) -> str:
    """One line saying why: the last line of the log, without zenoh's source location."""
    if log:
        return _RUST_SOURCE.sub("", log[-1].strip())
    return exit_status(code)


def agent_exit(agent: int, pid: int, code: int, log_path: Path, before_start: bool) -> AgentExitReport:
    log = tail(log_path)
    why = NOT_A_CRASH.get(code) if not log else None
    return AgentExitReport(agent, pid, code, is_crash(code), why or cause_of(log, code), log, before_start)


def send_report(session, run: str, r: AgentExitReport, timeout: float = 1.0) -> bool:
    """Tell the world of run `run` (admin `agent_exit`); True once it has answered."""
    payload = wire.encode_agent_exit(r.agent, r.pid, r.code, r.crash, r.cause, r.log)
    try:
        for reply in session.get(wire.world_admin_key(run), payload=payload, timeout=timeout):
            if reply.ok is not None:
                r.sent = True
    except Exception:  # the session is closing: the report stays in the launcher's list
        return False
    return r.sent


def world_failure(code: int, started: bool, log_path: Path) -> str:
    """One line: why the world exited with `code` (the last line of its log)."""
    when = "failed" if started else "could not start"
    return f"the world {when} ({exit_status(code)}): {cause_of(tail(log_path, 1), code)}"
