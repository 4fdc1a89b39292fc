"""The world's start-up, told to the launcher on a pipe: what it is doing, and when it listens.

The launcher (swarm/runtime/launcher.py) makes a pipe, hands the world its writing end (the fd
number in $SWARM_READY_FD) and reads the other. The world writes one word a line as it
goes (`STEPS`), `ready` once its hub listens, and closes its end; its exit closes it too.
So the launcher waits for exactly what it needs: `ready`, or the end of the pipe (the
world exited), never a fixed time; should a world hang while starting, the last word says
where. A world started by hand has no such fd and writes nothing.
"""

from __future__ import annotations

import os
import select
import time
from typing import Any

ENV_READY_FD = "SWARM_READY_FD"
READY = "ready"
# what the world is doing after each word (before any: Python starting and importing)
STEPS = {
    "": "starting (Python and its imports)",
    "credentials": "writing the run's credentials",
    "recording": "creating its recording",
    "listening": "opening its hub (zenoh.open)",
    "robots": "reaching the robots (command types, first poses)",
    READY: "listening",
}


class Announcer:
    """The world's side: `say(step)` for each step, `ready()` at the end (the fd is closed)."""

    def __init__(self, fd: int | None):
        self.fd = fd

    @classmethod
    def from_environment(cls) -> Announcer:
        """The fd the launcher gave (taken out of the environment, so nothing else writes to it)."""
        v = os.environ.pop(ENV_READY_FD, "")
        try:
            fd = int(v) if v else None
            if fd is not None:
                os.set_inheritable(fd, False)
        except (ValueError, OSError):
            fd = None
        return cls(fd)

    def say(self, step: str) -> None:
        if self.fd is None:
            return
        try:
            os.write(self.fd, step.encode() + b"\n")
        except OSError:  # the launcher is gone: nobody to tell
            self.close()

    def ready(self) -> None:
        self.say(READY)
        self.close()

    def close(self) -> None:
        if self.fd is not None:
            fd, self.fd = self.fd, None
            try:
                os.close(fd)
            except OSError:
                pass


class ReadyWait:
    """The launcher's side, on the reading end `fd` (owned: closed by `close`)."""

    def __init__(self, fd: int):
        self.fd: int | None = fd
        self.step = ""  # the last word read
        self.ended = False  # the pipe ended (the world exited, or closed it after `ready`)
        self._buf = b""

    def poll(self, timeout: float) -> bool:
        """Read what the world wrote within `timeout` s; True once it said `ready`."""
        fd = self.fd
        if self.step == READY or self.ended or fd is None:  # (None: closed)
            return self.step == READY
        readable, _, _ = select.select([fd], [], [], max(0.0, timeout))
        if readable:
            data = os.read(fd, 4096)
            if not data:
                self.ended = True
            self._buf += data
            *lines, self._buf = self._buf.split(b"\n")
            for line in lines:
                word = line.decode(errors="replace").strip()
                if word in STEPS:
                    self.step = word
        return self.step == READY

    def wait(self, timeout: float, stop: Any = lambda: False, interval: float = 0.1) -> bool:
        """Until `ready` (True), the pipe's end, `stop()` or `timeout` s (False)."""
        t_end = time.monotonic() + timeout
        while not self.poll(min(interval, max(0.0, t_end - time.monotonic()))):
            if self.ended or stop() or time.monotonic() >= t_end:
                return False
        return True

    def doing(self) -> str:
        """What the world was doing at its last word."""
        return STEPS.get(self.step, self.step)

    def close(self) -> None:
        if self.fd is not None:
            fd, self.fd = self.fd, None
            os.close(fd)
