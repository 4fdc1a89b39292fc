"""Zenoh sessions the way ZENOH.md says they work on these machines.

The world is the hub: a router-mode session that listens; everything else is a client
connected to it, either directly or through the router of its agent host (`swarm host`:
a router-mode session on the agent's machine, connected to the hub as `host`). Multicast
scouting is off everywhere (two runs on defaults hear each other), and every process sets its own link lease so that a frozen process is noticed
within about a second. Never open a session at import time, never fork after opening.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts import access, wire
from swarm.contracts.credentials import Credentials
from swarm.contracts.identities import OPERATOR, WORLD
from swarm.contracts.runtime_dir import dial_endpoint as dial_endpoint  # re-exported
from swarm.contracts.runtime_dir import runtime_dir as runtime_dir  # re-exported: the one place it is decided
from swarm.contracts.runtime_dir import write_private

LEASE_MS = 1000  # a frozen (SIGSTOP) process is dropped after ~0.95 s
CONNECT_TIMEOUT_MS = 10000
# The routers (the hub, an agent host's router) send many agents' express messages on one
# link: a world's frames to a host router, a host's commands to the hub. zenoh's default
# queue (2 batches of DATA per link, a message dropped after waiting 1 ms for room) lost
# frames and commands on a loaded 2-core machine: 6 in 10,000 with 10 agents behind a
# router, 10% with 20 and two CPU hogs. 16 batches (zenoh's largest: 32 made every link fail)
# and 50 ms lost none in 40,000 with the hogs. A frozen peer does not fill the queue within
# the 1 s lease (the sockets' buffers take that long), so the wait only covers a starved
# sending thread.
ROUTER_QUEUE = {
    "transport/link/tx/queue/size/data": 16,
    "transport/link/tx/queue/congestion_control/drop/wait_before_drop": 50_000,  # us
}


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
    supervisor: str | None = None  # the launcher's password (identities.ENV_SUPERVISOR); None: no supervisor


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
        **ROUTER_QUEUE,
    }
    if auth is not None:
        run = auth.creds.run
        user, password = auth.creds.identity(WORLD)
        settings.update({
            "transport/auth/usrpwd": {"user": user, "password": password, "dictionary_file": str(dictionary)},
            "access_control": access.access_control(run, auth.agent_ids, host=True),
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
    write_private(dictionary, access.user_dictionary(auth.creds.secret, auth.creds.run, auth.agent_ids,
                                                     host=True, supervisor=auth.supervisor).encode())
    try:
        return zenoh.open(hub_config(listen, auth, dictionary))
    finally:
        dictionary.unlink(missing_ok=True)


def host_router_config(listen: str, upstream: str, run: str, identity: tuple[str, str] | None = None,
                       dictionary: Path | None = None, acl: dict | None = None, tls: dict | None = None):
    """An agent host's router (swarm/host.py): listens on `listen` for its own agents and
    connects to the run's hub at `upstream`, as `identity` (the run's `host`). With
    `dictionary` and `acl`, only its agents get in, each confined as at the hub."""
    settings = {
        "mode": "router",
        "listen/endpoints": [listen],
        "connect/endpoints": [upstream],
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "transport/link/tx/lease": LEASE_MS,
        "transport/shared_memory/enabled": False,
        **ROUTER_QUEUE,
    }
    if identity is not None:
        usrpwd = {"user": identity[0], "password": identity[1]}
        if dictionary is not None:
            usrpwd["dictionary_file"] = str(dictionary)
        settings["transport/auth/usrpwd"] = usrpwd
    if acl is not None:
        settings.update({
            "access_control": acl,
            "low_pass_filter": access.size_filters(run),
            "transport/link/rx/max_message_size": access.MAX_MESSAGE,
        })
    settings.update(tls or {})
    return _config(settings)


def open_client(connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS, creds: Credentials | None = None,
                user: str = OPERATOR):
    """Open a client session as `user` (with `creds`; without, only an open hub lets it in);
    raises zenoh.ZError when the endpoint does not answer or refuses the identity."""
    import zenoh

    identity = creds.identity(user) if creds is not None and not creds.hub_is_open else None
    tls = _client_tls(creds) if creds is not None and connect.startswith("tls/") else None
    return zenoh.open(client_config(connect, timeout_ms, identity, tls))


def client_tls(creds: Credentials) -> dict | None:
    """TLS settings for a session that dials the run's `tls/` endpoint (from its credentials)."""
    return _client_tls(creds)


def _client_tls(creds: Credentials) -> dict | None:
    from swarm.contracts import tls

    return tls.client_settings_for(creds)


def default_endpoint(run: str) -> str:
    return f"unixsock-stream/{runtime_dir() / (run + '.sock')}"


def socket_path(endpoint: str) -> Path | None:
    prefix = "unixsock-stream/"
    return Path(endpoint[len(prefix):].split("#")[0]) if endpoint.startswith(prefix) else None


QUERY_TIMEOUT = 1.0  # s


def answer(query, key: str, payload: bytes) -> None:
    """Reply to a zenoh query and finish it at once. zenoh ends a query (its asker stops
    waiting) only when the last reference to the Query object goes; one kept by a loop
    variable or a batch list made askers wait out their own timeout (swarm pause: 1.1 s)."""
    try:
        query.reply(key, payload)
    finally:
        query.drop()


def query_statuses(session, run: str, timeout: float = QUERY_TIMEOUT, expected=None) -> dict[int, dict]:
    """Each live agent's own status, from one query to every agent's status queryable
    (malformed replies skipped). It ends once every agent of `expected` (e.g. the live ones
    of the world's info) has answered, or at the query's timeout (`expected` None: always)."""
    want = None if expected is None else set(expected)
    out: dict[int, dict] = {}
    if want is not None and not want:
        return out
    import zenoh

    # No consolidation: zenoh's default holds every reply until the query ends (its timeout)
    replies = session.get(wire.agent_key(run, "*", "status"), timeout=timeout,
                          consolidation=zenoh.ConsolidationMode.NONE)
    for r in replies:
        if r.ok is None:
            continue
        try:
            aid = wire.agent_of_key(str(r.ok.key_expr))
            st = wire.decode_status(r.ok.payload.to_bytes())
        except wire.WireError:
            continue
        if st["id"] == aid:
            out[aid] = st
        if want is not None and want <= out.keys():
            break
    return out
