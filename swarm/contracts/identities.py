"""Who may connect to a run: its identities and their passwords.

Each process that connects has an identity (a zenoh username): `operator` (the launcher
and the CLI), `agent-<id>` (one per agent), `host` (the router of an agent host: `swarm
host`) and `world` (the hub itself), with a password derived from the run's secret; and
`supervisor` (the `swarm up` launcher alone), whose password the launcher makes and hands
to its world only, so that no credentials file holds it. An
agent host also has a name of its own (a label, not an identity). The hub's rules
(swarm/contracts/access.py) need only these; the files that carry them are
swarm/contracts/credentials.py's. `CredentialsError` is the one error (one line) of
identities, credentials files and the runtime directory.
"""

from __future__ import annotations

import hashlib
import hmac
import re

OPERATOR = "operator"
WORLD = "world"
HOST = "host"  # the router of an agent host (swarm/runtime/host.py)
SUPERVISOR = "supervisor"  # the launcher (`swarm up`) alone: reports agent exits and faults done
# The supervisor's password: made by the launcher, given to its world in this environment
# variable, never written to a file (so no credentials file, and no operator, holds it).
ENV_SUPERVISOR = "SWARM_SUPERVISOR_PASSWORD"
_HOST_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,32}$")


class CredentialsError(Exception):
    """A credentials file or the runtime directory cannot be used; the message is one line."""


def agent_user(agent_id: int) -> str:
    return f"agent-{int(agent_id)}"


def check_host_name(name: str) -> str:
    """A host's name (a label: file and socket names, logs): 1-32 of A-Z a-z 0-9 _ . -"""
    if not isinstance(name, str) or not _HOST_NAME.match(name):
        raise CredentialsError(f"host name {name!r}: expected 1 to 32 of A-Z a-z 0-9 _ . -")
    return name


def password_for(secret: str, run: str, user: str) -> str:
    """The password of `user` in run `run` (HMAC-SHA256 of the run's secret; 128 bits)."""
    return hmac.new(bytes.fromhex(secret), f"{run}/{user}".encode(), hashlib.sha256).hexdigest()[:32]
