"""Tapping a live run's streams (`swarm echo KEY`): subscribe to one key of the run as its
operator, decode each message with the wire's own decoder (swarm/contracts/wire.py) and
render it as one line of text or one JSON object. No printing here: `Tap.messages()` yields
`Message`s, and the command (swarm/cli/tools.py) or the Python API prints or keeps them.

KEY is a key of the run without its `swarm/<run>/` prefix, as docs/reference/protocol.md
names them: `truth`, `events`, `world/control`, `agent/<id>/sense` (an agent's sensor
frames), `agent/<id>/cmd` (its commands), `agent/<id>/status`, `agent/<id>/ctl`; `<id>` may
be `*` for every agent. A name that is none of these is a `UsageError` naming it (exit 2).
A command's claim key is never shown: it proves who sends, and is nobody's business.

An agent key names an agent of the run: one that the run does not have is a `LiveError`
(exit 1, as `swarm logs 9` says it), unless the run may still add it (`swarm spawn --id N`:
an id in the world's `added_ids` range while fewer than `max_added` were added); then the
tap says once that it waits for that agent (a `Message` with a `note`).

Every message of the stream that reaches this process is given, or counted: the tap holds
at most MAX_BACKLOG_BYTES of messages not yet taken (a slow reader, a terminal that cannot
keep up), and counts those it could not hold; the world numbers its `truth` and `events`
messages (swarm/contracts/wire.py `next_seq`), and the tap counts the numbers missing
(messages lost on the way, e.g. dropped by zenoh's congestion control). A message says how
many were lost just before it (`dropped`); a count left at the end comes as a message of its
own (no data, `dropped` > 0). The other streams are not numbered: what zenoh drops on the
way there cannot be counted. `truth` is a sample by design: the world publishes it at most
every 20 ms of wall time (docs/reference/protocol.md#truth-record), so its ticks have gaps
that are no loss.
"""

from __future__ import annotations

import json
import math
import queue
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from swarm.contracts import wire
from swarm.contracts.errors import LiveError, UsageError
from swarm.contracts.freetext import printable

TOPICS = ("truth", "events", "world/control", "agent/ID/sense", "agent/ID/cmd", "agent/ID/status", "agent/ID/ctl")
AGENT_LEAVES = ("sense", "cmd", "status", "ctl")
ALIASES = {"control": "world/control", "event": "events"}
POLL_S = 0.25  # s between looks at whether the run has ended, while no message comes
MAX_BACKLOG_BYTES = 64 << 20  # messages received but not yet taken, at most (beyond: counted as dropped)
NUMBERED = ("truth", "events")  # the streams whose messages the world numbers (wire.next_seq)


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
        if not all(math.isfinite(v) for v in (x, y, heading)) or math.isinf(u):
            raise wire.WireError(f"truth: non-finite number for agent {aid}")
        # u is NaN for an agent that is gone, and for every agent in the final state (protocol 4.5)
        u_ = None if math.isnan(u) else u
        agents.append(
            {"id": aid, "x": x, "y": y, "heading": heading, "u": u_, "out": _opt(out), "state": str(wire.STATES[state])}
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
    be decoded (`error`, a WireError's line; `data` None). `dropped`: messages of the stream
    lost just before this one (module docstring); a message with neither data nor error
    only says that (`dropped` > 0, at the end) or says a `note` (the tap waits for an agent
    the run may still add)."""

    key: str
    leaf: str
    data: dict[str, Any] | None
    error: str | None = None
    dropped: int = 0
    note: str | None = None

    @property
    def is_data(self) -> bool:
        """A message of the stream (decoded or malformed), not a count or a note of the tap's."""
        return self.data is not None or self.error is not None

    def line(self) -> str:
        """One line of text (an agent key's messages carry the agent's id already), control
        characters escaped (swarm/contracts/freetext.py)."""
        if self.note is not None:
            return printable(self.note, None)
        if self.data is None and self.error is None:
            return dropped_line(self.dropped)
        if self.data is None:
            return printable(f"malformed message on {self.key}: {self.error}", None)
        return printable(LINES[self.leaf](self.data), None)

    def json(self) -> str:
        """One JSON object: {"key": ..., **data} (or "error"), with "dropped": N when N > 0
        messages were lost just before it ({"key", "dropped"} alone for a count at the end)."""
        body: dict[str, Any] = {"note": self.note} if self.note is not None else {}
        if self.data is not None:
            body = self.data
        elif self.error is not None:
            body = {"error": self.error}
        if self.dropped:
            body = {**body, "dropped": self.dropped}
        return json.dumps({"key": self.key, **body}, separators=(",", ":"), allow_nan=False)


def dropped_line(n: int) -> str:
    return f"dropped {n} message{'' if n == 1 else 's'}"


def presence(info: dict, topic: Topic) -> str | None:
    """Whether agent `topic.agent` can be heard in the run whose world info is `info`: None
    (it is in the run, or the key is not one agent's), a note (not in the run, but the run
    may still add it: the tap waits), or LiveError (it is not in the run and cannot be)."""
    if topic.agent is None or topic.agent == "*":
        return None
    aid, run, agents = int(topic.agent), info.get("run"), info.get("agents") or {}
    if str(aid) in agents:
        return None
    ids = ", ".join(sorted(agents, key=int)) or "none"
    span, cap, added = info.get("added_ids"), info.get("max_added"), info.get("added")
    if isinstance(span, list) and len(span) == 2 and all(type(v) is int for v in span):
        lo, hi = span
        if lo <= aid <= hi and type(cap) is int and type(added) is int:
            if added < cap:
                return f"agent {aid} is not in run {run} yet: waiting for it (swarm spawn --id {aid} adds it)"
            raise LiveError(
                f"agent {aid} is not in run {run} (ids: {ids}) and cannot be: {added} of {cap} agents added"
            )
        if lo <= hi:
            raise LiveError(f"agent {aid} is not in run {run} (ids: {ids}; agents added at run time: {lo}..{hi})")
    raise LiveError(f"agent {aid} is not in run {run} (ids: {ids})")


class Tap:
    """A subscription to `topic` on an open LiveRun (`with Tap(live, topic) as tap:`); its
    messages as they come (`messages`), until the run ends."""

    def __init__(self, live, topic: Topic, max_backlog: int = MAX_BACKLOG_BYTES):
        self.live = live
        self.topic = topic
        self.key = topic.key(live.ref.run)
        self.queue: queue.SimpleQueue[tuple[str, bytes, int]] = queue.SimpleQueue()
        self.sub = None
        self.note: str | None = None  # said first (`presence`)
        self.max_backlog = max_backlog
        self.lock = threading.Lock()
        self.backlog = 0  # bytes received and not yet taken
        self.lost = 0  # messages lost since the last one queued (not held, or numbers missing)
        self.dropped = 0  # messages lost in all (those given with a message, or at the end)
        self.last_seq: dict[str, int] = {}  # key -> the last sequence number received on it

    def __enter__(self) -> Tap:
        self.live.watch_end()  # the end notice: the tap ends with the run
        if self.topic.agent not in (None, "*"):
            self.note = presence(self.live.info(), self.topic)  # LiveError: an agent the run cannot have
        self.sub = self.live.session.declare_subscriber(
            self.key, lambda s: self.receive(str(s.key_expr), s.payload.to_bytes())
        )
        return self

    def receive(self, key: str, payload: bytes) -> None:
        """A message as it comes (on zenoh's callback thread): queued, with how many were lost
        just before it; or, past the backlog, counted as lost."""
        with self.lock:
            self.lost += self._missing(key, payload)
            if self.backlog + len(payload) > self.max_backlog:
                self.lost += 1
                return
            self.backlog += len(payload)
            lost, self.lost = self.lost, 0
        self.queue.put((key, payload, lost))

    def _missing(self, key: str, payload: bytes) -> int:
        """Numbers missing before this message's on its key (numbered streams; 0 when either
        number is unknown, or for a repeat)."""
        if self.topic.leaf not in NUMBERED:
            return 0
        seq = 0
        try:
            seq = wire.truth_seq(payload) if self.topic.leaf == "truth" else wire.decode_event_numbered(payload)[1]
        except wire.WireError:
            pass  # a malformed one: said when it is decoded
        if not seq:
            return 0
        last = self.last_seq.get(key, 0)
        self.last_seq[key] = seq
        return 0 if not last else max((seq - last) % (wire.SEQ_MOD - 1) - 1, 0)

    def __exit__(self, *exc) -> None:
        sub, self.sub = self.sub, None
        if sub is not None:
            try:
                sub.undeclare()
            except Exception:  # the session went with the run
                pass

    def decode(self, key: str, payload: bytes, dropped: int = 0) -> Message:
        try:
            return Message(key, self.topic.leaf, DECODERS[self.topic.leaf](payload), dropped=dropped)
        except wire.WireError as e:
            return Message(key, self.topic.leaf, None, str(e), dropped=dropped)

    def messages(self, count: int | None = None) -> Iterator[Message]:
        """Each message, decoded, until `count` of them (None: no limit) or the run's end
        (its end notice, or its endpoint refusing connections); the messages that came
        before the end are all given first, then, if some were lost after the last one, a
        message that only counts them. First, the tap's `note`, if it has one."""
        if self.note is not None:
            yield Message(self.key, self.topic.leaf, None, note=self.note)
        given = 0
        ending = False
        while count is None or given < count:
            try:
                key, payload, lost = self.queue.get(timeout=POLL_S)
            except queue.Empty:
                if ending:
                    break
                ending = self.live.gone()  # one more round for what is still on its way
                continue
            with self.lock:
                self.backlog -= len(payload)
            given += 1
            self.dropped += lost
            yield self.decode(key, payload, lost)
        else:
            return  # --count reached: what comes after is not this tap's business
        with self.lock:
            lost, self.lost = self.lost, 0
        if lost:
            self.dropped += lost
            yield Message(self.key, self.topic.leaf, None, dropped=lost)
