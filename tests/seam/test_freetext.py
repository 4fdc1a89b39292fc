"""Free text from the bus and the taps that show it (issue 33, items 6-8), without processes:

- the sanitiser (swarm/contracts/freetext.py `printable`): control characters escaped, text
  bounded, ordinary text untouched; the token bucket (`Budget`);
- where the world accepts text (swarm/contracts/wire.py): who asked a pause or a stop, an
  agent's host, its status, the log lines of a crash report;
- the world's admin inbox against a fake session (tests/support/fakes.py): a flood of pauses and
  resumes is written within a budget, counted, and the record ends with the clock's state;
- the tap (swarm/live/tap.py): numbered streams' missing numbers counted, a backlog past its
  bound counted, a count left at the end given, the final truth (u NaN) decoded; which
  agent ids a run cannot have (`presence`).
"""

from __future__ import annotations

import json
import math
import queue

import pytest
from fakes import FakeQuery
from test_shells import open_world

from swarm.contracts import wire
from swarm.contracts.errors import LiveError
from swarm.contracts.freetext import BY_CHARS, HOST_CHARS, Budget, printable
from swarm.contracts.vocabulary import AgentState
from swarm.live.tap import Message, Tap, Topic, presence
from swarm.world.inbox import ADMIN_BURST

EVIL = "\x1b[2J\x1b[H\x1b]0;pwned\x07\nresults: /nonexistent\r\x9b31m\u202eevil\u2028\ud800"


def _raw_controls(s: str) -> list[str]:
    return [ch for ch in s if not ch.isprintable()]


# -- printable ---------------------------------------------------------------------------------------
def test_printable_escapes_every_control_character_repr_style():
    out = printable(EVIL)
    assert _raw_controls(out) == []
    for piece in ("\\x1b[2J", "\\x07", "\\n", "\\r", "\\x9b", "\\u202e", "\\u2028", "\\ud800"):
        assert piece in out, (piece, out)
    assert out.startswith("\\x1b[2J\\x1b[H\\x1b]0;pwned\\x07\\nresults: /nonexistent")
    out.encode("utf-8")  # a lone surrogate would make a terminal's write fail


@pytest.mark.parametrize("text", ["swarm stop (ana@vm, pid 10270)", "é 日本 🚀 ~!@#", "", "a\\x1b literal"])
def test_printable_leaves_ordinary_text_as_it_is(text):
    assert printable(text) == text


def test_printable_bounds_the_text_and_says_how_long_it_was():
    out = printable("x" * 60_000, BY_CHARS)
    assert out == "x" * BY_CHARS + "... (60000 characters)"
    escaped = printable("\x1b" * 60_000, BY_CHARS)
    assert len(escaped) <= BY_CHARS + 30 and _raw_controls(escaped) == [] and escaped.endswith("(60000 characters)")
    assert printable("y" * 10, 10) == "y" * 10 and printable("y" * 11, 10).startswith("y" * 10 + "...")
    assert printable("z" * 5000, None) == "z" * 5000


def test_printable_keeps_what_it_is_told_to_and_takes_any_object():
    assert printable("a\tb\x1b", keep="\t") == "a\tb\\x1b"
    assert printable("a\tb") == "a\\tb"
    assert printable(12) == "12" and printable({"k": "\x1b"}) == "{'k': '\\x1b'}"


def test_budget_gives_a_burst_then_refills_at_its_rate():
    b = Budget(2.0, 3)
    assert [b.take(0.0) for _ in range(5)] == [True, True, True, False, False]
    assert not b.ready(0.4) and b.take(0.5) and not b.take(0.5)  # 2 a second: one back after 0.5 s
    assert [b.take(100.0) for _ in range(4)] == [True, True, True, False]  # never more than the burst
    assert not b.take(99.0)  # a clock that goes back refills nothing
    with pytest.raises(ValueError):
        Budget(0, 1)


# -- where the world accepts text --------------------------------------------------------------------
def test_admin_by_is_bounded_and_escaped_where_the_world_decodes_it():
    req = wire.decode_admin(wire.encode_admin("stop", by=EVIL + "x" * 60_000), wire.ADMIN_CMDS)
    assert len(req["by"]) <= BY_CHARS + 30 and _raw_controls(req["by"]) == [] and "\\x1b[2J" in req["by"]
    assert wire.decode_admin(wire.encode_admin("pause"), wire.ADMIN_CMDS)["by"] == "a client"
    assert wire.decode_admin(wire.encode_admin("pause", by="me"), wire.ADMIN_CMDS)["by"] == "me"
    with pytest.raises(wire.WireError, match="by"):
        wire.decode_admin(wire.encode_admin("pause", by={"x": 1}), wire.ADMIN_CMDS)
    with pytest.raises(wire.WireError) as e:
        wire.decode_admin(wire.encode_json({"cmd": "\x1b[2J" * 100}), wire.ADMIN_CMDS)
    assert _raw_controls(str(e.value)) == [] and len(str(e.value)) < 200


def test_join_host_status_and_exit_report_text_escaped():
    req = wire.decode_join_request(wire.encode_join_request(3, 10, EVIL + "h" * 1000))
    assert _raw_controls(req["host"]) == [] and len(req["host"]) <= HOST_CHARS + 30
    st = wire.decode_status(
        wire.encode_status({"v": 1, "id": 3, "role": "follower\x1b[31m", "rooted": True, "phase": EVIL, "host": "vm"})
    )
    assert st["role"] == "follower\\x1b[31m" and _raw_controls(st["phase"]) == [] and st["host"] == "vm"
    ex = wire.decode_admin(wire.encode_agent_exit(3, 10, 1, True, "crash\x1b[2J", ["a\tb\x1b]0;t\x07"]))
    assert ex["cause"] == "crash\\x1b[2J" and ex["log"] == ["a\tb\\x1b]0;t\\x07"]


# -- the world's admin inbox: a budget for pauses and resumes ----------------------------------------------
def _admin(world, cmd: str, by: str) -> dict:
    q = FakeQuery(wire.encode_admin(cmd, by=by))
    world.inbox.on_admin(q)
    return wire.decode_admin_reply(q.replies[0][1])


def _pause_resume(world) -> list[dict]:
    return [e for e in world.engine.events if e["kind"] in ("pause", "resume")]


def test_a_flood_of_pauses_and_resumes_is_counted_not_written_one_by_one():
    world, _ = open_world()
    now = [100.0]
    world.inbox.admin_clock = lambda: now[0]
    for i in range(500):  # 1,000 requests at one instant
        assert _admin(world, "pause", f"flood {i} {EVIL}")["paused"] is True
        assert _admin(world, "resume", f"flood {i}")["paused"] is False
    events = _pause_resume(world)
    assert len(events) == ADMIN_BURST  # the burst, then nothing more at that instant
    assert all(_raw_controls(e["reason"]) == [] and len(e["reason"]) < BY_CHARS + 60 for e in events)
    assert world.state.over_limit["admin"] == 1000 - ADMIN_BURST
    limits = [e for e in world.engine.events if e["kind"] == "limit"]
    assert len(limits) == 1 and limits[0]["limit"] == "admin"
    # the last one written was a resume, and the clock is resumed: nothing more to say
    world.inbox.drain(None, 0)
    assert len(_pause_resume(world)) == ADMIN_BURST
    # a pause held back is written once the budget allows, with how many it stands for
    _admin(world, "pause", "late")
    assert world.state.paused and len(_pause_resume(world)) == ADMIN_BURST
    world.inbox.drain(None, 0)
    assert len(_pause_resume(world)) == ADMIN_BURST  # no token yet
    now[0] += 1.0
    world.inbox.drain(None, 0)
    last = _pause_resume(world)[-1]
    assert last["kind"] == "pause" and last["requests"] == 991  # 990 of the flood (not written), and this one
    assert last["reason"] == "asked by late (the last of 991 pause and resume requests since the previous such event)"
    # at the end, what is held is written at once: the record ends with the clock's state
    _admin(world, "resume", "r")  # the budget's last token
    _admin(world, "pause", "end")  # held back
    assert world.state.paused and _pause_resume(world)[-1]["reason"] == "asked by r"
    world.inbox.admin_due(now=True)
    assert _pause_resume(world)[-1]["kind"] == "pause" and _pause_resume(world)[-1]["reason"] == "asked by end"


def test_pauses_and_resumes_within_the_budget_are_each_written():
    world, _ = open_world()
    now = [0.0]
    world.inbox.admin_clock = lambda: now[0]
    for i in range(20):
        now[0] += 1.0
        _admin(world, "pause" if i % 2 == 0 else "resume", f"op {i}")
    assert [e["reason"] for e in _pause_resume(world)] == [f"asked by op {i}" for i in range(20)]
    assert "admin" not in world.state.over_limit


# -- the tap -------------------------------------------------------------------------------------------------
class _Ref:
    run = "r1"


class _Live:
    ref = _Ref()

    def gone(self) -> bool:
        return True


def _tap(leaf: str, max_backlog: int = 1 << 20) -> Tap:
    return Tap(_Live(), Topic(leaf, leaf, None), max_backlog)


def _truth(tick: int, seq: int, u: float = 0.5) -> bytes:
    return wire.encode_truth(
        tick, tick * 0.01, [1, 2], [0.0, 1.0], [0.0, 1.0], [0.0, 0.0], [u, u], [-1, 1], [AgentState.ACTIVE] * 2, seq
    )


def test_truth_numbers_and_the_final_state_decoded():
    buf = _truth(7, 65535)
    assert wire.truth_seq(buf) == 65535 and wire.decode_truth(buf)[0] == 7
    assert wire.next_seq(65535) == 1 and wire.next_seq(0) == 1 and wire.next_seq(41) == 42
    assert wire.truth_seq(_truth(7, 0)) == 0
    with pytest.raises(wire.WireError):
        _truth(7, 65536)
    final = _tap("truth").decode("swarm/r1/truth", _truth(100, 3, math.nan))
    assert final.error is None and [a["u"] for a in final.data["agents"]] == [None, None]
    assert "u=-" in final.line() and json.loads(final.json())["agents"][0]["u"] is None
    assert _tap("truth").decode("swarm/r1/truth", _truth(100, 3, math.inf)).error is not None


@pytest.mark.slow
def test_missing_numbers_of_truth_and_events_are_counted():
    tap = _tap("truth")
    for seq in (5, 6, 9, 9, 12, 65535, 2):  # 7-8 lost, a repeat, 10-11 lost, ..., 1 lost across the wrap
        tap.receive("swarm/r1/truth", _truth(seq, seq))
    got = list(tap.messages())
    assert [m.dropped for m in got] == [0, 0, 2, 0, 2, 65535 - 12 - 1, 1]
    assert tap.dropped == sum(m.dropped for m in got)
    assert json.loads(got[2].json())["dropped"] == 2 and "dropped" not in json.loads(got[1].json())
    tap = _tap("events")
    for seq in (1, 2, 4):
        tap.receive("swarm/r1/events", wire.encode_event({"kind": "join", "tick": seq, "agent": 1, "reason": "x"}, seq))
    tap.receive("swarm/r1/events", wire.encode_event({"kind": "join", "tick": 9, "agent": 1, "reason": "old"}))
    assert [m.dropped for m in tap.messages()] == [0, 0, 1, 0]  # unnumbered (an older world): nothing to count


@pytest.mark.slow
def test_a_backlog_past_its_bound_is_counted_and_said():
    size = len(_truth(1, 1))
    tap = _tap("truth", max_backlog=3 * size)
    for seq in range(1, 11):  # nobody reads: 3 held, 7 not
        tap.receive("swarm/r1/truth", _truth(seq, seq))
    assert tap.queue.qsize() == 3
    got = list(tap.messages(count=3))
    assert [m.dropped for m in got] == [0, 0, 0] and tap.lost == 7
    tap.receive("swarm/r1/truth", _truth(11, 11))  # the next one held says what was lost before it
    (m,) = list(tap.messages(count=1))
    assert m.dropped == 7 and m.data["tick"] == 11
    for seq in range(12, 20):
        tap.receive("swarm/r1/truth", _truth(seq, seq))
    got = list(tap.messages())  # to the end: the last message only counts those lost at the end
    assert [m.data["tick"] for m in got if m.is_data] == [12, 13, 14]
    assert not got[-1].is_data and got[-1].dropped == 5 and got[-1].line() == "dropped 5 messages"
    assert json.loads(got[-1].json()) == {"key": "swarm/r1/truth", "dropped": 5}
    assert tap.dropped == 12


def test_an_unnumbered_stream_counts_only_its_backlog():
    tap = Tap(_Live(), Topic("agent/3/cmd", "cmd", "3"), 10)
    buf = wire.encode_cmd(wire.Command(3, 1, 0.5, None, wire.PHASES[0], None, 1))
    tap.receive("swarm/r1/agent/3/cmd", buf)  # 38 bytes: past a 10-byte backlog
    assert tap.queue.empty() and tap.lost == 1
    with pytest.raises(queue.Empty):
        tap.queue.get_nowait()


def test_a_message_line_never_carries_a_control_character():
    ev = {"tick": 3, "time": 0.03, "agent": None, "kind": "stop", "reason": "asked by \x1b]0;t\x07\nresults: /x"}
    m = _tap("events").decode("swarm/r1/events", wire.encode_event(ev, 1))
    assert _raw_controls(m.line()) == [] and "\\x1b]0;t" in m.line()
    assert _raw_controls(m.json()) == []
    note = Message("k", "cmd", None, note="waiting\x1b[2J")
    assert note.line() == "waiting\\x1b[2J" and not note.is_data


# -- which agents a run can have ----------------------------------------------------------------------------
INFO = {"run": "r1", "agents": {"1": {}, "2": {}}, "added_ids": [7, 30], "max_added": 24, "added": 0}


@pytest.mark.parametrize("agent", [None, "*", "1", "2"])
def test_agents_of_the_run_and_every_agent_are_heard(agent):
    assert presence(INFO, Topic("x", "cmd", agent)) is None


def test_an_agent_the_run_may_still_add_is_waited_for():
    note = presence(INFO, Topic("agent/12/cmd", "cmd", "12"))
    assert note is not None and "agent 12 is not in run r1 yet" in note and "swarm spawn --id 12" in note


@pytest.mark.parametrize(
    "agent,info,words",
    [
        ("99", INFO, "agent 99 is not in run r1 (ids: 1, 2; agents added at run time: 7..30)"),
        ("3", INFO, "agent 3 is not in run r1 (ids: 1, 2; agents added at run time: 7..30)"),
        ("12", {**INFO, "added": 24}, "agent 12 is not in run r1 (ids: 1, 2) and cannot be: 24 of 24 agents added"),
        ("12", {"run": "r1", "agents": {"1": {}}}, "agent 12 is not in run r1 (ids: 1)"),
    ],
)
def test_an_agent_the_run_cannot_have_is_one_line(agent, info, words):
    with pytest.raises(LiveError) as e:
        presence(info, Topic(f"agent/{agent}/cmd", "cmd", agent))
    assert str(e.value) == words and LiveError.exit_code == 1
