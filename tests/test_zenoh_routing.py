"""What zenoh 1.10 does with the hub's rules when agents sit behind a router of their own
host (the multi-host layout of issue 12), measured so that the design can rely on it:

- the hub judges the link a message came in on, so it sees the host router, not the agent:
  the host router's identity gets the union of the rules of the agents it hosts;
- the host router checks its own agents with the same rules (swarm/contracts/access.py),
  and needs a subject for its upstream link (by the hub's zid), or its default deny drops
  everything to and from the hub.

Real zenoh sessions in this process, Unix sockets in a private directory; a few seconds.
"""

from __future__ import annotations

import json
import time

import pytest

from swarm.contracts import access

RUN = "r"


def _open(settings: dict):
    import zenoh

    cfg = zenoh.Config()
    for k, v in {"scouting/multicast/enabled": False, "transport/shared_memory/enabled": False,
                 "scouting/delay": 0, **settings}.items():
        cfg.insert_json5(k, json.dumps(v))
    return zenoh.open(cfg)


def _wait(cond, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.02)
    return cond()


@pytest.fixture
def layout(tmp_path):
    """hub (agents 1 and 2 known; host-a hosts agent 1) <- host router a <- agent 1."""
    hub_ep, a_ep = f"unixsock-stream/{tmp_path}/hub.sock", f"unixsock-stream/{tmp_path}/a.sock"
    (tmp_path / "hub.users").write_text("operator:op\nagent-1:a1\nagent-2:a2\nhost-a:ha\n")
    (tmp_path / "a.users").write_text("agent-1:a1\n")
    acl = access.access_control(RUN, [1, 2])
    acl["subjects"].append({"id": "host-a", "usernames": ["host-a"]})
    acl["policies"].append({"rules": [r["id"] for r in access.agent_rules(RUN, 1)] + ["egress"],
                            "subjects": ["host-a"]})
    sessions = []
    try:
        hub = _open({"mode": "router", "listen/endpoints": [hub_ep], "access_control": acl,
                     "transport/auth/usrpwd": {"user": "world", "password": "w",
                                               "dictionary_file": str(tmp_path / "hub.users")}})
        sessions.append(hub)
        acl_a = access.access_control(RUN, [1])
        acl_a["rules"].append({"id": "upstream", "permission": "allow", "flows": ["ingress", "egress"],
                               "messages": access.ALL_MESSAGES, "key_exprs": [f"swarm/{RUN}/**"]})
        acl_a["subjects"].append({"id": "hub", "zids": [str(hub.info.zid())]})
        acl_a["policies"].append({"rules": ["upstream"], "subjects": ["hub"]})
        host = _open({"mode": "router", "listen/endpoints": [a_ep], "connect/endpoints": [hub_ep],
                      "access_control": acl_a,
                      "transport/auth/usrpwd": {"user": "host-a", "password": "ha",
                                                "dictionary_file": str(tmp_path / "a.users")}})
        sessions.append(host)

        def client(user, password, timeout_ms=3000):
            s = _open({"mode": "client", "connect/endpoints": [a_ep], "connect/timeout_ms": timeout_ms,
                       "transport/auth/usrpwd": {"user": user, "password": password}})
            sessions.append(s)
            return s

        yield hub, client
    finally:
        for s in reversed(sessions):
            s.close()


def test_an_agent_behind_its_host_router_is_confined_at_both_routers(layout):
    hub, client = layout
    cmds, sense = [], []
    hub.declare_subscriber(f"swarm/{RUN}/agent/*/cmd", lambda s: cmds.append(str(s.key_expr)))
    hub.declare_queryable(f"swarm/{RUN}/agent/*/join", lambda q: q.reply(str(q.key_expr), b"ok"))
    a1 = client("agent-1", "a1")
    a1.declare_subscriber(f"swarm/{RUN}/agent/1/sense", lambda s: sense.append(1))
    time.sleep(0.5)
    assert [r.ok.payload.to_bytes() for r in a1.get(f"swarm/{RUN}/agent/1/join", timeout=2.0) if r.ok] == [b"ok"]
    assert [r for r in a1.get(f"swarm/{RUN}/agent/2/join", timeout=1.0) if r.ok] == []
    a1.put(f"swarm/{RUN}/agent/1/cmd", b"mine")
    a1.put(f"swarm/{RUN}/agent/2/cmd", b"forged")
    hub.put(f"swarm/{RUN}/agent/1/sense", b"frame")
    assert _wait(lambda: cmds and sense)
    time.sleep(0.3)
    assert cmds == [f"swarm/{RUN}/agent/1/cmd"] and len(sense) == 1
    with pytest.raises(Exception):  # an identity host a does not host
        client("agent-2", "a2", timeout_ms=1500)
