"""Zenoh sessions the way ZENOH.md says they work on these machines.

The world is the hub: a router-mode session that listens; everything else is a client
connected to it. Multicast scouting is off everywhere (two runs on defaults hear each
other), and every process sets its own link lease so that a frozen process is noticed
within about a second. Never open a session at import time, never fork after opening.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from swarm.contracts import wire

LEASE_MS = 1000  # a frozen (SIGSTOP) process is dropped after ~0.95 s
CONNECT_TIMEOUT_MS = 10000


def _config(settings: dict):
    import zenoh

    cfg = zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


def hub_config(listen: str):
    return _config({
        "mode": "router",
        "listen/endpoints": [listen],
        "scouting/multicast/enabled": False,
        "scouting/delay": 0,
        "transport/link/tx/lease": LEASE_MS,
        # Small messages over loopback: the 16 MB shared-memory pool would only add RSS.
        "transport/shared_memory/enabled": False,
    })


def client_config(connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS):
    return _config({
        "mode": "client",
        "connect/endpoints": [connect],
        "connect/timeout_ms": timeout_ms,
        "scouting/multicast/enabled": False,
        "transport/link/tx/lease": LEASE_MS,
        # Small messages over loopback: the 16 MB shared-memory pool would only add RSS.
        "transport/shared_memory/enabled": False,
    })


def open_hub(listen: str):
    import zenoh

    return zenoh.open(hub_config(listen))


def open_client(connect: str, timeout_ms: int = CONNECT_TIMEOUT_MS):
    """Open a client session; raises zenoh.ZError when the endpoint does not answer."""
    import zenoh

    return zenoh.open(client_config(connect, timeout_ms))


def runtime_dir() -> Path:
    """Where local runs put their Unix sockets ($SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)."""
    d = Path(os.environ.get("SWARM_RUNTIME_DIR") or Path(tempfile.gettempdir()) / f"swarm-{os.getuid()}")
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    return d


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
