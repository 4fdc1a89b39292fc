"""The launcher's side of the agents' fork server (agents/forkserver.py).

- `make_subreaper()`: make this process a child subreaper (Linux `PR_SET_CHILD_SUBREAPER`):
  orphans among its descendants become its children, so an agent forked by the server (and
  left by the server's middle process) is the launcher's to wait for and reap.
- `AgentStarter`: what the launcher and `swarm host` start agents with: forked when it can,
  exec'd otherwise.
- `ForkServer`: the server as a member of the run's process group; `spawn(argv, log, env)`
  forks one agent and returns a `Forked`, the Popen-like handle of a process this one adopted.
- `wanted()`: whether to fork agents at all ($SWARM_FORK_AGENTS=0 says no: every agent is
  exec'd, as before; the benchmarks compare the two).

Anything wrong with the server (it cannot start, died, answers nonsense) makes `spawn`
raise `ForkError`; `AgentStarter` then execs that agent and the ones after it.
Standard library only.
"""

from __future__ import annotations

import ctypes
import json
import os
import select
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from swarm.runtime.procs import Group, wait_until

ENV_FORK_AGENTS = "SWARM_FORK_AGENTS"
PR_SET_CHILD_SUBREAPER = 36
READY_TIMEOUT = 60.0  # s for the server's imports (0.1-0.2 s on a quiet machine)
REPLY_TIMEOUT = 10.0  # s for the server to answer a request (it answers in milliseconds)


class ForkError(RuntimeError):
    """The fork server cannot fork an agent (the message says why)."""


def wanted(env=None) -> bool:
    env = os.environ if env is None else env
    return env.get(ENV_FORK_AGENTS, "1") not in ("0", "no", "false") and sys.platform.startswith("linux")


def make_subreaper() -> bool:
    """Make this process a child subreaper; True when it is one."""
    return set_subreaper(True)


def set_subreaper(on: bool) -> bool:
    """Make this process a child subreaper, or no longer one; True when done."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_CHILD_SUBREAPER, int(on), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


class Forked:
    """A child this process adopted (an agent forked by the server): the part of
    `subprocess.Popen` the launcher and `swarm.runtime.procs.Group` use (pid, returncode, poll, wait,
    send_signal, terminate, kill), on os.waitpid. Safe to poll from two threads."""

    def __init__(self, pid: int, args: list[str]):
        self.pid = pid
        self.args = args
        self.returncode: int | None = None
        self._lock = threading.Lock()

    def poll(self) -> int | None:
        if not self._lock.acquire(blocking=False):  # another thread is waiting for it: not now
            return self.returncode
        try:
            return self._wait_locked(os.WNOHANG)
        finally:
            self._lock.release()

    def wait(self, timeout: float | None = None) -> int:
        if timeout is None:
            code = self._wait(0)
        else:
            wait_until(lambda: self.poll() is not None, timeout, 0.01)
            code = self.returncode
        if code is None:
            raise subprocess.TimeoutExpired(self.args, 0.0 if timeout is None else timeout)
        return code

    def _wait(self, flags: int) -> int | None:
        with self._lock:
            return self._wait_locked(flags)

    def _wait_locked(self, flags: int) -> int | None:
        if self.returncode is not None:
            return self.returncode
        try:
            pid, status = os.waitpid(self.pid, flags)
        except ChildProcessError:  # not ours (any more): reaped elsewhere, its status unknown
            self.returncode = 255
            return self.returncode
        if pid == 0:
            return None
        self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class AgentStarter:
    """Starts agent processes (`python -m swarm.agents.process ARGS`) in `group`, each with `env`
    plus its own extra variables and its output in `logs/<name>`: forked by a fork server when
    it can (this process made a subreaper, the server started at once so it imports while
    the caller does other things), exec'd otherwise, and exec'd from the first time the
    server fails on (said once through `say`). The launcher and `swarm host` use it."""

    def __init__(self, group: Group, env: dict, logs: Path, say: Callable[[str], None], fork: bool = True):
        self.group, self.env, self.logs, self.say = group, env, logs, say
        self.server: ForkServer | None = None
        if fork and wanted(env) and make_subreaper():
            try:
                self.server = ForkServer(group, env, logs / "forkserver.log")
            except OSError as e:
                self.say(f"the agents' fork server did not start ({e}); agents are exec'd")
                set_subreaper(False)

    def start(self, args: list[str], log_name: str, extra_env: dict | None = None):
        """One agent process (a `Forked` or a `subprocess.Popen`)."""
        log = self.logs / log_name
        if self.server is not None:
            try:
                p = self.server.spawn(args, log, extra_env)
                self.group.adopt(p)
                return p
            except ForkError as e:
                self.say(f"{e}; agents are exec'd from now on")
                self.close(kill=True)
        with open(log, "ab") as out:
            return self.group.start(
                [sys.executable, "-m", "swarm.agents.process", *args],
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                env={**self.env, **(extra_env or {})},
            )

    def close(self, kill: bool = False) -> None:
        """No more forks: end the server (at once with `kill`: it failed) and stop being a
        subreaper (the agents adopted already stay this process's children)."""
        server, self.server = self.server, None
        if server is not None:
            server.close(kill)
            set_subreaper(False)


class ForkServer:
    """agents/forkserver.py as a member of `group`, started with `env` (the agents')."""

    def __init__(self, group: Group, env: dict, log: Path):
        with open(log, "ab") as err:
            self.proc = group.start(
                [sys.executable, "-m", "swarm.agents.forkserver"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=err,
                env=env,
            )
        if self.proc.stdin is None or self.proc.stdout is None:  # (never: both are pipes)
            raise ForkError("the agents' fork server has no pipes")
        self.stdin, self.stdout = self.proc.stdin, self.proc.stdout
        self.broken: str | None = None
        self.ready = False

    def _reply(self, timeout: float) -> dict:
        ready, _, _ = select.select([self.stdout], [], [], timeout)
        line = self.stdout.readline() if ready else b""
        return json.loads(line) if line else {"error": "no answer (it ended, or took too long)"}

    def spawn(self, argv: list[str], log: Path, extra_env: dict | None = None) -> Forked:
        """Fork `python -m swarm.agents.process *argv`, its output to `log`, with `extra_env` added
        to the server's environment."""
        if self.broken:
            raise ForkError(self.broken)
        try:
            if not self.ready:  # its imports, once (they may take a while on a busy machine)
                reply = self._reply(READY_TIMEOUT)
                if not reply.get("ready"):
                    raise ForkError(str(reply.get("error", reply)))
                self.ready = True
            req = {"argv": argv, "log": str(log), "env": extra_env or {}}
            self.stdin.write(json.dumps(req).encode() + b"\n")
            self.stdin.flush()
            reply = self._reply(REPLY_TIMEOUT)
            if "pid" not in reply:
                raise ForkError(str(reply.get("error", reply)))
            return Forked(int(reply["pid"]), [sys.executable, "-m", "swarm.agents.process", *argv])
        except (OSError, ValueError, TypeError, ForkError) as e:
            self.broken = f"the agents' fork server: {e}"
            raise ForkError(self.broken) from None

    def close(self, kill: bool = False) -> None:
        """End the server (the end of its stdin; SIGKILL with `kill`); the group's stop reaps it."""
        if kill and self.proc.poll() is None:
            self.proc.kill()
        for f in (self.stdin, self.stdout):
            try:
                f.close()
            except OSError:
                pass
