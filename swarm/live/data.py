"""What the live commands show, as plain data: the world's info merged with the agents' own
statuses, and the communication graph of it. No printing, no typer; `live` is a
`swarm.live.client.LiveRun` (or anything with its `info()` and `statuses()`)."""

from __future__ import annotations

from swarm.contracts.graph import analyse

AGENT_FIELDS = (
    "id",
    "role",
    "state",
    "alive",
    "answered",
    "pid",
    "host",
    "out",
    "hops",
    "root",
    "phase",
    "follow",
    "fallback",
    "pinned",
    "x",
    "y",
    "heading",
    "speed",
    "u",
    "distance",
    "expected_radius",
    "radial_error",
    "relative_error",
    "orbit_radius",
    "last_command_age",
    "missed",
    "commands",
    "joins",
    "drops",
    "garbage",
    "rogue_commands",
)


def merge_agents(info: dict, statuses: dict[int, dict]) -> list[dict]:
    """One row per agent of the world's info, sorted by id (fields: AGENT_FIELDS).

    A live agent that answered its status query gives its own pid, host, out-neighbour,
    hops, phase and follow state; an agent that did not answer, or that the world has
    dropped, is described by the world's info alone (its `follow`: that of its last latched
    command; none when it is not active; absent from an older world's info: None).
    """
    rows = []
    for key in sorted(info.get("agents", {}), key=int):
        a = info["agents"][key]
        aid = int(a["id"])
        st = statuses.get(aid)
        own = st if (st is not None and a.get("alive")) else None
        row = {f: a.get(f) for f in AGENT_FIELDS}
        row.update(
            id=aid,
            answered=st is not None,
            phase=None,
            fallback=None,
            pinned=None,
            # bad messages: dropped by the world for this agent, plus those the agent dropped
            garbage=(a.get("garbage") or 0) + ((st or {}).get("garbage") or 0),
            rogue_commands=a.get("rogue_commands") or 0,
        )
        if own is not None:
            row.update(
                pid=own.get("pid", row["pid"]),
                host=own.get("host", row["host"]),
                out=own.get("out"),
                hops=own.get("hops"),
                phase=own.get("phase"),
                follow=own.get("follow", row["follow"]),  # an older agent's status has none: the world's
                fallback=own.get("fallback"),
                pinned=own.get("pinned"),
            )
        rows.append(row)
    return rows


def snapshot(live, sensing: bool = False) -> dict:
    """{"info": world info, "agents": merged rows} read now (statuses right after info, ending
    once every agent live in the info has answered)."""
    info = live.info(sensing=sensing)
    statuses = live.statuses(int(a["id"]) for a in info.get("agents", {}).values() if a.get("alive"))
    return {"info": info, "agents": merge_agents(info, statuses)}


def graph_of(snap: dict, sensing: bool = False) -> dict:
    """The communication graph (docs/reference/cli.md#graph, `swarm graph --json`)."""
    info, rows = snap["info"], snap["agents"]
    out = {r["id"]: r["out"] for r in rows}
    leaders = {r["id"] for r in rows if r["role"] == "leader"}
    alive = {r["id"] for r in rows if r["alive"]}
    g = analyse(out, leaders, alive)
    doc = {
        "run": info.get("run"),
        "tick": info.get("tick"),
        "time": info.get("time"),
        **g,
        "dead": sorted(set(out) - alive),
        "agents": [
            {
                "id": r["id"],
                "role": r["role"],
                "alive": r["alive"],
                "out": r["out"],
                "source": "agent" if (r["answered"] and r["alive"]) else "world",
            }
            for r in rows
        ],
    }
    if sensing:
        doc["sensing"] = [list(map(int, e)) for e in info.get("sensing", [])]
    return doc


def graph_key(g: dict) -> tuple:
    """What makes two graph_of() documents the same picture (tick and time aside)."""
    return (tuple(map(tuple, g["edges"])), tuple(g["nodes"]), tuple(g["dead"]), tuple(map(tuple, g.get("sensing", []))))
