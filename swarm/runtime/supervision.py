"""What `swarm up` makes of a child process that exits by itself (swarm/runtime/launcher.py).

An agent process that exits while the run goes is an `AgentExitReport`: its exit
status, one line of cause and the last lines of its log. It is a *crash* (the run does not count as
converged, and `swarm up` exits 4) unless it ended for a reason that is not its own
failure: the end of the run (0), the world gone or silent past the grace (4, 5), a
signal from outside (SIGKILL, SIGTERM, SIGINT, SIGHUP; `swarm kill`), or a scripted
fault the launcher carried out (not reported at all). Every other status is a crash:
1 (an exception, e.g. in a follower law), 3 (refused or unusable configuration: an
agent the launcher starts must be admitted), and crash signals (SIGSEGV, SIGABRT, ...).

The cause (of an agent's exit, and of a world's failure: `world_failure`) is taken from the
log only when the log's last line is an error, by this rule (`error_line`):

- the last line of a Python traceback: a last line that is not indented and reads `Name`
  or `Name: message` (e.g. "RuntimeError: the law gave up"), after an indented line (the
  traceback's last frame) or with a "Traceback (most recent call last):" line earlier in
  the log's tail;
- a line the process marked as its error: "swarm <command>[ <id>]: ..." is how the world
  and agent processes say why they stop (world/main.py, agents/process.py), while their
  progress and notes are "[world] ..." / "[agent N] ..." lines; also faulthandler's
  "Fatal Python error: ...".

Anything else (a progress line, a note, an empty log) is not a cause: the exit status says
it all (`killed by SIGKILL`), and is said once ("agent 3 (pid 42) exited (killed by
SIGKILL)", "the world failed (killed by SIGKILL)"); an agent's exit 4 or 5 says what those
mean (NOT_A_CRASH).
"""

from __future__ import annotations

import re
import signal
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts import wire
from swarm.contracts.lifeline import exit_status
from swarm.contracts.vocabulary import ExitCode, signal_exit

LOG_TAIL_LINES = 20  # (wire.EXIT_LOG_LINES at most)
# Exits that are not the agent's own failure (agents/process.py, agents/world_link.py).
NOT_A_CRASH: dict[int, str] = {
    ExitCode.WORLD_GONE: "the world vanished",
    ExitCode.WORLD_SILENT: "the world did not answer within the grace",
}
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

    def said(self) -> str:
        """The cause beyond the exit status ("" when the status is all there is to say)."""
        return "" if self.cause == self.status() else self.cause

    def line(self) -> str:
        """One line for the terminal: the status, and the cause when it says more."""
        what = "could not start" if self.before_start else ("crashed" if self.crash else "exited")
        said = self.said()
        return f"agent {self.agent} (pid {self.pid}) {what} ({self.status()})" + (f": {said}" if said else "")


def is_crash(code: int) -> bool:
    """Whether an exit status (not caused by the launcher) is the agent's own failure."""
    if code == ExitCode.OK or code in NOT_A_CRASH:
        return False
    if code < 0:
        return -code not in OUTSIDE_SIGNALS
    return not any(code == signal_exit(s) for s in OUTSIDE_SIGNALS)


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


TRACEBACK = "Traceback (most recent call last):"
_EXCEPTION_LINE = re.compile(r"^[A-Za-z_][\w.]*(: .*)?$")  # "RuntimeError: ...", "KeyboardInterrupt"
_MARKED_ERROR = re.compile(r"^(swarm [a-z]+( \d+)?: |Fatal Python error: )")


def error_line(log: list[str]) -> str | None:
    """The log's last line if it is an error (the module docstring's rule), without zenoh's
    source location; None otherwise."""
    if not log:
        return None
    last = log[-1].rstrip()
    after_frame = len(log) > 1 and log[-2][:1].isspace()
    if _MARKED_ERROR.match(last) or (_EXCEPTION_LINE.match(last) and (after_frame or TRACEBACK in log[:-1])):
        return _RUST_SOURCE.sub("", last.strip())
    return None


def cause_of(log: list[str], code: int) -> str:
    """One line saying why: the log's error line (`error_line`), else the exit status."""
    return error_line(log) or exit_status(code)


def agent_exit(agent: int, pid: int, code: int, log_path: Path, before_start: bool) -> AgentExitReport:
    log = tail(log_path)
    why = error_line(log) or NOT_A_CRASH.get(code) or exit_status(code)
    return AgentExitReport(agent, pid, code, is_crash(code), why, log, before_start)


def send_report(session, run: str, r: AgentExitReport, timeout: float = 1.0) -> bool:
    """Tell the world of run `run` (`agent_exit` on its supervise key: `session` must be the
    launcher's, as `supervisor`); True once it has answered."""
    payload = wire.encode_agent_exit(r.agent, r.pid, r.code, r.crash, r.said(), r.log)  # the world says the status
    try:
        for reply in session.get(wire.world_supervise_key(run), payload=payload, timeout=timeout):
            if reply.ok is not None:
                r.sent = True
    except Exception:  # the session is closing: the report stays in the launcher's list
        return False
    return r.sent


def world_failure(code: int, started: bool, log_path: Path) -> str:
    """One line: why the world exited with `code`: its status, and its log's error line
    if the log ends with one (the module docstring's rule)."""
    when = "failed" if started else "could not start"
    why = error_line(tail(log_path))
    return f"the world {when} ({exit_status(code)})" + (f": {why}" if why else "")
