"""swarm/contracts/wire.py in-process: every message's encode/decode pair round-trips, and
every decoder turns the malformed corpus (tests/support/malformed.py) into WireError, never into
another exception or a message. Milliseconds, no network."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest
from malformed import (
    ADMIN_BAD,
    BAD_JSON,
    CASE2_IDS,
    CONTROL_BAD,
    CTL_BAD,
    EVENTS_BAD,
    JOIN_BAD,
    _cmd_bad,
    _j,
    _oversized,
    _sense_bad,
    _truth_bad,
)

from swarm.contracts import wire
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.vocabulary import EventKind, FollowState, Phase
from swarm.world.sensing import build_frames, sensing_matrix

# -- round trips ---------------------------------------------------------------------------


def test_frame_and_command_round_trip():
    f = SensorFrame(7, 0.07, 3, 0.5, (Contact(1, 0.1, 0.2, 5.0, 0), Contact(6, -1.0, 2.0, 9.5, -1)), (1.0, -2.0))
    assert wire.decode_sense(wire.encode_sense(f)) == f
    c = wire.Command(3, 7, 0.25, 1, Phase.TRACK, 2, 2**64 - 1)
    assert wire.decode_cmd(wire.encode_cmd(c)) == c
    assert wire.decode_cmd(wire.encode_cmd(c)).follow == FollowState.NONE


@pytest.mark.parametrize("state", list(FollowState))
def test_a_command_carries_its_follow_state_in_the_byte_that_was_reserved(state):
    """Every follow state round-trips; its code is its index in FOLLOW_STATES, in byte 3 (the
    reserved byte, always 0 before: NONE is 0, so older senders' commands say none)."""
    c = wire.Command(3, 7, 0.25, 1, Phase.SHADOW, None, 99, state)
    buf = wire.encode_cmd(c)
    assert wire.decode_cmd(buf) == c
    assert buf[3] == wire.FOLLOW_STATES.index(state)
    assert buf[:3] + b"\0" + buf[4:] == wire.encode_cmd(c._replace(follow=FollowState.NONE))
    assert wire.encode_cmd_fields(3, 7, 0.25, 1, Phase.SHADOW, None, 99, state) == buf


def test_follow_states_on_the_wire_are_every_follow_state_with_none_first():
    assert wire.FOLLOW_STATES[0] == FollowState.NONE
    assert sorted(wire.FOLLOW_STATES) == sorted(FollowState)
    assert len(set(wire.FOLLOW_STATES)) == len(wire.FOLLOW_STATES) <= 127  # int8 codes in trajectory.npz


def test_a_command_with_an_unknown_follow_state_is_a_wire_error():
    good = wire.encode_cmd(wire.Command(3, 7, 0.25, 1, Phase.TRACK, 2, 5, FollowState.KEEP))
    for code in (len(wire.FOLLOW_STATES), 200, 255):
        with pytest.raises(wire.WireError, match="unknown follow state code"):
            wire.decode_cmd(good[:3] + bytes([code]) + good[4:])


def test_frames_encoded_all_at_once_are_the_frames_built_one_by_one():
    """The world's fast path (encode_sense_rows) sends the bytes of encode_sense for the
    frames world/sensing.py builds: leaders with the target, followers without, an agent
    that senses nobody, range-limited sensing."""

    rng = np.random.default_rng(5)
    n = 9
    ids = np.arange(10, 10 + n)
    x, y, g = rng.uniform(-20, 20, n), rng.uniform(-20, 20, n), rng.uniform(-3, 3, n)
    x[4], y[4] = 500.0, 500.0  # senses nobody
    lead = np.zeros(n, dtype=bool)
    lead[[0, 5]] = True
    hops = rng.integers(-1, 4, n)
    present = np.ones(n, dtype=bool)
    present[7] = False
    target = (1.5, -2.0)
    rows = [0, 1, 2, 3, 4, 5, 6, 8]
    s, bearing, rngm = sensing_matrix(x, y, g, present, 15.0, None)
    got = wire.encode_sense_rows(3, 0.03, rows, ids, g, target[0] - x, target[1] - y, lead, s, bearing, rngm, hops)
    want = build_frames(3, 0.03, ids, x, y, g, present, rows, lead, target, 15.0, None, hops)
    assert [wire.decode_sense(b) for b in got] == [want[int(ids[k])] for k in rows]
    assert got == [wire.encode_sense(want[int(ids[k])]) for k in rows]
    assert wire.decode_sense(got[4]).contacts == ()


def test_join_round_trip():
    req = wire.decode_join_request(wire.encode_join_request(4, 123, "host", {"role": "follower"}))
    assert (req["id"], req["pid"], req["host"], req["spec"]) == (4, 123, "host", {"role": "follower"})
    rep = wire.decode_join_reply(wire.encode_join_reply(True, run="r", agent=4, key=99, brain={"dt": 0.01}))
    assert rep["ok"] and rep["key"] == 99 and rep["brain"] == {"dt": 0.01}
    no = wire.decode_join_reply(wire.encode_join_reply(False, error="agent 4 is already live"))
    assert no == {"v": 1, "ok": False, "error": "agent 4 is already live"}


def test_a_join_reply_naming_laws_of_its_own_is_version_2():
    """An agent of a build that does not read the brain's "law" refuses such a reply (its
    strict version check) instead of flying the built-in laws in their place; this build
    reads both versions; every other message stays version 1."""

    plain = wire.encode_join_reply(True, run="r", agent=4, key=99, brain={"dt": 0.01})
    own = wire.encode_join_reply(True, run="r", agent=4, key=99, brain={"dt": 0.01}, own_laws=True)
    assert json.loads(plain)["v"] == 1 and json.loads(own)["v"] == wire.JOIN_REPLY_LAW_VERSION == 2
    assert wire.decode_join_reply(own)["key"] == 99
    with pytest.raises(wire.WireError, match="protocol version 2"):
        wire.decode_json(own, "join reply")  # what a version-1-only reader does
    with pytest.raises(wire.WireError, match="protocol version 2"):
        wire.decode_status(wire.encode_json({"id": 4}, 2))


def test_admin_ctl_control_event_round_trip():
    assert wire.decode_admin(wire.encode_admin("pause", by="me"))["by"] == "me"
    assert wire.decode_admin(wire.encode_admin("fault_done", index=3))["index"] == 3
    assert wire.decode_admin_reply(wire.encode_admin_reply(True, paused=True, tick=5))["tick"] == 5
    assert wire.decode_admin_reply(wire.encode_admin_reply(False, error="x"))["ok"] is False
    assert [wire.decode_ctl(wire.encode_ctl(s)) for s in wire.CTL_SIGNALS] == list(wire.CTL_SIGNALS)
    assert wire.decode_control(wire.encode_end(42)) == 42
    n = wire.decode_control(wire.encode_fault_notice(2, 3000, {"index": 2, "kind": "freeze", "agent": 5, "at": 30.0}))
    assert (n.index, n.tick, n.kind, n.agent, n.fault["at"]) == (2, 3000, "freeze", 5, 30.0)
    ev = {"tick": 1, "time": 0.01, "agent": 2, "kind": EventKind.SWITCH, "reason": "x", "from": None, "to": 4}
    assert wire.decode_event(wire.encode_event(ev)) == ev
    info = {"run": "r", "tick": 3, "agents": {"1": {"id": 1}}}
    assert wire.decode_info(wire.encode_info(info))["agents"] == info["agents"]
    st = {"id": 2, "role": "follower", "out": 4, "hops": 2, "rooted": True}
    assert wire.decode_status(wire.encode_status(st))["out"] == 4


# -- the malformed corpus ------------------------------------------------------------------

DECODERS = {
    "ctl": (wire.decode_ctl, CTL_BAD),
    "control": (wire.decode_control, CONTROL_BAD),
    "events": (wire.decode_event, EVENTS_BAD),
    "admin": (wire.decode_admin, ADMIN_BAD),
    "join": (wire.decode_join_request, JOIN_BAD),
    "status": (wire.decode_status, BAD_JSON),
    "info": (wire.decode_info, BAD_JSON),
    "admin reply": (wire.decode_admin_reply, BAD_JSON),
    "join reply": (
        wire.decode_join_reply,
        BAD_JSON
        + [
            _j({"v": 1, "ok": True}),
            _j({"v": 1, "ok": True, "key": -1, "brain": {}}),
            _j({"v": 1, "ok": True, "key": 2**64, "brain": {}}),
            _j({"v": 1, "ok": True, "key": 5, "brain": "x"}),
            _j({"v": 1, "ok": False}),
            _j({"v": 1, "ok": "yes"}),
        ],
    ),
}


def _join_is_only_semantically_bad(buf: bytes) -> bool:
    """Join requests that are well-formed messages and only wrong for the world (an id not
    in its scenario, a spec it refuses): it answers them with a refusal after decoding
    (tests/process/test_resilience.py)."""
    req = wire.decode_join_request(buf)
    return req["id"] not in CASE2_IDS and (req.get("spec") is not None or req["id"] == 42)


@pytest.mark.parametrize("kind", sorted(DECODERS))
def test_every_malformed_payload_is_a_wire_error(kind):
    decode, corpus = DECODERS[kind]
    rng = random.Random(kind)
    corpus = list(corpus) + [_oversized(rng), _oversized(rng, b'{"v": 1, "kind": "end"}')]
    accepted = []
    for buf in corpus:
        try:
            decode(buf)
        except wire.WireError:
            continue
        accepted.append(buf)
    if kind == "join":  # an unknown id or a bad spec is the world's to judge, not the decoder's
        accepted = [b for b in accepted if not _join_is_only_semantically_bad(b)]
    assert not accepted, f"{kind}: decoded without error: {[b[:80] for b in accepted]}"


@pytest.mark.parametrize("kind", ["cmd", "sense", "truth"])
def test_broken_binary_messages_are_wire_errors(kind):
    rng = random.Random(kind)
    make = {
        "cmd": lambda: _cmd_bad(rng, rng.choice(CASE2_IDS)),
        "sense": lambda: _sense_bad(rng, rng.choice(CASE2_IDS)),
        "truth": lambda: _truth_bad(rng),
    }[kind]
    decode = {"cmd": wire.decode_cmd, "sense": wire.decode_sense, "truth": wire.decode_truth}[kind]
    errors = other = 0
    for _ in range(2000):
        buf = make()
        try:
            decode(buf)
        except wire.WireError:
            errors += 1
        except Exception as e:  # noqa: BLE001 - the point of the test
            other += 1
            pytest.fail(f"{kind}: {type(e).__name__} instead of WireError on {buf[:40]!r}")
    # Some broken messages decode fine and are refused by the receiver instead (a command for
    # another agent, an out-neighbour the world does not know, unknown agents in truth).
    assert errors > 1000 and other == 0
