"""The errors of the Python API that are the project's own, in one place. Each says what is
wrong in one line (its message) and carries the exit code the command line gives it
(`exit_code`); swarm/cli/errors.py turns them, and the errors of the layers below
(scenarios, run directories, recordings, plots), into that line and that code.

- `NoRunError` (1): no (single) run found or reachable, or its world ended or stopped
  answering during a call (`swarm.live.client.NoRun` is this class); `StoppedAnswering`, one of
  them, says that a watched world stopped answering without having ended.
- `LiveError` (1): the run is there but cannot do what was asked (an unknown agent id, an
  agent that is not live, a spawned agent that did not join, a kill not followed by a drop).
- `UsageError` (2): a bad argument (a spawn spec, an id out of the run's range, a signal name).
- `UpError` (1): a `swarm.up` run cannot do what was asked (it ended, or never started).
"""

from __future__ import annotations

from swarm.contracts.vocabulary import Coded, ExitCode

__all__ = ["LiveError", "NoRunError", "StoppedAnswering", "SwarmError", "UpError", "UsageError", "one_line"]


def one_line(e: BaseException) -> str:
    """The first line of an error's message (its class name if it has none)."""
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


class SwarmError(Coded):
    """An error of the API; `exit_code` is what the command line exits with."""

    exit_code = ExitCode.FAILED


class NoRunError(SwarmError):
    """No (single) run matches, or its world ended or does not answer; the message says what was looked at."""


class StoppedAnswering(NoRunError):
    """A watched world stopped answering for several seconds without having ended (no end
    notice, its endpoint still there): stalled, starved, or cut off from this machine."""


class LiveError(SwarmError):
    """The live run cannot do what was asked; the message says why."""


class UsageError(SwarmError, ValueError):
    """A bad argument; the message names it."""

    exit_code = ExitCode.USAGE


class UpError(SwarmError, RuntimeError):
    """The run cannot do what was asked (it ended, or never started); the message says why,
    with the last lines of `swarm up`'s output."""
