"""Ending a live run from any terminal (`swarm stop`): an admin `stop` on the world's
`world/admin` queryable, which only the run's operator (and the launcher) may query
(swarm/contracts/access.py). The world records a `stop` event, answers with its tick and
stops itself as on SIGINT: its results are written (summary.json: `completed` false,
`stopped_by_signal` 2), and the `swarm up` that launched it, which watches the events, ends
the run as on Ctrl-C (exit 130; docs/reference/exit-codes.md#swarm-up). It goes over zenoh,
so it works the same from another machine with the run's credentials.
"""

from __future__ import annotations

import getpass
import os
import socket
from dataclasses import dataclass

from swarm.contracts.errors import LiveError
from swarm.runtime.procs import wait_until

STOP_DEADLINE = 60.0  # s for a stopped world to have written its results and gone


@dataclass(frozen=True)
class Stopped:
    """Run `run` was asked to stop at tick `tick`; `out`: where its results go (None: not
    said); `ended`: it has ended (None: not waited for)."""

    run: str
    tick: int | None
    out: str | None
    ended: bool | None

    def line(self) -> str:
        where = f"; results in {self.out}" if self.out else ""
        if self.ended is None:
            return f"run {self.run} stopping at tick {self.tick}{where}"
        return f"run {self.run} stopped at tick {self.tick}{where}"


def asker() -> str:
    """Who asks, for the `stop` event's reason: `swarm stop (user@host, pid N)`."""
    try:
        user = getpass.getuser()
    except Exception:  # no name for this uid
        user = str(os.getuid())
    return f"swarm stop ({user}@{socket.gethostname()}, pid {os.getpid()})"


def stop_run(live, by: str | None = None, wait: bool = True, timeout: float = STOP_DEADLINE) -> Stopped:
    """Ask the world of `live` (an open swarm.live.client.LiveRun) to stop the run; with
    `wait`, until it has ended (its end notice, or its endpoint refusing connections):
    LiveError after `timeout` s."""
    live.watch_end()
    out = None
    try:
        out = live.info().get("out")
    except Exception:  # the info is for the line only: the stop is what counts
        pass
    rep = live.admin("stop", by=by or asker())
    done = Stopped(live.ref.run, rep.get("tick"), out if isinstance(out, str) else None, None)
    if not wait:
        return done
    if not wait_until(live.gone, timeout, 0.1):
        raise LiveError(f"run {done.run} was asked to stop at tick {done.tick} but has not ended within {timeout:g} s")
    return Stopped(done.run, done.tick, done.out, True)
