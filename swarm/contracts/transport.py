"""Zenoh sessions the way ZENOH.md says they work on these machines.

The world is the hub: a router-mode session that listens; everything else is a client
connected to it. Multicast scouting is off everywhere (two runs on defaults hear each
other), and every process sets its own link lease so that a frozen process is noticed
within about a second. Never open a session at import time, never fork after opening.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts import access, wire
from swarm.contracts.credentials import OPERATOR, WORLD, Credentials, write_private
from swarm.contracts.credentials import dial_endpoint as dial_endpoint  # re-exported
from swarm.contracts.credentials import runtime_dir as runtime_dir  # re-exported: the one place it is decided

LEASE_MS = 1000  # a frozen (SIGSTOP) process is dropped after ~0.95 s
CONNECT_TIMEOUT_MS = 10000


def _config(settings: dict):
    import zenoh

    cfg = zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


# For benchmarks and debugging only: a hub that accepts anyone and checks nothing
# (docs/protocol.md, threat model). Clients with credentials still connect to it.
ENV_OPEN_HUB = "SWARM_OPEN_HUB"


@dataclass(frozen=True)
class HubAuth:
    """What the hub needs to check who connects and what they may do."""

    creds: Credentials  # the run's own credentials (with its secret)
    agent_ids: tuple[int, ...]  # every id an agent of this run may take
    tls: dict | None = None  # zenoh settings for a tls/ endpoint (swarm/contracts/tls.py)


def open_hub_requested() -> bool:
    return os.environ.get(ENV_OPEN_HUB, "") not in ("", "0")


def hub_config(listen: str, auth: HubAuth | None = None, dictionary: Path | None = None):
    settings = {
        "mode": "router",
        "listen/endpoints": [listen],
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "transport/link/tx/lease": LEASE_MS,
        # Small messages over loopback: the 16 MB shared-memory pool would only add RSS.
        "transport/shared_memory/enabled": False,
    }
    if auth is not None:
        run = auth.creds.run
        user, password = auth.creds.identity(WORLD)
        settings.update({
            "transport/auth/usrpwd": {"user": user, "password": password, "dictionary_file": str(dictionary)},
            "access_control": access.access_control(run, auth.agent_ids),
            "low_pass_filter": access.size_filters(run),
            "transport/link/rx/max_message_size": access.MAX_MESSAGE,
            **(auth.tls or {}),
        })
    return _config(settings)


def client_config(connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS, identity: tuple[str, str] | None = None,
                  tls: dict | None = None):
    settings = {
        "mode": "client",
        "connect/endpoints": [connect],
        "connect/timeout_ms": timeout_ms,
        "scouting/multicast/enabled": False,
        "transport/link/tx/lease": LEASE_MS,
        # Small messages over loopback: the 16 MB shared-memory pool would only add RSS.
        "transport/shared_memory/enabled": False,
    }
    if identity is not None:
        settings["transport/auth/usrpwd"] = {"user": identity[0], "password": identity[1]}
    settings.update(tls or {})
    return _config(settings)


def open_hub(listen: str, auth: HubAuth | None = None):
    """Open the run's hub. With `auth`, only the run's identities may connect and each may
    do only what swarm/contracts/access.py allows. zenoh reads the user dictionary once,
    at open: it lives in a private file for that moment only."""
    import zenoh

    if auth is None:
        return zenoh.open(hub_config(listen))
    dictionary = runtime_dir() / f".{auth.creds.run}.users"
    write_private(dictionary, access.user_dictionary(auth.creds.secret, auth.creds.run, auth.agent_ids).encode())
    try:
        return zenoh.open(hub_config(listen, auth, dictionary))
    finally:
        dictionary.unlink(missing_ok=True)


def open_client(connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS, creds: Credentials | None = None,
                user: str = OPERATOR):
    """Open a client session as `user` (with `creds`; without, only an open hub lets it in);
    raises zenoh.ZError when the endpoint does not answer or refuses the identity."""
    import zenoh

    identity = creds.identity(user) if creds is not None and not creds.hub_is_open else None
    tls = _client_tls(creds) if creds is not None and connect.startswith("tls/") else None
    return zenoh.open(client_config(connect, timeout_ms, identity, tls))


def _client_tls(creds: Credentials) -> dict | None:
    from swarm.contracts import tls

    return tls.client_settings_for(creds)


def default_endpoint(run: str) -> str:
    return f"unixsock-stream/{runtime_dir() / (run + '.sock')}"


def socket_path(endpoint: str) -> Path | None:
    prefix = "unixsock-stream/"
    return Path(endpoint[len(prefix):].split("#")[0]) if endpoint.startswith(prefix) else None


QUERY_TIMEOUT = 1.0  # s


def query_statuses(session, run: str, timeout: float = QUERY_TIMEOUT) -> dict[int, dict]:
    """Each live agent's own status, from its status queryable (malformed replies skipped)."""
    out: dict[int, dict] = {}
    for r in session.get(wire.agent_key(run, "*", "status"), timeout=timeout):
        if r.ok is None:
            continue
        try:
            aid = wire.agent_of_key(str(r.ok.key_expr))
            st = wire.decode_status(r.ok.payload.to_bytes())
        except wire.WireError:
            continue
        if st["id"] == aid:
            out[aid] = st
    return out
