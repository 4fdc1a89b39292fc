"""Tapping a live run's streams (`swarm echo KEY`): subscribe to one key of the run as its
operator, decode each message with the wire's own decoder (swarm/contracts/wire.py) and
render it as one line of text or one JSON object. No printing here: `Tap.messages()` yields
`Message`s, and the command (swarm/cli/tools.py) or the Python API prints or keeps them.

KEY is a key of the run without its `swarm/<run>/` prefix, as docs/reference/protocol.md
names them: `truth`, `events`, `world/control`, `agent/<id>/sense` (an agent's sensor
frames), `agent/<id>/cmd` (its commands), `agent/<id>/status`, `agent/<id>/ctl`; `<id>` may
be `*` for every agent. A name that is none of these is a `UsageError` naming it (exit 2).
A command's claim key is never shown: it proves who sends, and is nobody's business.
"""

from __future__ import annotations

import json
import math
import queue
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from swarm.contracts import wire
from swarm.contracts.errors import UsageError

TOPICS = ("truth", "events", "world/control", "agent/ID/sense", "agent/ID/cmd", "agent/ID/status", "agent/ID/ctl")
AGENT_LEAVES = ("sense", "cmd", "status", "ctl")
ALIASES = {"control": "world/control", "event": "events"}
POLL_S = 0.25  # s between looks at whether the run has ended, while no message comes


@dataclass(frozen=True)
class Topic:
    """A parsed KEY: `leaf` is truth, events, control, or an agent leaf; `agent` an id or "*"."""

    name: str  # as the user gave it (aliases resolved)
    leaf: str
    agent: str | None = None

    def key(self, run: str) -> str:
        if self.agent is not None:
            return wire.agent_key(run, self.agent, self.leaf)
        return {"truth": wire.truth_key, "events": wire.events_key, "control": wire.world_control_key}[self.leaf](run)


def parse_topic(name: str) -> Topic:
    """The Topic of KEY `name`; UsageError (one line naming it) for anything else."""
    key = ALIASES.get(name.strip("/"), name.strip("/"))
    if key in ("truth", "events"):
        return Topic(key, key)
    if key == "world/control":
        return Topic(key, "control")
    parts = key.split("/")
    if len(parts) == 3 and parts[0] == "agent" and parts[2] in AGENT_LEAVES:
        aid = parts[1]
        if aid == "*" or (wire.AGENT_ID_RE.match(aid) and int(aid) <= wire.MAX_AGENT_ID):
            return Topic(key, parts[2], aid)
        raise UsageError(f"key {name!r}: {aid!r} is not an agent id (0..{wire.MAX_AGENT_ID}, or * for every agent)")
    raise UsageError(f"unknown key {name!r}: use one of {', '.join(TOPICS)} (ID: an agent id, or *)")


# -- decoding: one dict per message (JSON-ready: no NaN, no numpy) ------------------------------------------
def _opt(v: int) -> int | None:
    return None if v < 0 else v


def _truth(buf: bytes) -> dict[str, Any]:
    tick, time, recs = wire.decode_truth(buf)
    agents = []
    for r in recs.tolist():
        aid, x, y, heading, u, out, state = r
        if state >= len(wire.STATES):
            raise wire.WireError(f"truth: unknown state code {state} of agent {aid}")
        vals = (x, y, heading, u)
        if not all(math.isfinite(v) for v in vals):
            raise wire.WireError(f"truth: non-finite number for agent {aid}")
        agents.append(
            {"id": aid, "x": x, "y": y, "heading": heading, "u": u, "out": _opt(out), "state": str(wire.STATES[state])}
        )
    return {"tick": tick, "time": time, "agents": agents}


def _sense(buf: bytes) -> dict[str, Any]:
    f = wire.decode_sense(buf)
    return {
        "agent": f.agent,
        "tick": f.tick,
        "time": f.time,
        "heading": f.heading,
        "target": list(f.target) if f.target is not None else None,
        "contacts": [
            {"id": c[0], "bearing": c[1], "heading": c[2], "range": c[3], "hops": _opt(c[4])} for c in f.contacts
        ],
    }


def _cmd(buf: bytes) -> dict[str, Any]:
    c = wire.decode_cmd(buf)  # its claim key left out (see the module)
    return {"agent": c.agent, "tick": c.tick, "u": c.u, "out": c.out, "phase": str(c.phase), "hops": c.hops}


def _control(buf: bytes) -> dict[str, Any]:
    msg = wire.decode_control(buf)
    if isinstance(msg, int):
        return {"kind": "end", "tick": msg}
    return {"kind": "fault", "index": msg.index, "tick": msg.tick, "fault": msg.fault}


def _status(buf: bytes) -> dict[str, Any]:
    return {k: v for k, v in wire.decode_status(buf).items() if k != "v"}


DECODERS: dict[str, Callable[[bytes], dict[str, Any]]] = {
    "truth": _truth,
    "events": wire.decode_event,
    "control": _control,
    "sense": _sense,
    "cmd": _cmd,
    "status": _status,
    "ctl": lambda buf: {"signal": wire.decode_ctl(buf)},
}


# -- one line of text per message --------------------------------------------------------------------------
def _f(v: float | None, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _i(v: int | None) -> str:
    return "-" if v is None else str(v)


def _truth_line(d: dict) -> str:
    rows = [
        f"{a['id']} ({_f(a['x'], 2)}, {_f(a['y'], 2)}) h={_f(a['heading'])} u={_f(a['u'])} "
        f"out={_i(a['out'])} {a['state']}"
        for a in d["agents"]
    ]
    return f"tick {d['tick']} t={_f(d['time'])} | " + " | ".join(rows)


def _event_line(d: dict) -> str:
    head = f"tick {d.get('tick')} t={_f(d.get('time'))} {d['kind']}"
    if d.get("agent") is not None:
        head += f" agent {d['agent']}"
    more = {k: v for k, v in d.items() if k not in ("tick", "time", "wall_time", "agent", "kind", "reason")}
    tail = "".join(f" {k}={json.dumps(v, separators=(',', ':'))}" for k, v in more.items())
    return f"{head}: {d.get('reason', '')}{tail}"


def _sense_line(d: dict) -> str:
    target = "-" if d["target"] is None else f"({_f(d['target'][0], 2)}, {_f(d['target'][1], 2)})"
    contacts = "; ".join(
        f"{c['id']} b={_f(c['bearing'])} h={_f(c['heading'])} r={_f(c['range'], 2)} hops={_i(c['hops'])}"
        for c in d["contacts"]
    )
    return (
        f"agent {d['agent']} tick {d['tick']} t={_f(d['time'])} heading={_f(d['heading'])} target={target} "
        f"contacts {len(d['contacts'])}" + (f": {contacts}" if contacts else "")
    )


def _cmd_line(d: dict) -> str:
    return (
        f"agent {d['agent']} tick {d['tick']} u={_f(d['u'], 4)} out={_i(d['out'])} phase={d['phase']} "
        f"hops={_i(d['hops'])}"
    )


def _control_line(d: dict) -> str:
    if d["kind"] == "end":
        return f"end at tick {d['tick']}"
    f = d["fault"]
    return f"fault {d['index']} at tick {d['tick']}: {f.get('kind')} agent {f.get('agent')}"


LINES: dict[str, Callable[[dict], str]] = {
    "truth": _truth_line,
    "events": _event_line,
    "control": _control_line,
    "sense": _sense_line,
    "cmd": _cmd_line,
    "status": lambda d: json.dumps(d, separators=(",", ":"), allow_nan=False),
    "ctl": lambda d: f"signal {d['signal']}",
}


@dataclass(frozen=True)
class Message:
    """One message of the tap: its full key, and what it says (`data`), or why it could not
    be decoded (`error`, a WireError's line; `data` None)."""

    key: str
    leaf: str
    data: dict[str, Any] | None
    error: str | None = None

    def line(self) -> str:
        """One line of text (an agent key's messages carry the agent's id already)."""
        if self.data is None:
            return f"malformed message on {self.key}: {self.error}"
        return LINES[self.leaf](self.data)

    def json(self) -> str:
        """One JSON object: {"key": ..., **data} (or "error")."""
        body = {"error": self.error} if self.data is None else self.data
        return json.dumps({"key": self.key, **body}, separators=(",", ":"), allow_nan=False)


class Tap:
    """A subscription to `topic` on an open LiveRun (`with Tap(live, topic) as tap:`); its
    messages as they come (`messages`), until the run ends."""

    def __init__(self, live, topic: Topic):
        self.live = live
        self.topic = topic
        self.key = topic.key(live.ref.run)
        self.queue: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
        self.sub = None

    def __enter__(self) -> Tap:
        self.live.watch_end()  # the end notice: the tap ends with the run
        self.sub = self.live.session.declare_subscriber(
            self.key, lambda s: self.queue.put((str(s.key_expr), s.payload.to_bytes()))
        )
        return self

    def __exit__(self, *exc) -> None:
        sub, self.sub = self.sub, None
        if sub is not None:
            try:
                sub.undeclare()
            except Exception:  # the session went with the run
                pass

    def decode(self, key: str, payload: bytes) -> Message:
        try:
            return Message(key, self.topic.leaf, DECODERS[self.topic.leaf](payload))
        except wire.WireError as e:
            return Message(key, self.topic.leaf, None, str(e))

    def messages(self, count: int | None = None) -> Iterator[Message]:
        """Each message, decoded, until `count` of them (None: no limit) or the run's end
        (its end notice, or its endpoint refusing connections); the messages that came
        before the end are all given first."""
        given = 0
        ending = False
        while count is None or given < count:
            try:
                key, payload = self.queue.get(timeout=POLL_S)
            except queue.Empty:
                if ending:
                    return
                ending = self.live.gone()  # one more round for what is still on its way
                continue
            given += 1
            yield self.decode(key, payload)
