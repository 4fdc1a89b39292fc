"""The project's vocabulary, in one place: the exit codes every process and command uses
(docs: reference/exit-codes), the base class of errors that carry one, the kinds of the
world's events, the reasons of "switch" events, the states of an agent in the world and the
phases an agent reports. The string vocabularies are `StrEnum`s: each member is equal to
the string written on the wire and in the outputs, so those stay as they were.

One code can mean different things in different processes (4 is "the world is gone" for an
agent, "an agent failed" for `swarm up` and `swarm host`); each meaning has its own name, the
later names being aliases of the first (`ExitCode.AGENT_FAILED is ExitCode.WORLD_GONE`).
A process stopped by signal N exits 128 + N (`signal_exit`).
"""

from __future__ import annotations

from enum import IntEnum, StrEnum
from typing import ClassVar

__all__ = ["AgentState", "Coded", "EventKind", "ExitCode", "FollowState", "Phase", "SwitchReason", "signal_exit"]


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


class EventKind(StrEnum):
    """`kind` of an event on `swarm/<run>/events` and in summary.json (docs: reference/protocol)."""

    JOIN = "join"
    REJOIN = "rejoin"
    DROP = "drop"
    SWITCH = "switch"
    START = "start"
    ADD = "add"
    PAUSE = "pause"
    RESUME = "resume"
    FAULT = "fault"
    FAULT_SKIPPED = "fault_skipped"
    FAULT_LATE = "fault_late"
    ROGUE = "rogue"
    CRASH = "crash"
    EXIT = "exit"
    LIMIT = "limit"
    DESERTED = "deserted"
    STOP = "stop"  # an operator's `swarm stop`: the run ends as on SIGINT
    STALE = "stale"  # robots: an agent's robot's pose is older than the robots file's stale_after (zero twist)
    FRESH = "fresh"  # robots: its poses come again
    LATE = "late"  # realtime: the world fell a tick or more behind and re-anchored its clock (no burst)
    SAFETY = "safety"  # [safety]: the filter changed an agent's command (the first tick of each spell)


class SwitchReason(StrEnum):
    """The `reason` of a "switch" event: what ground truth says about the follower's change of
    out-neighbour (both engines write these words; "no out-neighbour: ..." takes a suffix)."""

    CHOSEN = "out-neighbour chosen"
    LEFT = "out-neighbour left the world"
    OUT_OF_SIGHT = "out-neighbour out of sight"
    NO_PATH = "out-neighbour has no path to a leader"
    ANOTHER = "another agent chosen"
    PINNED_NOT_SENSED = "pinned out-neighbour not sensed"
    NONE_SEARCHING = "no out-neighbour: searching"
    NONE_LOITERING = "no out-neighbour: loitering"


class AgentState(StrEnum):
    """An agent's state in the world (`WorldCore.state`, the `now` of a "drop" event)."""

    ACTIVE = "active"
    COASTING = "coasting"  # its process died and the scenario says on_dropout = "coast"
    GONE = "gone"


class Phase(StrEnum):
    """The phase an agent reports with its command (`Decision.phase`)."""

    ARC1 = "arc1"  # leaders: the first arc of the circle-circle path
    ARC2 = "arc2"  # leaders: the second arc
    ORBIT = "orbit"  # leaders: on the orbit
    TRACK = "track"  # followers: steering by out, advertising a path through it
    SHADOW = "shadow"  # followers: steering by out without a path to a leader
    SEARCH = "search"  # followers (sticky): nobody to steer by, flying a search pattern
    LOST = "lost"  # followers: nobody to steer by and no search


class FollowState(StrEnum):
    """A follower's selection state under the sticky rule (agents/sticky.py; the states and
    their transitions: docs/design/selection.md#states), reported with its command. Its
    position in FOLLOW_STATES (swarm/contracts/wire.py) is its wire code."""

    NONE = "none"  # leaders, and followers under the other rules (fixed, nearest, rooted)
    ACQUIRE = "acquire"  # no commitment yet: waiting for its nearest agent to root, tracking the nearest rooted one
    KEEP = "keep"  # committed: steering by its out-neighbour, advertising a path through it
    HOLD = "hold"  # its out-neighbour is sensed but lost its path: steering by it, advertising none
    COAST = "coast"  # its out-neighbour left the sensor's reach at the edge: steering by a prediction
    SHADOW = "shadow"  # steering by an agent it may not commit to yet, advertising none
    SEARCH = "search"  # nobody to steer by: flying the search pattern
    LOST = "lost"  # nobody to steer by and no search
    LATE = "late"  # joined a run under way: choosing nobody until its earlier life is forgotten
