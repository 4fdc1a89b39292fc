"""How an agent process finds its run and claims its id (the world's join query, which
also hands it its configuration), and how it ends: `AgentExit` with an exit code."""

from __future__ import annotations

import os
import socket
from typing import Any

from swarm.contracts import wire
from swarm.contracts.vocabulary import ExitCode


class AgentExit(BaseException):  # also raised by signal handlers: never swallowed by `except Exception`
    def __init__(self, code: int, message: str = ""):
        super().__init__(message)
        self.code = code
        self.message = message


def claim(session: Any, run: str, agent_id: int, timeout: float = 5.0, spec: dict | None = None) -> dict:
    """Ask the world for agent_id (a new agent brings its spec); returns the reply or raises AgentExit."""
    req = wire.encode_join_request(agent_id, os.getpid(), socket.gethostname(), spec)
    replies = list(session.get(wire.agent_key(run, agent_id, "join"), payload=req, timeout=timeout))
    for r in replies:
        if r.ok is None:
            continue
        try:
            rep = wire.decode_join_reply(r.ok.payload.to_bytes())
        except wire.WireError as e:
            raise AgentExit(ExitCode.REFUSED, f"agent {agent_id}: bad join reply: {e}") from None
        if not rep["ok"]:
            raise AgentExit(ExitCode.REFUSED, f"agent {agent_id} refused: {rep['error']}")
        return rep
    # no world to join: nothing listens on the endpoint, or no world of the run answers
    raise AgentExit(ExitCode.NO_WORLD, f"agent {agent_id}: no world of run {run!r} answered its join query")
