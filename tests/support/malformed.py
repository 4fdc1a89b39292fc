"""The malformed-message corpus: payloads that are not valid messages of this protocol,
per key kind, plus generators of broken binary frames, commands and truth. Fed to the
decoders one by one in tests/pure/test_wire.py and sent 10,000 at a time to a live run in
tests/process/test_resilience.py."""

from __future__ import annotations

import json
import math

import numpy as np

from swarm.contracts import wire

CASE2_IDS = [1, 2, 3, 4, 5, 6]
CASE2_LEADERS = [1, 6]
NON_IDS = ["abc", "007", "-1", "99", "3x", "0x3", "+3", "3.0", "99999999999", "4294967296"]
MIB = 1 << 20


def _j(obj) -> bytes:
    return json.dumps(obj).encode()


BAD_JSON = [
    b"",
    b"{",
    b"}",
    b"null",
    b"[]",
    b"[1, 2, 3]",
    b'"text"',
    b"42",
    b"true",
    b"{}",
    b"\xff\xfe\xfd",
    b'{"v": "1"}',
    b'{"v": 1.0}',
    b'{"v": true}',
    b'{"v": 2}',
    b'{"v": null}',
    b'{"v": -1}',
    b'{"v": 1, "x": NaN}',
    b'{"v": 1, "x": Infinity}',
    b'{"v": 1, "x": -1e999}',
    b'{"v": 1, "x": ' + b"9" * 5000 + b"}",
    b"[" * 100_000 + b"]" * 100_000,
    b'{"v": 1, "v": "1"}',
]
CTL_BAD = BAD_JSON + [
    _j({"v": 1, "kind": "signal", "signal": "HUP"}),
    _j({"v": 1, "kind": "signal", "signal": 9}),
    _j({"v": 1, "kind": "signal", "signal": ["KILL"]}),
    _j({"v": 1, "kind": "signal", "signal": None}),
    _j({"v": 1, "kind": "signal", "signal": {"KILL": 1}}),
    _j({"v": 1, "kind": "signal"}),
    _j({"v": 1, "kind": "signal", "signal": "kill"}),
    _j({"v": 1, "kind": "sig", "signal": "KILL"}),
    _j({"v": 1, "kind": ["signal"], "signal": "TERM"}),
    _j({"v": 1, "signal": "STOP"}),
    _j({"v": 2, "kind": "signal", "signal": "KILL"}),
    _j({"kind": "signal", "signal": "KILL"}),
    _j({"v": True, "kind": "signal", "signal": "KILL"}),
    _j({"v": "1", "kind": "signal", "signal": "TERM"}),
    b'{"v": 1.0, "kind": "signal", "signal": "KILL"}',
    b'{"v": 1, "kind": "signal", "signal": "KILL", "x": NaN}',
]
CONTROL_BAD = BAD_JSON + [
    _j({"kind": "end"}),
    _j({"v": 2, "kind": "end"}),
    _j({"v": "1", "kind": "end"}),
    _j({"v": True, "kind": "end"}),
    b'{"v": 1.0, "kind": "end"}',
    b'{"v": 1, "kind": "end", "x": NaN}',
    b'{"v": 1, "kind": "end", "x": 1e999}',
    _j({"v": 1, "kind": "End"}),
    _j({"v": 1, "kind": ["end"]}),
    _j({"v": 1, "kind": 5}),
    _j({"v": 1, "kind": None}),
    _j({"v": 1, "kind": "fault"}),
    _j({"v": 1, "kind": "fault", "fault": "kill"}),
    _j({"v": 1, "kind": "fault", "fault": [4, "kill"]}),
    _j({"v": 1, "kind": "fault", "fault": None}),
    _j({"v": 1, "kind": "fault", "index": "0", "fault": {"agent": "4", "kind": "kill"}}),
    _j({"v": 1, "kind": "fault", "index": None, "fault": {"agent": None, "kind": "freeze"}}),
    _j({"v": 1, "kind": "fault", "index": [], "fault": {"agent": 4, "kind": "KILL"}}),
    _j({"v": 1, "kind": "fault", "index": {}, "fault": {"agent": 4, "kind": ["kill"]}}),
    _j({"v": 1, "kind": "fault", "fault": {"agent": 4}}),
    _j({"v": 1, "kind": "fault", "fault": {"kind": "kill"}}),
    _j({"v": 2, "kind": "fault", "index": 0, "fault": {"agent": 4, "kind": "kill"}}),
]
EVENTS_BAD = BAD_JSON + [
    _j({"v": 1, "event": 5}),
    _j({"v": 1, "event": None}),
    _j({"v": 1}),
    _j({"v": 1, "event": {"kind": 7}}),
    _j({"v": 2, "event": {}}),
]
ADMIN_BAD = BAD_JSON + [
    _j({"v": 1, "cmd": "Pause"}),
    _j({"v": 1, "cmd": ["pause"]}),
    _j({"v": 1, "cmd": {"pause": True}}),
    _j({"v": 1, "cmd": None}),
    _j({"v": 1}),
    _j({"v": 2, "cmd": "pause"}),
    _j({"cmd": "pause"}),
    _j({"v": True, "cmd": "pause"}),
    b'{"v": 1.0, "cmd": "pause"}',
    b'{"v": 1, "cmd": "pause", "by": NaN}',
    b'{"v": 1, "cmd": "pause", "by": -Infinity}',
    _j({"v": 1, "cmd": "fault_done"}),
    _j({"v": 1, "cmd": "fault_done", "index": "0"}),
    _j({"v": 1, "cmd": "fault_done", "index": True}),
    b'{"v": 1, "cmd": "fault_done", "index": 0.0}',
    _j({"v": 1, "cmd": "fault_done", "index": [0]}),
    _j({"v": 1, "cmd": "fault_done", "index": None}),
]
_SPEC = {"role": "follower", "x": 0.0, "y": 0.0, "heading": 0.0, "speed": 1.0}
JOIN_BAD = BAD_JSON + [
    _j({"v": 1, "id": "3", "pid": 1, "host": "h"}),
    _j({"v": 1, "id": 3.5, "pid": 1, "host": "h"}),
    b'{"v": 1, "id": 3.0, "pid": 1, "host": "h"}',
    _j({"v": 1, "id": True, "pid": 1, "host": "h"}),
    _j({"v": 1, "id": None, "pid": 1, "host": "h"}),
    _j({"v": 1, "id": 3, "pid": "1", "host": "h"}),
    _j({"v": 1, "id": 3, "pid": 1, "host": 5}),
    _j({"v": 1, "id": 3, "pid": 1}),
    _j({"v": 1, "pid": 1, "host": "h"}),
    _j({"v": 2, "id": 3, "pid": 1, "host": "h"}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h"}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": "follower"}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": [1]}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {}}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {**_SPEC, "speed": -1.0}}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {**_SPEC, "follow": 999}}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {**_SPEC, "role": "leader"}}),
    _j({"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {**_SPEC, "colour": "red"}}),
    _j({"v": 1, "id": -5, "pid": 1, "host": "h", "spec": _SPEC}),
    _j({"v": 1, "id": 2**40, "pid": 1, "host": "h", "spec": _SPEC}),
    b'{"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {"role": "follower", "x": NaN, "y": 0, '
    b'"heading": 0, "speed": 1}}',
    b'{"v": 1, "id": 42, "pid": 1, "host": "h", "spec": {"role": "follower", "x": 1e999, "y": 0, '
    b'"heading": 0, "speed": 1}}',
]


def _cmd(agent, tick=0, u=0.1, out=-1, hops=-1, key=12345, phase=0, kind=wire.KIND_CMD, version=wire.VERSION, follow=0):
    return wire.CMD.pack(kind, version, phase, follow, agent, tick, u, out, hops, key)


def _sense(
    agent,
    tick=0,
    t=0.0,
    heading=0.1,
    target=(5.0, 5.0),
    contacts=((2, 0.1, 0.2, 5.0, 1),),
    n=None,
    kind=wire.KIND_SENSE,
    version=wire.VERSION,
):
    tx, ty = target if target is not None else (math.nan, math.nan)
    head = wire.SENSE_HEAD.pack(
        kind, version, int(target is not None), 0, agent, tick, t, heading, tx, ty, len(contacts) if n is None else n
    )
    return head + b"".join(wire.CONTACT.pack(*c) for c in contacts)


def _truth(ids=CASE2_IDS, x=None, kind=wire.KIND_TRUTH, version=wire.VERSION, n=None, state=0, out=None):
    k = len(ids)
    x = np.arange(k, dtype=float) if x is None else x
    buf = wire.encode_truth(
        7,
        0.07,
        np.array(ids),
        x,
        np.zeros(k),
        np.zeros(k),
        np.zeros(k),
        np.full(k, -1) if out is None else np.array(out),
        ["active"] * k,
    )
    head = wire.TRUTH_HEAD.pack(kind, version, 0, 0, k if n is None else n, 7, 0.07)
    recs = bytearray(buf[wire.TRUTH_HEAD.size :])
    if state:
        recs[-1] = state
    return head + bytes(recs)


def _trunc(rng, buf: bytes) -> bytes:
    return buf[: rng.randrange(len(buf))]


def _cmd_bad(rng, key_id) -> bytes:
    a = key_id if isinstance(key_id, int) else rng.choice(CASE2_IDS + [99])
    other = rng.choice([i for i in CASE2_IDS if i != a] or [1])
    return rng.choice(
        [
            lambda: rng.randbytes(rng.randint(0, 80)),
            lambda: _trunc(rng, _cmd(a)),
            lambda: _cmd(a) + b"\0" * rng.randint(1, 16),
            lambda: _cmd(a, kind=wire.KIND_SENSE),
            lambda: _cmd(a, kind=0),
            lambda: _cmd(a, kind=255),
            lambda: _cmd(a, version=2),
            lambda: _cmd(a, version=0),
            lambda: _cmd(a, u=math.nan),
            lambda: _cmd(a, u=math.inf),
            lambda: _cmd(a, u=-math.inf),
            lambda: _cmd(a, u=math.nan, out=other),
            lambda: _cmd(a, phase=rng.randint(5, 255)),
            lambda: _cmd(a, follow=rng.randint(len(wire.FOLLOW_STATES), 255)),  # an unknown follow state
            lambda: _cmd(a, tick=-rng.randint(1, 2**40)),
            lambda: _cmd(other),  # a command for another agent on this agent's key
            lambda: _cmd(a, out=a),
            lambda: _cmd(a, out=99),
            lambda: _cmd(a, out=2**31 - 1),
        ]
    )()


def _sense_bad(rng, aid) -> bytes:
    other = rng.choice([i for i in CASE2_IDS if i != aid] or [1])
    leader = aid in CASE2_LEADERS if isinstance(aid, int) else False
    a = aid if isinstance(aid, int) else 3
    choices = [
        lambda: rng.randbytes(rng.randint(0, 200)),
        lambda: _trunc(rng, _sense(a)),
        lambda: _sense(a) + b"\0" * rng.randint(1, 7),
        lambda: _sense(a, kind=wire.KIND_CMD),
        lambda: _sense(a, kind=9),
        lambda: _sense(a, version=2),
        lambda: _sense(a, version=0),
        lambda: _sense(a, contacts=((2, math.nan, 0.2, 5.0, 1),)),  # NaN bearing
        lambda: _sense(a, contacts=((2, 0.1, math.inf, 5.0, 1),)),
        lambda: _sense(a, contacts=((2, 0.1, 0.2, -math.inf, 1),)),
        lambda: _sense(a, heading=math.nan),
        lambda: _sense(a, t=math.inf),
        lambda: _sense(a, target=(math.nan, 0.0)),
        lambda: _sense(a, n=3),
        lambda: _sense(a, n=wire.MAX_AGENTS + 1),
        lambda: _sense(a, n=2**32 - 1),
        lambda: _sense(a, tick=-5),
        lambda: _sense(other),  # a frame for another agent
    ]
    if leader:
        choices.append(lambda: _sense(a, target=None))  # a leader frame without the target
    return rng.choice(choices)()


def _truth_bad(rng) -> bytes:
    return rng.choice(
        [
            lambda: rng.randbytes(rng.randint(0, 300)),
            lambda: _trunc(rng, _truth()),
            lambda: _truth(kind=wire.KIND_SENSE),
            lambda: _truth(version=7),
            lambda: _truth(n=10),
            lambda: _truth(n=wire.MAX_AGENTS + 1),
            lambda: _truth(x=np.full(6, math.nan)),
            lambda: _truth(x=np.full(6, math.inf)),
            lambda: _truth(state=9),
            lambda: _truth(ids=[1, 99, 2, 2**31 - 1], out=[-1, 1, 99, 2]),  # agents the scenario does not have
            lambda: _truth(out=[-1, 2, 2, 3, 4, 7]),  # a self-loop and an unknown out-neighbour
        ]
    )()


def _oversized(rng, json_like: bytes | None = None) -> bytes:
    """> 1 MiB: random bytes, or an otherwise well-formed JSON object padded past the limit."""
    if json_like is None:
        return rng.randbytes(MIB + rng.randint(1, 4096))
    obj = json.loads(json_like)
    obj["pad"] = "x" * (MIB + rng.randint(1, 4096))
    return _j(obj)
