"""Zenoh sessions, set up the same way for every process of a run (docs/design/architecture.md#zenoh).

The world is the hub: a router-mode session that listens; everything else is a client
connected to it, either directly or through the router of its agent host (`swarm host`:
a router-mode session on the agent's machine, connected to the hub as `host`). Multicast
scouting is off everywhere (two runs on defaults hear each other), and every process sets
its own link lease so that a frozen process is noticed within about a second. Never open a
session at import time, never fork after opening.
Routers keep their door open to the run's own processes while strangers crowd it (`DOOR`,
`listen_endpoint`), and a hub on tcp/ or tls/ has a local door too (`local_door`).
"""

from __future__ import annotations

import json
import os
import resource
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarm.contracts import access, tls, wire
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


# The door (docs/guides/security.md#door): zenoh gives a connection that has
# not finished its handshake one of `accept_pending` places (default 100) for up to
# `accept_timeout` (default 10 s) and closes any that comes while they are all taken. 300 idle
# TCP connections from a stranger (reopened as soon as closed) kept every place taken: the
# run's own CLI and agents were shut out for as long as they were held. With more places than
# that and a 2 s limit the run's own sessions (a handshake of a few ms on loopback, well
# under 2 s on any link we support) got in within 2 s throughout. A place costs an open file
# and a small task; the hub's limit on open files is raised to fit (raise_open_files).
ACCEPT_PENDING = 4096
ACCEPT_TIMEOUT_MS = 2000
# TLS links do their TLS handshake before zenoh's places (tls-listener, every handshake at
# once), and zenoh's TLS acceptor sleeps 100 ms after *each* failed handshake, one at a time
# (eclipse-zenoh/zenoh#2685; not configurable in 1.10): with the default 10 s handshake limit
# 300 idle connections failed 30 handshakes a second, which kept it asleep. Idle strangers
# that are left waiting fail none; those that give up still cost 100 ms each (measured:
# docs/guides/security.md#door).
TLS_HANDSHAKE_TIMEOUT_MS = 600_000
DOOR = {
    "transport/unicast/accept_pending": ACCEPT_PENDING,
    "transport/unicast/accept_timeout": ACCEPT_TIMEOUT_MS,
}


def listen_endpoint(listen: str) -> str:
    """`listen` as a router is told to listen on it: a tls/ endpoint with its handshake limit."""
    if not listen.startswith("tls/") or "tls_handshake_timeout_ms" in listen:
        return listen
    return listen + (";" if "#" in listen else "#") + f"tls_handshake_timeout_ms={TLS_HANDSHAKE_TIMEOUT_MS}"


def raise_open_files(want: int = ACCEPT_PENDING + 1024) -> None:
    """Lift this process's soft limit on open files towards `want` (never past the hard one):
    a router holds one per waiting connection."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = want if hard == resource.RLIM_INFINITY else min(want, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (ValueError, OSError):
            pass


def _config(settings: dict) -> Any:
    import zenoh  # lazy: only a process that opens a session loads zenoh's native library

    cfg = zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


# For benchmarks and debugging only: a hub that accepts anyone and checks nothing
# (docs/reference/protocol.md#security). Clients with credentials still connect to it.
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


def hub_config(
    listen: str, auth: HubAuth | None = None, dictionary: Path | None = None, door: str | None = None
) -> Any:
    settings = {
        "mode": "router",
        "listen/endpoints": [listen_endpoint(listen)] + ([door] if door else []),
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "transport/link/tx/lease": LEASE_MS,
        # Small messages over loopback: the 16 MB shared-memory pool would only add RSS.
        "transport/shared_memory/enabled": False,
        **ROUTER_QUEUE,
        **DOOR,
    }
    if auth is not None:
        run = auth.creds.run
        user, password = auth.creds.identity(WORLD)
        settings.update(
            {
                "transport/auth/usrpwd": {"user": user, "password": password, "dictionary_file": str(dictionary)},
                "access_control": access.access_control(run, auth.agent_ids, host=True),
                "low_pass_filter": access.size_filters(run),
                "transport/link/rx/max_message_size": access.MAX_MESSAGE,
                **(auth.tls or {}),
            }
        )
    return _config(settings)


def client_config(
    connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS, identity: tuple[str, str] | None = None, tls: dict | None = None
) -> Any:
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


def open_hub(listen: str, auth: HubAuth | None = None) -> Any:
    """Open the run's hub. With `auth`, only the run's identities may connect and each may
    do only what swarm/contracts/access.py allows. zenoh reads the user dictionary once,
    at open: it lives in a private file for that moment only."""
    import zenoh  # lazy: only a process that opens a session loads zenoh's native library

    raise_open_files()
    if auth is None:
        return zenoh.open(hub_config(listen))
    secret = auth.creds.secret
    if secret is None:
        raise ValueError("the hub needs the run's own credentials (with its secret)")
    dictionary = runtime_dir() / f".{auth.creds.run}.users"
    door = local_door(auth.creds.run) if socket_path(listen) is None else None
    try:
        write_private(
            dictionary,
            access.user_dictionary(
                secret, auth.creds.run, auth.agent_ids, host=True, supervisor=auth.supervisor
            ).encode(),
        )
        if door is not None and len(str(socket_path(door))) <= 100:  # (Unix socket paths: < 108 bytes)
            try:
                return zenoh.open(hub_config(listen, auth, dictionary, door))
            except zenoh.ZError:
                pass  # its own door could not open: the run listens on `listen` only
        return zenoh.open(hub_config(listen, auth, dictionary))
    finally:
        dictionary.unlink(missing_ok=True)


def door_of(connect: str, creds: Credentials | None) -> str | None:
    """The local door of the run of `creds` if `connect` is that run's own tcp/ or tls/
    endpoint and the door answers on this machine, else None."""
    if creds is None or socket_path(connect) is not None or not connect.startswith(("tcp/", "tls/")):
        return None
    if dial_endpoint(connect) != dial_endpoint(creds.endpoint):
        return None
    door = local_door(creds.run)
    path = socket_path(door)
    if path is None or not path.exists():
        return None
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        try:
            s.connect(str(path))
        except OSError:
            return None
    return door


def local_door(run: str) -> str:
    """The run's door on its own machine: a Unix socket in the (private) runtime dir that the hub
    of a run on tcp/ or tls/ listens on too, with the same checks, so that the commands and
    agents started there never queue behind strangers at the network port (docs/guides/security.md#door)."""
    return f"unixsock-stream/{runtime_dir() / (run + '.door.sock')}"


def host_router_config(
    listen: str,
    upstream: str,
    run: str,
    identity: tuple[str, str] | None = None,
    dictionary: Path | None = None,
    acl: dict | None = None,
    tls: dict | None = None,
) -> Any:
    """An agent host's router (swarm/runtime/host.py): listens on `listen` for its own agents and
    connects to the run's hub at `upstream`, as `identity` (the run's `host`). With
    `dictionary` and `acl`, only its agents get in, each confined as at the hub."""
    settings = {
        "mode": "router",
        "listen/endpoints": [listen_endpoint(listen)],
        "connect/endpoints": [upstream],
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "transport/link/tx/lease": LEASE_MS,
        "transport/shared_memory/enabled": False,
        **ROUTER_QUEUE,
        **DOOR,
    }
    if identity is not None:
        usrpwd = {"user": identity[0], "password": identity[1]}
        if dictionary is not None:
            usrpwd["dictionary_file"] = str(dictionary)
        settings["transport/auth/usrpwd"] = usrpwd
    if acl is not None:
        settings.update(
            {
                "access_control": acl,
                "low_pass_filter": access.size_filters(run),
                "transport/link/rx/max_message_size": access.MAX_MESSAGE,
            }
        )
    settings.update(tls or {})
    return _config(settings)


def open_client(
    connect: str,
    timeout_ms: int = CONNECT_TIMEOUT_MS,
    creds: Credentials | None = None,
    user: str = OPERATOR,
    door: bool = True,
) -> Any:
    """Open a client session as `user` (with `creds`; without, only an open hub lets it in);
    raises zenoh.ZError when the endpoint does not answer or refuses the identity. With
    `door`, a session to its run's own endpoint goes through the run's local door when the
    hub has one on this machine (`local_door`), falling back to `connect`."""
    import zenoh  # lazy: only a process that opens a session loads zenoh's native library

    identity = creds.identity(user) if creds is not None and not creds.hub_is_open else None
    via = door_of(connect, creds) if door else None
    if via is not None:
        try:
            return zenoh.open(client_config(via, timeout_ms, identity))
        except zenoh.ZError:
            pass
    tls = _client_tls(creds) if creds is not None and connect.startswith("tls/") else None
    return zenoh.open(client_config(connect, timeout_ms, identity, tls))


def client_tls(creds: Credentials) -> dict | None:
    """TLS settings for a session that dials the run's `tls/` endpoint (from its credentials)."""
    return _client_tls(creds)


def _client_tls(creds: Credentials) -> dict | None:
    return tls.client_settings_for(creds)


def default_endpoint(run: str) -> str:
    return f"unixsock-stream/{runtime_dir() / (run + '.sock')}"


def socket_path(endpoint: str) -> Path | None:
    prefix = "unixsock-stream/"
    return Path(endpoint[len(prefix) :].split("#")[0]) if endpoint.startswith(prefix) else None


QUERY_TIMEOUT = 1.0  # s


def answer(query: Any, key: str, payload: bytes) -> None:
    """Reply to a zenoh query and finish it at once. zenoh ends a query (its asker stops
    waiting) only when the last reference to the Query object goes; one kept by a loop
    variable or a batch list made askers wait out their own timeout (swarm pause: 1.1 s)."""
    try:
        query.reply(key, payload)
    finally:
        query.drop()


def query_statuses(session: Any, run: str, timeout: float = QUERY_TIMEOUT, expected: Any = None) -> dict[int, dict]:
    """Each live agent's own status, from one query to every agent's status queryable
    (malformed replies skipped). It ends once every agent of `expected` (e.g. the live ones
    of the world's info) has answered, or at the query's timeout (`expected` None: always)."""
    want = None if expected is None else set(expected)
    out: dict[int, dict] = {}
    if want is not None and not want:
        return out
    import zenoh  # lazy: only a process that opens a session loads zenoh's native library

    # No consolidation: zenoh's default holds every reply until the query ends (its timeout)
    replies = session.get(
        wire.agent_key(run, "*", "status"), timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE
    )
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
