"""What zenoh 1.10 does with the hub's rules when agents sit behind a router of their own
host (the multi-host layout: docs/guides/several-machines.md#hosts), measured so that the design can rely on it:

- the hub judges the link a message came in on, so it sees the host router, not the agent:
  the host router's identity gets the union of the rules of the agents it hosts;
- the host router checks its own agents with the same rules (swarm/contracts/access.py),
  and needs a subject for its upstream link (by the hub's zid), or its default deny drops
  everything to and from the hub.

The last two tests use the settings `swarm world` and `swarm host` open with (two hosts
sharing the run's `host` identity). Real zenoh sessions in this process, Unix sockets in a
private directory; a few seconds.
"""

from __future__ import annotations

import json
import time

import pytest
import zenoh
from deadlines import DEADLINE

from swarm.contracts import access
from swarm.contracts import credentials as C
from swarm.contracts import transport as T

# Long tier: each test waits out zenoh's connect and query timeouts to show what is refused.
pytestmark = pytest.mark.slow

RUN = "r"


def _open(settings: dict):
    cfg = zenoh.Config()
    for k, v in {
        "scouting/multicast/enabled": False,
        "transport/shared_memory/enabled": False,
        "scouting/delay": 0,
        **settings,
    }.items():
        cfg.insert_json5(k, json.dumps(v))
    return zenoh.open(cfg)


def _wait(cond, timeout=DEADLINE):
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
    acl["policies"].append(
        {"rules": [r["id"] for r in access.agent_rules(RUN, 1)] + ["egress"], "subjects": ["host-a"]}
    )
    sessions = []
    try:
        hub = _open(
            {
                "mode": "router",
                "listen/endpoints": [hub_ep],
                "access_control": acl,
                "transport/auth/usrpwd": {
                    "user": "world",
                    "password": "w",
                    "dictionary_file": str(tmp_path / "hub.users"),
                },
            }
        )
        sessions.append(hub)
        acl_a = access.access_control(RUN, [1])
        acl_a["rules"].append(
            {
                "id": "upstream",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": access.ALL_MESSAGES,
                "key_exprs": [f"swarm/{RUN}/**"],
            }
        )
        acl_a["subjects"].append({"id": "hub", "zids": [str(hub.info.zid())]})
        acl_a["policies"].append({"rules": ["upstream"], "subjects": ["hub"]})
        host = _open(
            {
                "mode": "router",
                "listen/endpoints": [a_ep],
                "connect/endpoints": [hub_ep],
                "access_control": acl_a,
                "transport/auth/usrpwd": {
                    "user": "host-a",
                    "password": "ha",
                    "dictionary_file": str(tmp_path / "a.users"),
                },
            }
        )
        sessions.append(host)

        def client(user, password, timeout_ms=3000):
            s = _open(
                {
                    "mode": "client",
                    "connect/endpoints": [a_ep],
                    "connect/timeout_ms": timeout_ms,
                    "transport/auth/usrpwd": {"user": user, "password": password},
                }
            )
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
    with pytest.raises(zenoh.ZError):  # an identity host a does not host
        client("agent-2", "a2", timeout_ms=1500)


@pytest.fixture
def swarm_layout(tmp_path, monkeypatch):
    """The layout as `swarm world` and `swarm host` make it (swarm/contracts/transport.py,
    access.py, swarm/runtime/host.py's settings): a hub with the run's identities (agents 1-4 and
    `host`), two host routers connected as `host` (a: agents 1, 2; b: agents 3, 4)."""

    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(tmp_path))
    hub_ep = f"unixsock-stream/{tmp_path}/hub.sock"
    own = C.new_credentials(RUN, hub_ep, ids=(1, 2, 3, 4), added_ids=(5, 4))
    sessions = []
    try:
        hub = T.open_hub(hub_ep, T.HubAuth(own, (1, 2, 3, 4)))
        sessions.append(hub)
        hosts = {}
        for name, ids in (("a", (1, 2)), ("b", (3, 4))):
            hc = own.export_host(name, ids)
            users = tmp_path / f"{name}.users"
            C.write_private(users, access.host_dictionary(hc.identity(C.agent_user(a)) for a in ids).encode())
            ep = f"unixsock-stream/{tmp_path}/{name}.sock"
            sessions.append(
                zenoh.open(
                    T.host_router_config(
                        ep,
                        hub_ep,
                        RUN,
                        hc.identity(C.HOST),
                        users,
                        access.host_router_access(RUN, ids, str(hub.info.zid())),
                    )
                )
            )
            users.unlink()
            hosts[name] = (ep, hc)

        def client(host, user, creds=None, timeout_ms=3000):
            ep, hc = hosts[host] if host in hosts else (hub_ep, None)
            s = T.open_client(ep, timeout_ms, creds=creds or hc, user=user)
            sessions.append(s)
            return s

        yield hub, client, own
    finally:
        for s in reversed(sessions):
            s.close()


def test_agents_on_two_hosts_share_the_host_identity_and_stay_confined(swarm_layout):
    hub, client, own = swarm_layout
    cmds, frames = [], []
    hub.declare_subscriber(f"swarm/{RUN}/agent/*/cmd", lambda s: cmds.append(str(s.key_expr)))
    a1, b3 = client("a", "agent-1"), client("b", "agent-3")
    for s, aid in ((a1, 1), (b3, 3)):
        s.declare_subscriber(f"swarm/{RUN}/agent/{aid}/sense", lambda s_, aid=aid: frames.append(aid))
    time.sleep(0.5)
    for s, aid, other in ((a1, 1, 2), (a1, 1, 3), (b3, 3, 4), (b3, 3, 1)):
        s.put(f"swarm/{RUN}/agent/{aid}/cmd", b"mine")
        s.put(f"swarm/{RUN}/agent/{other}/cmd", b"forged")  # its host-mate's, or the other host's
    for aid in (1, 3):
        hub.put(f"swarm/{RUN}/agent/{aid}/sense", b"frame")
    assert _wait(lambda: len(cmds) >= 4 and len(frames) >= 2)
    time.sleep(0.3)
    assert sorted(set(cmds)) == [f"swarm/{RUN}/agent/1/cmd", f"swarm/{RUN}/agent/3/cmd"] and sorted(frames) == [1, 3]
    for host, user in (("a", "agent-3"), ("b", "agent-1"), ("a", "operator")):  # not this host's identities
        with pytest.raises(zenoh.ZError):
            client(host, user, creds=own, timeout_ms=800)


def test_the_host_identity_at_the_hub_is_any_agent_never_the_operator(swarm_layout):
    """What a stolen host file gives at the hub: every agent's keys (the hub cannot tell who
    is behind a host router), none of the operator's or the world's."""
    hub, client, own = swarm_layout
    got = {"truth": [], "cmd": [], "ctl": [], "control": []}
    hub.declare_subscriber(f"swarm/{RUN}/agent/*/cmd", lambda s: got["cmd"].append(str(s.key_expr)))
    hub.declare_subscriber(f"swarm/{RUN}/world/control", lambda s: got["control"].append(1))
    hub.declare_queryable(f"swarm/{RUN}/world/admin", lambda q: q.reply(str(q.key_expr), b"done"))
    h = client("hub", "host", creds=own)
    h.declare_subscriber(f"swarm/{RUN}/truth", lambda s: got["truth"].append(1))
    h.declare_subscriber(f"swarm/{RUN}/agent/4/ctl", lambda s: got["ctl"].append(1))
    time.sleep(0.5)
    h.put(f"swarm/{RUN}/agent/4/cmd", b"any agent's")
    h.put(f"swarm/{RUN}/world/control", b"forged notice")
    hub.put(f"swarm/{RUN}/truth", b"t")
    hub.put(f"swarm/{RUN}/agent/4/ctl", b"c")
    assert _wait(lambda: got["cmd"] and got["ctl"])
    assert [r for r in h.get(f"swarm/{RUN}/world/admin", timeout=1.0) if r.ok is not None] == []
    time.sleep(0.3)
    assert got["truth"] == [] and got["control"] == [] and got["cmd"] == [f"swarm/{RUN}/agent/4/cmd"]
