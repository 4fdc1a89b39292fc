"""Child processes and deadlines, in one place: the launcher, the runtime tests and the
benchmark all start, signal, stop and wait for processes through this module.

- `wait_until(cond, timeout, interval)`: poll a condition until it holds or a deadline
  passes (the only poll loop; callers decide what a timeout means).
- `Group`: children in one process group of their own. The first child started leads
  it (pgid == its pid; a new session with `session=True`), later ones join it. The group
  can be signalled as a whole and stopped (SIGTERM, SIGKILL after a grace period, every
  child reaped, and a last SIGKILL for whatever else joined it, e.g. grandchildren).
- `command_words`, `agent_id_of`: a process's command line as words, and the agent id
  in an agent's, whether it was exec'd or forked (and titled) by the fork server.
- `Reaper`: a thread that reaps a group's members (not its leader) as they exit, so a
  child killed from outside is no zombie while its parent is busy.

While a member is unreaped, even as a zombie, it is in the group and the group id cannot
be given to anyone else, so a signal to the group reaches only what was started in it; once
every member is reaped, the group is not signalled any more. The leader is reaped only by
`reap()` (or `stop()`), its exit status read meanwhile without reaping it (`exit_code`), so
the group keeps its id, and new members can still join it, while other members come and go.

Standard library only (the top `swarm` layer; used by tests and benchmarks too).
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterable
from typing import Literal, TypeVar

T = TypeVar("T")


def wait_until(cond: Callable[[], T], timeout: float, interval: float = 0.01) -> T | Literal[False]:
    """Poll `cond` every `interval` s until it returns something truthy (returned) or
    `timeout` s have passed (False). It is always called at least once, and last after the
    deadline, so a condition that holds at the deadline counts."""
    t_end = time.monotonic() + timeout
    while True:
        late = time.monotonic() >= t_end
        value = cond()
        if value:
            return value
        if late:
            return False
        time.sleep(interval)


class Group:
    """Children in one process group: the first started leads it, the rest join it.

    `session=True` starts the leader in a new session (`start_new_session`: no controlling
    terminal, so a terminal's Ctrl-C or hangup does not reach the group); otherwise in a
    new process group of this session (`process_group=0`).
    """

    def __init__(self, session: bool = False):
        self.session = session
        self.pgid: int | None = None
        self.members: list[subprocess.Popen] = []  # leader first

    @property
    def leader(self) -> subprocess.Popen | None:
        return self.members[0] if self.members else None

    def start(self, args, **popen_kwargs) -> subprocess.Popen:
        """Popen(args, **popen_kwargs) in this group (leading it when it is the first)."""
        if self.pgid is None:
            where = {"start_new_session": True} if self.session else {"process_group": 0}
        else:
            where = {"process_group": self.pgid}
        p = subprocess.Popen(args, **where, **popen_kwargs)
        if self.pgid is None:
            self.pgid = p.pid
        self.members.append(p)
        return p

    def adopt(self, p) -> None:
        """Count as a member a child already in the group that this process did not start
        itself (a Popen-like handle: pid, returncode, poll, wait; swarm/runtime/forks.py's `Forked`)."""
        assert self.pgid is not None, "a group is led by a child it started"
        self.members.append(p)

    def exit_code(self, p: subprocess.Popen) -> int | None:
        """A member's exit status (negative: killed by that signal), None while it runs.
        Other members are reaped by this; the leader only by `reap()`."""
        if p.returncode is not None:
            return p.returncode
        if p is not self.leader:
            return p.poll()
        try:
            info = os.waitid(os.P_PID, p.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return p.poll()
        if info is None:
            return None
        return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status

    def reap_exited(self) -> list[subprocess.Popen]:
        """Reap the members, other than the leader, that have exited since the last call (no
        zombie of theirs stays); returns them. Safe from another thread than the one that
        starts them (`Reaper`)."""
        return [p for p in self.members[1:] if p.returncode is None and p.poll() is not None]

    def running(self) -> list[subprocess.Popen]:
        """The members that have not exited."""
        return [p for p in self.members if self.exit_code(p) is None]

    def signal(self, sig: int) -> bool:
        """Send `sig` to the whole group; False when there is no group (any more) to signal."""
        if self.pgid is None or not any(p.returncode is None for p in self.members):
            return False  # no group, or all reaped: the id is not ours any more
        try:
            os.killpg(self.pgid, sig)
        except ProcessLookupError:
            return False
        return True

    def alive(self) -> bool:
        """Whether anything of the group still runs: a member, or any other process in the
        group (a grandchild). Members that exited are reaped first (the leader only by
        `reap()`); then the group is probed with signal 0, and, where /proc tells, zombies
        (the unreaped leader, orphans an init does not reap) do not count."""
        if self.pgid is None:
            return False
        if self.running():
            return True
        try:
            os.killpg(self.pgid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # it exists, but is not ours to signal
            return True
        runs = group_runs(self.pgid)
        return True if runs is None else runs

    def reap(self, timeout: float = 5.0) -> None:
        """Wait up to `timeout` s for each member, so that no zombie stays. Once the leader
        has exited, whatever else is left in the group (grandchildren) gets SIGKILL first,
        and the leader is reaped last, when nothing of its group runs any more."""
        for p in self.members[1:]:
            _wait(p, timeout)
        leader = self.leader
        if leader is None:
            return
        pgid = self.pgid  # set with the leader
        if pgid is not None and self.exit_code(leader) is not None and self.signal(signal.SIGKILL):
            wait_until(lambda: not group_runs(pgid), timeout, 0.01)
        _wait(leader, timeout)

    def kill(self, timeout: float = 5.0) -> None:
        """SIGKILL to the group at once, then reap."""
        self.signal(signal.SIGKILL)
        self.reap(timeout)

    def stop(self, grace: float = 3.0, timeout: float = 5.0) -> None:
        """SIGTERM to the group, SIGKILL if a member still runs `grace` s later, then reap."""
        stop_groups([self], grace, timeout)


class Reaper:
    """A thread that reaps a group's exited members (`Group.reap_exited`, never the leader)
    every `interval` s, however long its owner's own loop is busy (e.g. in a query waiting
    for its timeout): a member that exits is reaped within `interval` s. `stop()` ends it."""

    def __init__(self, group: Group, interval: float = 0.2):
        self.group = group
        self.interval = interval
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="reaper", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            self.group.reap_exited()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)


def stop_groups(groups: Iterable[Group], grace: float = 3.0, timeout: float = 5.0) -> None:
    """`Group.stop` for several groups at once (one grace period for all): SIGTERM to every
    group with a member running, SIGKILL to those with one still running `grace` s later,
    then reap every member (waiting up to `timeout` s for each)."""
    groups = list(groups)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        busy = [g for g in groups if g.running()]
        if not busy:
            break
        for g in busy:
            g.signal(sig)
        wait_until(_none_running(busy), grace, 0.02)
    for g in groups:
        g.reap(timeout)


def _none_running(groups: list[Group]) -> Callable[[], bool]:
    return lambda: not any(g.running() for g in groups)


def group_runs(pgid: int) -> bool | None:
    """Whether a process of group `pgid` runs (is not a zombie), from /proc; None where
    there is no /proc to tell."""
    try:
        names = os.listdir("/proc")
    except OSError:
        return None
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as f:
                stat = f.read()
        except OSError:  # gone meanwhile
            continue
        state, _ppid, pgrp = stat[stat.rindex(b")") + 2 :].split()[:3]
        if int(pgrp) == pgid and state != b"Z":
            return True
    return False


def _wait(p: subprocess.Popen, timeout: float) -> None:
    try:
        p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pass


def command_words(parts: list[str]) -> list[str]:
    """A process's command line as words, from /proc/PID/cmdline's NUL-separated parts (or
    psutil's `cmdline()`). A process that set its title (an agent forked by the fork server,
    agents/forkserver.py) has it as one string of words, padded with empty parts."""
    words = [p for p in parts if p]
    return words[0].split() if len(words) == 1 else words


def agent_id_of(parts: list[str]) -> int | None:
    """The agent id of an agent process (`python -m swarm.agents.process ID ...`) from its command
    line's parts; None for any other process."""
    words = command_words(parts)
    if "swarm.agents.process" not in words:
        return None
    i = words.index("swarm.agents.process") + 1
    return int(words[i]) if i < len(words) and words[i].isdigit() else None
