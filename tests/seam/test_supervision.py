"""Supervision without processes: what `swarm up` makes of an agent's exit, the
`agent_exit` admin request and the world's `crash` / `exit` events, non-finite law
outputs, the world riding out its own stall, the end of a deserted run, and the agent's
link to a world that stops answering (fake sessions, tests/support/fakes.py). The same with real
processes: tests/process/test_supervision_runtime.py.
"""

from __future__ import annotations

import math
import signal
import socket
import time

import pytest
import zenoh
from fakes import FakeQuery, FakeSession
from test_shells import RUN, join, open_world

from swarm.contracts import wire
from swarm.contracts.lifeline import endpoint_refuses, exit_status
from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import wait_until
from swarm.runtime.supervision import agent_exit, cause_of, is_crash, tail

# -- classifying an exit ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "code, crash",
    [
        (ExitCode.FAILED, True),
        (ExitCode.REFUSED, True),
        (ExitCode.USAGE, True),
        (-signal.SIGSEGV, True),
        (-signal.SIGABRT, True),
        (ExitCode.OK, False),
        (ExitCode.WORLD_GONE, False),
        (ExitCode.WORLD_SILENT, False),
        (-signal.SIGKILL, False),
        (-signal.SIGTERM, False),
        (ExitCode.TERMINATED, False),
        (ExitCode.INTERRUPTED, False),
    ],
)
def test_which_exits_are_crashes(code, crash):
    assert is_crash(code) is crash


def test_exit_status_in_words():
    assert exit_status(1) == "exit code 1" and exit_status(-signal.SIGSEGV) == "killed by SIGSEGV"
    assert exit_status(-99) == "killed by signal 99"


def test_report_takes_the_traceback_last_line_as_cause(tmp_path):
    log = tmp_path / "agent-2.log"
    log.write_text(
        "[agent 2] tick 1: out-neighbour 1 -> 3\nTraceback (most recent call last):\n"
        '  File "law.py", line 3, in law\nRuntimeError: the law gave up\n\n'
    )
    r = agent_exit(2, 123, 1, log, before_start=False)
    assert (r.crash, r.cause, r.log[-1]) == (True, "RuntimeError: the law gave up", "RuntimeError: the law gave up")
    assert r.line() == "agent 2 (pid 123) crashed (exit code 1): RuntimeError: the law gave up"
    quiet = agent_exit(3, 124, -signal.SIGKILL, tmp_path / "none.log", before_start=True)
    assert (quiet.crash, quiet.cause, quiet.log) == (False, "killed by SIGKILL", [])
    assert "could not start" in quiet.line()
    assert tail(tmp_path / "none.log") == []


def test_zenoh_source_locations_are_cut_from_the_cause():
    line = (
        "swarm world: cannot listen on tcp/127.0.0.1:99999: invalid port value at "
        "/root/.cargo/git/checkouts/zenoh/io/zenoh-link-commons/src/lib.rs:62."
    )
    assert cause_of([line], 2) == "swarm world: cannot listen on tcp/127.0.0.1:99999: invalid port value"


# -- the agent_exit request --------------------------------------------------------------------------


def test_agent_exit_round_trip_and_limits():
    buf = wire.encode_agent_exit(2, 77, 1, True, "RuntimeError: x" * 100, [f"line {i}" for i in range(50)])
    req = wire.decode_admin(buf)
    assert (req["cmd"], req["id"], req["pid"], req["code"], req["crash"]) == ("agent_exit", 2, 77, 1, True)
    assert len(req["cause"]) == wire.EXIT_LINE_CHARS and req["log"][-1] == "line 49"
    assert len(req["log"]) == wire.EXIT_LOG_LINES
    good = {"cmd": "agent_exit", "id": 2, "pid": 1, "code": 1, "crash": True, "cause": "c", "log": []}
    for bad in (
        {"crash": 1},
        {"code": 999},
        {"log": "x"},
        {"log": [1]},
        {"log": ["x" * 501]},
        {"id": -1},
        {"cause": None},
    ):
        with pytest.raises(wire.WireError):
            wire.decode_admin(wire.encode_json({**good, **bad}))
    del good["pid"]
    with pytest.raises(wire.WireError):
        wire.decode_admin(wire.encode_json(good))


def _admin(world, payload: bytes, on: str = "supervise") -> dict:
    q = FakeQuery(payload)
    (world.inbox.reports.on_supervise if on == "supervise" else world.inbox.on_admin)(q)
    return wire.decode_admin_reply(q.replies[0][1])


def _leave(world, aid: int) -> None:
    world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), zenoh.SampleKind.DELETE, None)


def test_world_records_crash_and_exit_events():
    world, _ = open_world()
    join(world, 1)
    join(world, 2)
    _leave(world, 2)
    rep = _admin(
        world, wire.encode_agent_exit(2, 102, 1, True, "RuntimeError: boom", ["Traceback", "RuntimeError: boom"])
    )
    assert rep["ok"]
    _admin(world, wire.encode_agent_exit(1, 101, -9, False, "", []))  # before its token went: kept
    assert [e["kind"] for e in world.engine.events if e["kind"] in ("crash", "exit")] == ["crash"]
    _leave(world, 1)
    world.inbox.drain(None, 0)
    crash, gone = [e for e in world.engine.events if e["kind"] in ("crash", "exit")]
    assert (crash["kind"], crash["agent"], crash["code"], crash["cause"]) == ("crash", 2, 1, "RuntimeError: boom")
    assert crash["reason"] == "process 102 ended (exit code 1): RuntimeError: boom"
    assert crash["log"] == ["Traceback", "RuntimeError: boom"]
    assert (gone["kind"], gone["reason"]) == ("exit", "process 101 ended (killed by SIGKILL)")
    stranger = _admin(world, wire.encode_agent_exit(9, 1, 1, True, "x", []))
    assert not stranger["ok"] and "not in the run" in stranger["error"] and world.state.over_limit["supervise"] == 1


def test_lockstep_holds_a_lost_token_unless_the_launcher_reported_the_exit():
    """A started lockstep run holds a token lost other than by a scripted fault (LINK_GRACE):
    the agent stays in, and its token coming back changes nothing. A token lost after the
    launcher's exit report (the report came first) drops the agent at once."""
    world, _ = open_world()
    join(world, 1)
    join(world, 2)
    world.state.started = True
    _leave(world, 1)
    assert 1 in world.core.active_ids() and 1 in world.inbox.lost_after_stall
    world.inbox.on_alive(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.PUT, None)
    assert 1 in world.core.active_ids() and not world.inbox.lost_after_stall and world.inbox.disturbed == 1
    assert _admin(world, wire.encode_agent_exit(2, 102, -9, False, "", []))["ok"]
    _leave(world, 2)
    world.inbox.drain(None, 0)
    assert world.core.active_ids() == [1]
    assert [e["kind"] for e in world.engine.events if e["agent"] == 2][-2:] == ["drop", "exit"]
    assert world.state.irreproducible == [f"agent 2 dropped at tick {world.core.tick}, not by a scripted fault"]


def test_a_report_on_a_live_agent_never_reaches_the_record(monkeypatch):
    """A crash reported for an agent that stays in the world is refused once the wait is
    over; a fault_done for a fault the clock is not waiting for is refused; neither report
    is accepted on the operator's admin key at all."""
    import swarm.world.reports as inbox_mod

    monkeypatch.setattr(inbox_mod, "EXIT_REPORT_WAIT", 0.0)
    world, _ = open_world()
    join(world, 1)
    join(world, 2)
    assert _admin(world, wire.encode_agent_exit(2, 1, 1, True, "forged", []))["ok"]
    world.inbox.drain(None, 0)
    assert not [e for e in world.engine.events if e["kind"] in ("crash", "exit")]
    assert world.state.over_limit["supervise"] == 1 and not world.inbox.reports.exit_reports
    rep = _admin(world, wire.encode_admin("fault_done", index=0))
    assert not rep["ok"] and "not being carried out" in rep["error"] and not world.state.faults_done
    world.state.fault_awaited = 0
    assert _admin(world, wire.encode_admin("fault_done", index=0))["ok"] and world.state.faults_done == {0}
    for forged in (wire.encode_agent_exit(2, 1, 1, True, "forged", []), wire.encode_admin("fault_done", index=0)):
        rep = _admin(world, forged, on="admin")
        assert not rep["ok"] and "unknown cmd" in rep["error"]
    assert 2 in world.core.active_ids()


# -- non-finite law outputs ------------------------------------------------------------------------


def test_non_finite_law_output_is_counted_and_held(tmp_path, monkeypatch):
    (tmp_path / "nanlaw_mod.py").write_text(
        "import math\ncalls = []\n"
        "def law(g_i, g_j, lam, c1, c2):\n"
        "    calls.append(1)\n"
        "    return math.nan if len(calls) % 2 == 0 else 0.25\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    from test_shells import SCENARIO

    from swarm.agents.brain import AgentBrain
    from swarm.contracts.brain_config import BrainConf
    from swarm.contracts.scenario import parse_scenario
    from swarm.world.engine import Engine

    sc = {
        **SCENARIO,
        "gains": {"c1": 1.0, "c2": 0.5, "law": "nanlaw_mod:law"},
        "agents": [SCENARIO["agents"][0], {**SCENARIO["agents"][1], "max_turn_rate": 0.1}],
    }
    s = parse_scenario(sc)
    c = BrainConf.from_scenario(s, 2)
    brain = AgentBrain(c)
    frame = Engine(s, 10).frames()[2]
    us = [brain.decide(frame._replace(tick=k)).u for k in range(4)]
    # 0.25 saturates to the limit 0.1; a NaN holds it (not the limit a NaN would saturate to).
    assert us == [0.1, 0.1, 0.1, 0.1] and brain.nonfinite == 2 and math.isnan(brain.last_nonfinite)


def test_agent_status_carries_the_non_finite_count():
    from test_shells import claim

    from swarm.agents.node import AgentNode

    world, _ = open_world()
    ses = FakeSession()
    node = AgentNode(ses, RUN, 2, claim(world, 2), wait_world=False)
    node.brain.nonfinite = 3
    node.open()
    node.maybe_publish_status(force=True)
    st = wire.decode_status(ses.on(wire.agent_key(RUN, 2, "status"))[-1])
    assert st["nonfinite"] == 3
    with pytest.raises(wire.WireError):
        wire.decode_status(wire.encode_status({**st, "nonfinite": -1}))


# -- the world's own stall, and a deserted run -------------------------------------------------------


def test_world_rides_out_its_own_stall():
    from swarm.world import inbox

    world, _ = open_world()
    join(world, 1)
    join(world, 2)
    alive = lambda aid, kind: world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), kind, None)  # noqa: E731
    world.inbox.stall_seen = time.monotonic()  # the world was just stopped
    alive(1, zenoh.SampleKind.DELETE)
    alive(2, zenoh.SampleKind.DELETE)
    alive(1, zenoh.SampleKind.PUT)  # agent 1's link came back: nothing happened to it
    assert sorted(world.core.active_ids()) == [1, 2]
    world.inbox.lost_after_stall[2] = time.monotonic() - 0.01  # agent 2's did not, in time
    world.inbox.drain(None, 0)
    kinds = [(e["kind"], e["agent"]) for e in world.engine.events if e["kind"] in ("drop", "rejoin")]
    assert kinds == [("drop", 2)] and world.book[2].drops == 1 and world.core.active_ids() == [1]
    world.inbox.stall_seen -= inbox.REJOIN_WAIT + 1  # long after a stall: a lost token is a drop at once
    alive(1, zenoh.SampleKind.DELETE)
    assert world.core.active_ids() == []


def test_deserted_run_ends_unless_a_restart_is_scripted(monkeypatch):
    from swarm.world import clock

    world, _ = open_world()
    join(world, 1)
    assert not world.clock.deserted()
    world.inbox.on_alive(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.DELETE, None)
    assert not world.clock.deserted() and world.clock.deserted_since is not None  # the grace starts
    world.clock.deserted_since -= clock.DESERTED_GRACE + 0.1
    assert world.clock.deserted()
    join(world, 1)
    assert not world.clock.deserted() and world.clock.deserted_since is None


# -- the agent's link to its world ------------------------------------------------------------------


def _link(tmp_path, endpoint, grace=0.2, wait_world=False):
    from swarm.agents.world_link import WorldLink

    link = WorldLink(FakeSession(), RUN, 2, endpoint, grace, wait_world)
    link.still_there = lambda timeout: False  # the fake hub never answers
    return link


def test_agent_exits_4_when_the_world_is_gone(tmp_path):
    from swarm.agents.joining import AgentExit

    link = _link(tmp_path, f"unixsock-stream/{tmp_path}/gone.sock")
    with pytest.raises(AgentExit) as e:
        link.on_delete(0.0)
    assert e.value.code == ExitCode.WORLD_GONE and "vanished" in e.value.message


def _exit_of(check):
    """The AgentExit `check()` raises, or None."""
    from swarm.agents.joining import AgentExit

    try:
        check()
    except AgentExit as e:
        return e
    return None


@pytest.mark.slow
def test_agent_waits_for_a_silent_world_then_exits_5(tmp_path):
    from swarm.agents.world_link import RESUMED, WAITING

    path = tmp_path / "w.sock"
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    srv.bind(str(path))
    srv.listen(8)  # a stopped world: the kernel still accepts
    try:
        link = _link(tmp_path, f"unixsock-stream/{path}")
        assert link.on_delete(0.0) == WAITING
        link.check()  # within the grace
        assert link.on_put() == RESUMED and link.lost_at is None
        assert link.on_delete(0.0) == WAITING
        e = wait_until(lambda: _exit_of(link.check), 10.0)  # once the grace (0.2 s) is over
        assert e and e.code == ExitCode.WORLD_SILENT and "has not answered for 0.2 s" in e.message
        waiting = _link(tmp_path, f"unixsock-stream/{path}", wait_world=True)
        waiting.on_delete(0.0)
        # --wait-world: no exit once the grace is over, the world counts as gone
        assert wait_until(lambda: _exit_of(waiting.check) is None and waiting.alive is False, 10.0)
    finally:
        srv.close()


def test_endpoint_refuses(tmp_path):
    assert endpoint_refuses(f"unixsock-stream/{tmp_path}/none.sock")
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    assert endpoint_refuses(f"tcp/127.0.0.1:{port}")  # bound, not listening
    assert endpoint_refuses(f"tls/127.0.0.1:{port}")  # TLS over the same TCP port
    s.listen(1)
    try:
        assert not endpoint_refuses(f"tcp/127.0.0.1:{port}")
        assert not endpoint_refuses(f"tls/127.0.0.1:{port}")
    finally:
        s.close()
    assert not endpoint_refuses("udp/127.0.0.1:1") and not endpoint_refuses("tcp/nonsense")
