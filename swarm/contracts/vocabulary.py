"""The project's vocabulary, in one place: the exit codes every process and command uses
(docs: reference/exit-codes), and the base class of errors that carry one.

One code can mean different things in different processes (4 is "the world is gone" for an
agent, "an agent failed" for `swarm up` and `swarm host`); each meaning has its own name, the
later names being aliases of the first (`ExitCode.AGENT_FAILED is ExitCode.WORLD_GONE`).
A process stopped by signal N exits 128 + N (`signal_exit`).
"""

from __future__ import annotations

from enum import IntEnum
from typing import ClassVar

__all__ = ["Coded", "ExitCode", "signal_exit"]


class ExitCode(IntEnum):
    OK = 0  # every process: the run ended / the command did what it was asked
    FAILED = 1  # a crash (an uncaught exception), the world failed, a run that cannot be found or read
    USAGE = 2  # bad options, scenario, credentials; the world cannot listen on its endpoint
    REFUSED = 3  # agent: no usable credentials, a claim or session refused, an unusable brain
    JOIN_TIMEOUT = 3  # world: not every agent joined within --join-timeout
    WORLD_GONE = 4  # agent: the world's token vanished and its endpoint refuses connections
    AGENT_FAILED = 4  # `swarm up` / `swarm host`: an agent process failed
    WORLD_SILENT = 5  # agent: the world stopped answering and did not come back within --world-grace
    DESERTED = 5  # world (and `swarm up` after it): no agent left
    NO_WORLD = 6  # agent: no world to join
    NO_SPACE = 74  # world: the recording or the results could not be written (EX_IOERR)
    INTERRUPTED = 130  # stopped by SIGINT (128 + 2)
    TERMINATED = 143  # stopped by SIGTERM (128 + 15)


def signal_exit(signum: int) -> int:
    """The exit code of a process stopped by signal `signum`: 128 + signum."""
    return 128 + signum


class Coded(Exception):
    """An error whose class says the exit code the command line gives it (`exit_code`);
    swarm/cli/errors.py prints its message as one line and exits with that code."""

    exit_code: ClassVar[int] = ExitCode.FAILED
