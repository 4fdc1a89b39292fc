"""Who owns each agent id of a run: the world's book per agent process, and admission.

An agent process claims its id with a join request; the world accepts at most one
process per id (the claim waits CLAIM_TTL s for the process's liveliness token) and gives
it a random 64-bit claim key that every command must carry. A new agent (not in the
scenario) brings a spec, checked like a scenario's [[agents]] entry. No I/O here: the
world process (world/process.py) decodes the request and sends the reply.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from swarm.contracts import wire
from swarm.contracts.scenario import format_validation_error
from swarm.contracts.scenario_tables import AgentSpec
from swarm.world.core import ACTIVE, WorldCore

CLAIM_TTL = 10.0  # s: an accepted join claim waits this long for the agent's token
CHURN_EVENTS = 500  # join/rejoin/drop events written per agent; later ones are counted only


@dataclass
class AgentBook:
    """What the world keeps about one agent's process (not its physics)."""

    pid: int | None = None
    host: str | None = None
    claim_until: float = 0.0  # join accepted, waiting for the token until then (monotonic s)
    commands: int = 0
    missed: int = 0  # lockstep: ticks stepped on a held command after the deadline
    stale_sum: int = 0  # realtime: sum over ticks of (tick - tick of the command used)
    stale_max: int = 0
    last_cmd_tick: int = -1
    last_cmd_wall: float = 0.0
    joins: int = 0
    drops: int = 0
    garbage: int = 0
    key: int | None = None  # claim key of the process that owns the id; commands must carry it
    rogue: int = 0  # commands on this agent's key without its owner's claim key
    rogue_noted: float = 0.0
    flooded: int = 0  # messages on this agent's keys dropped: more than its share waiting (world/inbox.py)
    churn: int = 0  # join, rejoin and drop events; past CHURN_EVENTS they are counted, not written
    churn_unwritten: int = 0


def new_agent_spec(aid: int, spec: object, core: WorldCore) -> AgentSpec:
    """The AgentSpec of an agent added at run time (`swarm spawn`); WireError names the field."""
    if aid in core.index:
        raise wire.WireError(f"agent {aid} already exists")
    if not isinstance(spec, dict):
        raise wire.WireError("spec: expected a JSON object")
    try:
        a = AgentSpec.model_validate({**spec, "id": aid})
    except ValidationError as e:
        raise wire.WireError(format_validation_error(f"agent {aid} spec", e).replace("\n", ";")) from None
    if a.follow is not None and a.follow not in core.index:
        raise wire.WireError(f"agent {aid} spec: follow: no agent has id {a.follow}")
    if a.role == "follower" and a.follow is None and core.scenario.sensing.selection == "fixed":
        raise wire.WireError(
            f'agent {aid} spec: follow: this run pins its graph (selection = "fixed"); a new follower needs --follow J'
        )
    return a


def admit(core: WorldCore, book: AgentBook, req: dict, now: float) -> int:
    """Accept the claim `req` (a decoded join request) on an id the world knows: returns
    the new claim key, or raises WireError when a process already owns the id."""
    aid = req["id"]
    if (core.state[core.index[aid]] == ACTIVE and book.key is not None) or book.claim_until > now:
        raise wire.WireError(f"agent {aid} is already live (pid {book.pid} on {book.host})")
    book.pid, book.host, book.claim_until = req["pid"], req["host"], now + CLAIM_TTL
    book.key = secrets.randbits(64)
    return book.key


def agent_figures(
    book: AgentBook, ticks: int, realtime: bool, garbage: int = 0, nonfinite: int = 0, **selection: Any
) -> dict:
    """One agent's process figures for summary.json (see docs/reference/outputs.md#summary);
    `garbage`, `nonfinite` and `selection` (losses, loss_switches_max) are what the agent
    counted itself (its status)."""
    n = max(ticks, 1)
    return {
        "pid": book.pid,
        "host": book.host,
        "commands": book.commands,
        "missed_ticks": book.missed,
        "joins": book.joins,
        "drops": book.drops,
        "garbage": book.garbage + garbage,
        "rogue_commands": book.rogue,
        "nonfinite": nonfinite,
        "flooded_messages": book.flooded,
        "churn_events_unwritten": book.churn_unwritten,
        **selection,
        **({"staleness_mean_ticks": book.stale_sum / n, "staleness_max_ticks": book.stale_max} if realtime else {}),
    }
