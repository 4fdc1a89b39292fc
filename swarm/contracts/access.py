"""What each identity may do on a run's hub: zenoh access-control rules, message-size
filters and the user dictionary, built from the run id and the ids its agents may take.

The hub (the world's router session) enforces all of this in zenoh itself: a message a
rule does not allow never reaches a subscriber or queryable, and a declaration it does
not allow (a subscriber, a queryable, a liveliness token) is never routed. Nothing
here runs per message in Python. Default: deny. Allowed, on the ingress of the hub
(what a client may send):

- `agent-<k>`: put its own `cmd` and `status`; subscribe to its own `sense` and `ctl`
  and to `world/control`; declare and answer its own `status` queryable; claim its id
  on its own `join` key; declare its own `alive` token; watch and query `world/alive`.
- `operator` (the CLI, and whoever holds the run's credentials): read everything of
  the run (subscribe, query, liveliness), query `world/info` and `world/admin` (pause,
  resume), put on any agent's `ctl`. It cannot put commands, frames, truth, events or
  control notices, declares no queryable or token, and cannot write the run's record.
- `supervisor` (the `swarm up` launcher alone): what the operator may do, and query
  `world/supervise` (an agent process exited, a scripted fault was carried out). Its
  password is not derived from the run's secret: the launcher makes it and gives it to
  its world only (`identities.ENV_SUPERVISOR`); no credentials file holds it, and a
  world started without it has no supervisor at all. The world also checks each report
  against what it knows (world/inbox.py).

- `host` (the router of an agent host, `swarm host`): what any agent of the run may do,
  the union of every `agent-<k>` rule. zenoh judges a message by the link it came in
  on, and the agents behind a host router all come in on that router's one link, so the
  hub cannot confine them one by one: their host router does (`host_router_access`,
  the same per-agent rules, checked on its own agents' links).

Everything the hub sends to a client (egress) is allowed: a client only receives what
its allowed declarations and queries asked for.

The rules must name every identity before the hub opens, so an agent added at run time
takes an id from the range the scenario reserves (`Scenario.added_id_range`), and the
`host` identity exists in every run, whether or not a host ever connects.
"""

from __future__ import annotations

from collections.abc import Iterable

from swarm.contracts import wire
from swarm.contracts.identities import HOST, OPERATOR, SUPERVISOR, agent_user, password_for

ALL_MESSAGES = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
]

# Largest payload the hub accepts from a client, per key (bytes). zenoh drops a bigger
# message at the hub before any Python code sees it.
CMD_LIMIT = 256  # a command is 38 bytes
SMALL_LIMIT = 64 << 10  # status, ctl, admin requests and replies
JOIN_LIMIT = wire.MAX_JSON_BYTES  # a join claim may bring a new agent's spec
MAX_MESSAGE = 2 * wire.MAX_JSON_BYTES  # the link closes on anything bigger (transport/link/rx)


def _rule(rid: str, messages: list[str], keys: list[str], flow: str = "ingress") -> dict:
    return {"id": rid, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": keys}


def agent_rules(run: str, aid: int) -> list[dict]:
    def k(leaf: str) -> str:
        return wire.agent_key(run, aid, leaf)

    p = f"a{aid}"
    return [
        _rule(f"{p}-put", ["put"], [k("cmd"), k("status")]),
        _rule(f"{p}-sub", ["declare_subscriber"], [k("sense"), k("ctl"), wire.world_control_key(run)]),
        _rule(f"{p}-status", ["declare_queryable", "reply"], [k("status")]),
        _rule(f"{p}-join", ["query"], [k("join")]),
        _rule(f"{p}-token", ["liveliness_token"], [k("alive")]),
        _rule(f"{p}-world", ["declare_liveliness_subscriber", "liveliness_query"], [wire.world_alive_key(run)]),
    ]


def operator_rules(run: str) -> list[dict]:
    everything = f"{wire.run_prefix(run)}/**"
    return [
        _rule("op-read", ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"], [everything]),
        _rule(
            "op-query",
            ["query"],
            [wire.world_info_key(run), wire.world_admin_key(run), wire.agent_key(run, "*", "status")],
        ),
        _rule("op-ctl", ["put"], [wire.agent_key(run, "*", "ctl")]),
    ]


def supervisor_rules(run: str) -> list[dict]:
    return [
        _rule(
            "sup-read",
            ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
            [f"{wire.run_prefix(run)}/**"],
        ),
        _rule(
            "sup-query",
            ["query"],
            [
                wire.world_info_key(run),
                wire.world_admin_key(run),
                wire.world_supervise_key(run),
                wire.agent_key(run, "*", "status"),
            ],
        ),
        _rule("sup-ctl", ["put"], [wire.agent_key(run, "*", "ctl")]),
    ]


def access_control(run: str, agent_ids: Iterable[int], host: bool = False, operator: bool = True) -> dict:
    """zenoh's `access_control` section for run `run` whose agents may take `agent_ids`; with
    `host`, a `host` identity allowed what any of those agents is (the hub of a run that
    may have agent hosts); without `operator`, no operator (a host router)."""
    rules, subjects, policies = [], [], []
    ids = list(agent_ids)
    for aid in ids:
        rs = agent_rules(run, aid)
        rules += rs
        subjects.append({"id": agent_user(aid), "usernames": [agent_user(aid)]})
        policies.append({"rules": [r["id"] for r in rs], "subjects": [agent_user(aid)]})
    users = [agent_user(a) for a in ids]
    if host:
        subjects.append({"id": HOST, "usernames": [HOST]})
        policies.append({"rules": [r["id"] for r in rules], "subjects": [HOST]})  # every agent's rules
        users.append(HOST)
    if operator:
        op = operator_rules(run)
        rules += op
        subjects.append({"id": OPERATOR, "usernames": [OPERATOR]})
        policies.append({"rules": [r["id"] for r in op], "subjects": [OPERATOR]})
        sup = supervisor_rules(run)
        rules += sup
        subjects.append({"id": SUPERVISOR, "usernames": [SUPERVISOR]})
        policies.append({"rules": [r["id"] for r in sup], "subjects": [SUPERVISOR]})
        users[:0] = [OPERATOR, SUPERVISOR]
    rules.append(_rule("egress", ALL_MESSAGES, [f"{wire.run_prefix(run)}/**"], flow="egress"))
    policies.append({"rules": ["egress"], "subjects": users})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def host_router_access(run: str, agent_ids: Iterable[int], hub_zid: str) -> dict:
    """zenoh's `access_control` section for the router of an agent host (`swarm host`): its
    own agents (`agent_ids`) confined by the same rules as at the hub, and its upstream link
    to the run's hub (known by its zenoh id: the hub does not authenticate to the host)
    let through both ways for anything of the run. Default deny: nothing else gets in."""
    acl = access_control(run, agent_ids, operator=False)
    acl["rules"].append(
        {
            "id": "upstream",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ALL_MESSAGES,
            "key_exprs": [f"{wire.run_prefix(run)}/**"],
        }
    )
    acl["subjects"].append({"id": "hub", "zids": [str(hub_zid)]})
    acl["policies"].append({"rules": ["upstream"], "subjects": ["hub"]})
    return acl


def size_filters(run: str) -> list[dict]:
    """zenoh's `low_pass_filter` section: the largest payload accepted on each key."""

    def f(fid: str, keys: list[str], limit: int) -> dict:
        return {
            "id": fid,
            "flows": ["ingress"],
            "messages": ["put", "query", "reply"],
            "key_exprs": keys,
            "size_limit": limit,
        }

    return [
        f("cmd", [wire.agent_key(run, "*", "cmd")], CMD_LIMIT),
        f(
            "small",
            [
                wire.agent_key(run, "*", "status"),
                wire.agent_key(run, "*", "ctl"),
                wire.world_admin_key(run),
                wire.world_supervise_key(run),
                wire.world_info_key(run),
            ],
            SMALL_LIMIT,
        ),
        f("join", [wire.agent_key(run, "*", "join")], JOIN_LIMIT),
    ]


def user_dictionary(
    secret: str, run: str, agent_ids: Iterable[int], host: bool = False, supervisor: str | None = None
) -> str:
    """The hub's `dictionary_file` content: one `user:password` line per identity; the
    `supervisor` line only with its password (the launcher's: see the module)."""
    users = [OPERATOR] + [agent_user(a) for a in agent_ids] + ([HOST] if host else [])
    sup = f"{SUPERVISOR}:{supervisor}\n" if supervisor else ""
    return sup + "".join(f"{u}:{password_for(secret, run, u)}\n" for u in users)


def host_dictionary(passwords: Iterable[tuple[str, str]]) -> str:
    """A host router's `dictionary_file` content: its own agents' `user:password` lines."""
    return "".join(f"{u}:{p}\n" for u, p in passwords)
