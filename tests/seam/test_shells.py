"""The process shells' logic against a fake session (tests/support/fakes.py): the world's admission,
liveliness, commands, admin and frames; the agent's frames in and commands out. No
network, no processes: the middle tier between the pure tests and the multi-process ones.
"""

from __future__ import annotations

import pytest
import zenoh
from fakes import FakeQuery, FakeSession

from swarm.contracts import wire
from swarm.contracts.scenario import parse_scenario
from swarm.contracts.vocabulary import ExitCode, Phase, SwitchReason
from swarm.world.clock import Clock
from swarm.world.engine import Engine
from swarm.world.fairness import FairQueue
from swarm.world.inbox import Inbox
from swarm.world.inbox_messages import Join
from swarm.world.joins import Joins
from swarm.world.process import World, WorldConfig
from swarm.world.state import RunState

RUN = "shells"
SCENARIO = {
    "run": {"dt": 0.01, "duration": 1.0},
    "gains": {"c1": 1.0, "c2": 0.5},
    "agents": [
        {"id": 1, "role": "leader", "x": 10.0, "y": 0.0, "heading": 1.57, "speed": 1.0, "orbit_radius": 10.0},
        {"id": 2, "role": "follower", "x": 0.0, "y": -5.0, "heading": 0.0, "speed": 1.5},
    ],
}


def open_world(scenario: dict = SCENARIO):
    world = World(WorldConfig(parse_scenario(scenario), RUN, "unixsock-stream//nonexistent", None, progress=False))
    ses = FakeSession()
    world._open(ses)
    return world, ses


def test_the_join_reply_is_version_2_only_when_the_run_has_laws_of_its_own():
    """docs/reference/protocol.md#join-reply: an agent that cannot read "law" must refuse a run whose laws it would
    otherwise replace with the built-in ones."""
    world, _ = open_world()
    assert claim(world, 2)["v"] == 1
    own = {**SCENARIO, "law": {"leader": "helpers_law:orbit_rate_leader", "params": {"rate": 0.25}}}
    world, _ = open_world(own)
    assert claim(world, 2)["v"] == wire.JOIN_REPLY_LAW_VERSION  # its follower too: one run, one version


def claim(world, aid: int, on: int | None = None) -> dict:
    """Agent `aid` claims its id on agent `on`'s join key (default: its own)."""
    key = wire.agent_key(RUN, aid if on is None else on, "join")
    q = FakeQuery(wire.encode_join_request(aid, 100 + aid, "host"), key_expr=key)
    world.joins.on_join(q)
    ((reply_key, payload),) = q.replies
    assert reply_key == key
    assert q.dropped, "the join query was answered but not finished (its asker waits out its timeout)"
    return wire.decode_join_reply(payload)


def join(world, aid: int) -> int:
    rep = claim(world, aid)
    world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), zenoh.SampleKind.PUT, None)
    return rep["key"]


# -- the world -------------------------------------------------------------------------------


def test_world_admits_each_id_once_and_refuses_strangers():
    world, _ = open_world()
    rep = claim(world, 2)
    assert rep["ok"] and rep["brain"]["agent"]["id"] == 2 and rep["brain"]["sensing"]["selection"] == "sticky"
    again = claim(world, 2)  # the first claim is still waiting for its token
    assert not again["ok"] and "already live" in again["error"]
    stranger = claim(world, 9)
    assert not stranger["ok"] and "not in scenario" in stranger["error"]


def test_world_joins_on_the_token_and_drops_when_it_goes():
    world, _ = open_world()
    join(world, 1)
    assert [e["kind"] for e in world.engine.events] == ["join"]
    world.inbox.on_alive(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.DELETE, None)
    assert [e["kind"] for e in world.engine.events] == ["join", "drop"]
    assert world.book[1].drops == 1 and world.core.active_ids() == []


def test_world_latches_owned_commands_and_counts_the_rest():
    world, ses = open_world()
    key1, key2 = join(world, 1), join(world, 2)
    pending = {1, 2}
    world.publish_frames()
    frames = {wire.decode_sense(p).agent: wire.decode_sense(p) for k, p in ses.sent if k.endswith("/sense")}
    assert set(frames) == {1, 2} and frames[1].target is not None and frames[2].target is None
    cmd_key = wire.agent_key(RUN, 2, "cmd")
    world.inbox.on_cmd(cmd_key, wire.encode_cmd(wire.Command(2, 0, 0.3, 1, Phase.TRACK, 1, key2 ^ 1)), pending)
    assert world.book[2].rogue == 1 and pending == {1, 2}  # not the owner's key: ignored
    world.inbox.on_cmd(cmd_key, b"garbage", pending)
    follows_itself = wire.encode_cmd(wire.Command(2, 0, 0.3, 2, Phase.TRACK, 1, key2))
    world.inbox.on_cmd(cmd_key, follows_itself, pending)
    # the world's count, and agent 2's: what the world dropped on that agent's keys
    # (docs/guides/faults.md#hostile-input)
    assert world.state.garbage == 2 and world.book[2].garbage == 2 and world.book[1].garbage == 0
    world.inbox.on_cmd(cmd_key, wire.encode_cmd(wire.Command(2, 0, 0.3, 1, Phase.TRACK, 1, key2)), pending)
    assert pending == {1} and world.core.u[1] == 0.3 and world.engine.out[1] == 1
    (switch,) = [e for e in world.engine.events if e["kind"] == "switch"]
    assert (switch["agent"], switch["from"], switch["to"], switch["reason"]) == (2, None, 1, SwitchReason.CHOSEN)
    world.inbox.on_cmd(
        wire.agent_key(RUN, 1, "cmd"), wire.encode_cmd(wire.Command(1, 0, 0.1, None, Phase.ORBIT, 0, key1)), pending
    )
    assert pending == set()
    world.record_and_step()
    assert world.core.tick == 1 and world.engine.rec.rows == 1


def test_world_admin_pauses_and_refuses_unknown_commands():
    world, _ = open_world()
    q = FakeQuery(wire.encode_admin("pause", by="test"))
    world.inbox.on_admin(q)
    assert world.state.paused and wire.decode_admin_reply(q.replies[0][1])["paused"] is True
    q = FakeQuery(wire.encode_json({"cmd": "explode"}))
    world.inbox.on_admin(q)
    rep = wire.decode_admin_reply(q.replies[0][1])
    assert rep["ok"] is False and "unknown cmd" in rep["error"] and world.state.garbage == 1


def test_world_info_reports_expected_radius_through_the_chosen_graph():
    world, _ = open_world()
    key2 = join(world, 2)
    join(world, 1)
    world.inbox.on_cmd(
        wire.agent_key(RUN, 2, "cmd"), wire.encode_cmd(wire.Command(2, 0, 0.0, 1, Phase.TRACK, 1, key2)), None
    )
    info = wire.decode_info(wire.encode_info(world.info()))
    a2 = info["agents"]["2"]
    assert (a2["root"], a2["hops"], a2["expected_radius"]) == (1, 1, 15.0)  # 1.5 m/s at omega 0.1


# -- the world's parts, each without the others' zenoh shell --------------------------------------


def parts(scenario: dict = SCENARIO):
    """The run's state, the queue, the joins and the inbox of a world, made by hand: no
    World, no session (an added agent's publisher is only noted)."""
    s = parse_scenario(scenario)
    state = RunState(
        WorldConfig(s, RUN, "unixsock-stream//nonexistent", None, progress=False), Engine(s, 100, joined=False), 100
    )
    queue = FairQueue(state)
    added: list[int] = []
    inbox = Inbox(state, queue, Joins(state, added.append))
    return state, queue, inbox, added


def test_the_inbox_alone_admits_joins_and_latches_commands():
    state, queue, inbox, _ = parts()
    q = FakeQuery(wire.encode_join_request(2, 102, "host"), key_expr=wire.agent_key(RUN, 2, "join"))
    queue.enqueue(Join(q))
    queue.token(wire.agent_key(RUN, 2, "alive"), zenoh.SampleKind.PUT)
    while inbox.drain(None, 0):
        pass
    key = wire.decode_join_reply(q.replies[0][1])["key"]
    assert state.core.active_ids() == [2] and [e["kind"] for e in state.engine.events] == ["join"]
    queue.command(wire.agent_key(RUN, 2, "cmd"), wire.encode_cmd_fields(2, 0, 0.2, None, Phase.LOST, None, key))
    pending = {2}
    assert inbox.drain(pending, 0) and not pending and state.core.u[1] == 0.2 and state.book[2].commands == 1


def test_the_joins_alone_add_an_agent_through_the_shells_callback():
    state, _, inbox, added = parts()
    q = FakeQuery(wire.encode_join_request(5, 105, "host", NEW), key_expr=wire.agent_key(RUN, 5, "join"))
    inbox.joins.on_join(q)
    assert wire.decode_join_reply(q.replies[0][1])["ok"] and added == [5] and 5 in state.book
    assert [e["kind"] for e in state.engine.events] == ["add"]


class _Shell:
    """The clock's view of a world process: frames to nobody, a step of the engine."""

    def __init__(self, state: RunState):
        self.state, self.stepped = state, 0

    def publish_frames(self) -> set[int]:
        self.state.engine.mark_frames()
        return set(self.state.core.active_ids())

    def resend_frames(self, aids) -> None:
        pass

    def record_and_step(self) -> None:
        self.state.engine.end_tick()
        self.stepped += 1

    def send_control(self, payload: bytes) -> None:
        pass


class _Parts:
    """What `claim` and `join` above use of a world, from its parts."""

    def __init__(self, state: RunState, inbox: Inbox):
        self.joins, self.inbox = inbox.joins, inbox


def test_the_clock_alone_holds_a_silent_agent_to_the_deadline_and_says_so():
    state, _, inbox, _ = parts()
    join(_Parts(state, inbox), 1)
    shell = _Shell(state)
    clock = Clock(state, inbox, shell, deadline=0.01)
    state.started = True
    clock.lockstep_tick()
    shell.record_and_step()
    assert clock.late == {1: 1} and state.book[1].missed == 1 and state.core.tick == 1
    rep = clock.reproducibility()
    assert rep["reproducible"] is False and "missed the lockstep deadline (agent 1)" in rep["not_reproducible"][0]


# -- the agent -------------------------------------------------------------------------------


def test_agent_answers_its_frames_with_commands_and_counts_garbage():
    from swarm.agents.node import AgentNode

    world, _ = open_world()
    reply = claim(world, 2)
    ses = FakeSession()
    node = AgentNode(ses, RUN, 2, reply, wait_world=False)
    node.open()
    engine = Engine(parse_scenario(SCENARIO), 10)
    frame = engine.frames()[2]
    node.on_sense(frame)
    (cmd,) = [wire.decode_cmd(p) for p in ses.on(wire.agent_key(RUN, 2, "cmd"))]
    brain = node.new_brain()
    d = brain.decide(frame)
    assert (cmd.agent, cmd.tick, cmd.u, cmd.out, cmd.hops, cmd.key) == (2, 0, d.u, 1, 1, reply["key"])
    node.on_sense(frame)  # the same tick again (a world after its stall): the same command, brain not stepped
    first, again = ses.on(wire.agent_key(RUN, 2, "cmd"))
    assert again == first and node.commands == 1
    node.on_ctl(wire.encode_json({"kind": "signal", "signal": "HUP"}))
    assert node.garbage == 1
    node.maybe_publish_status(force=True)
    st = wire.decode_status(ses.on(wire.agent_key(RUN, 2, "status"))[-1])
    assert (st["out"], st["hops"], st["rooted"], st["commands"]) == (1, 1, True, 1)


# -- limits and trust ---------------------------------------------------------------------------
NEW = {"role": "follower", "x": 1.0, "y": 1.0, "heading": 0.0, "speed": 1.0}


def add(world, aid: int, spec: dict | None = None) -> dict:
    q = FakeQuery(
        wire.encode_join_request(aid, 100 + aid, "host", spec or NEW), key_expr=wire.agent_key(RUN, aid, "join")
    )
    world.joins.on_join(q)
    return wire.decode_join_reply(q.replies[0][1])


def test_added_agents_take_reserved_ids_up_to_the_cap():
    """Added agents take ids from the range the hub's rules were made for; once the cap is
    reached every further claim with a spec is refused: one `limit` event, and a count."""
    world, _ = open_world()  # 2 agents: ids 3..10 may be added, 8 of them
    events = []
    world.engine.on_event = events.append
    s = world.cfg.scenario
    assert (s.added_agents_cap, s.added_id_range) == (8, range(3, 11))
    outside = add(world, 11)
    assert not outside["ok"] and "take ids 3..10" in outside["error"]
    assert "added_agents" not in world.state.over_limit  # a wrong id is not the cap
    assert all(add(world, aid)["ok"] for aid in range(3, 11))
    assert world.info()["added"] == 8
    refused = [add(world, aid) for aid in (11, 12, 11)]
    assert all(not r["ok"] and "its limit (run.max_added_agents)" in r["error"] for r in refused)
    assert world.state.over_limit["added_agents"] == 3 and world.info()["over_limit"] == {"added_agents": 3}
    assert [e["kind"] for e in events].count("limit") == 1
    assert len(world.book) == 10


def test_join_claims_are_rate_limited_per_agent_with_one_event_and_a_count():
    """A burst of claims on one agent's key, then one per s: that agent's flood does not
    use up another agent's claims."""
    from swarm.world.joins import JOIN_BURST

    world, _ = open_world()
    events = []
    world.engine.on_event = events.append
    replies = [claim(world, 2) for _ in range(JOIN_BURST + 5)]
    limited = [r for r in replies if not r["ok"] and "too many join claims" in r["error"]]
    assert len(limited) == 5 and world.state.over_limit["join_rate"] == 5
    assert [e["kind"] for e in events].count("limit") == 1
    assert claim(world, 1)["ok"], "agent 2's flood blocked agent 1's claim"


def test_a_full_inbox_drops_commands_and_queries_but_never_liveliness(monkeypatch):
    import swarm.world.fairness as inbox_mod

    monkeypatch.setattr(inbox_mod, "INBOX_MAX", 3)
    world, _ = open_world()
    events = []
    world.engine.on_event = events.append
    for _ in range(5):
        world.queue.command(wire.agent_key(RUN, 1, "cmd"), b"x")
    world.queue.token(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.PUT)
    assert world.queue.qsize() == 4 and world.queue.dropped == 2
    while world.inbox.drain(None, 0):
        pass
    assert world.state.over_limit["inbox"] == 2 and [e["kind"] for e in events].count("limit") == 1


def test_one_keys_flood_costs_no_other_agent_a_command():
    """Agent 2's command key flooded far past its share: every command of agent 1's gets in,
    agent 2's excess is dropped and counted to agent 2 (flooded_messages), one event."""
    from swarm.world.fairness import PER_KEY_MAX

    world, _ = open_world()
    k1, k2 = join(world, 1), join(world, 2)
    events = []
    world.engine.on_event = events.append
    for _ in range(PER_KEY_MAX + 500):
        cmd = wire.encode_cmd_fields(2, 0, 0.1, None, Phase.TRACK, None, k2)
        world.queue.command(wire.agent_key(RUN, 2, "cmd"), cmd)
    world.queue.command(wire.agent_key(RUN, 1, "cmd"), wire.encode_cmd_fields(1, 0, 0.1, None, Phase.TRACK, None, k1))
    pending = {1, 2}
    while world.inbox.drain(pending, 0):
        pass
    assert world.book[1].commands == 1 and world.book[1].flooded == 0
    assert world.book[2].flooded == 500 and world.book[2].commands == 1
    assert [e.get("key") for e in events if e["kind"] == "limit"] == [wire.agent_key(RUN, 2, "cmd")]
    assert not world.queue.waiting, "the count of waiting messages went astray"


def test_a_rogues_flood_on_an_agents_key_costs_that_agent_nothing():
    """Forged commands (no claim key) on agent 2's key far past its share: counted as rogue,
    never queued, and agent 2's own command still gets in."""
    from swarm.world.fairness import PER_KEY_MAX

    world, _ = open_world()
    join(world, 1)
    k2 = join(world, 2)
    for _ in range(4 * PER_KEY_MAX):
        world.queue.command(
            wire.agent_key(RUN, 2, "cmd"), wire.encode_cmd_fields(2, 0, 5.0, None, Phase.TRACK, None, k2 ^ 1)
        )
    world.queue.command(wire.agent_key(RUN, 2, "cmd"), wire.encode_cmd_fields(2, 0, 0.1, None, Phase.TRACK, None, k2))
    assert world.queue.qsize() == 1
    pending = {2}
    while world.inbox.drain(pending, 0):
        pass
    b = world.book[2]
    assert (b.commands, b.flooded, b.rogue) == (1, 0, 4 * PER_KEY_MAX) and not pending
    assert [e["kind"] for e in world.engine.events].count("rogue") == 1


@pytest.mark.slow
def test_a_flapping_token_is_seen_at_its_latest_state_and_its_churn_is_capped():
    """100,000 toggles of agent 2's token while the world is busy: one inbox entry, the
    latest state; churn past CHURN_EVENTS is counted, not written."""
    from swarm.world.roster import CHURN_EVENTS

    world, _ = open_world()
    join(world, 1)
    key = wire.agent_key(RUN, 2, "alive")
    for i in range(100_000):
        world.queue.token(key, zenoh.SampleKind.PUT if i % 2 == 0 else zenoh.SampleKind.DELETE)
    assert world.queue.qsize() == 1
    while world.inbox.drain(None, 0):
        pass
    assert 2 not in world.core.active_ids() and world.book[2].joins == 0  # last state: gone
    for i in range(2 * CHURN_EVENTS + 11):  # handled one by one: each a join or a drop
        world.queue.token(key, zenoh.SampleKind.PUT if i % 2 == 0 else zenoh.SampleKind.DELETE)
        world.inbox.drain(None, 0)
    b = world.book[2]
    written = [e for e in world.engine.events if e["agent"] == 2 and e["kind"] in ("join", "rejoin", "drop")]
    assert len(written) == CHURN_EVENTS and b.churn_unwritten == CHURN_EVENTS + 11 and b.joins + b.drops == b.churn
    assert [e["limit"] for e in world.engine.events if e["kind"] == "limit"] == ["churn"]
    assert 2 in world.core.active_ids()  # the last toggle was a PUT: the state is still followed


def test_a_law_from_the_join_reply_is_not_imported_unless_trusted(tmp_path, monkeypatch):
    """A join reply (from the world, or once from a rogue) names a law "module:function":
    the agent refuses it, without importing the module, unless its own user trusts it."""
    import json
    import sys

    import pytest

    from swarm.agents.joining import AgentExit
    from swarm.agents.node import AgentNode

    marker = tmp_path / "imported"
    (tmp_path / "evil_law.py").write_text(
        f"open({str(marker)!r}, 'w').write('x')\n\ndef law(gi, gj, lam, c1, c2):\n    return 0.0\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("SWARM_TRUSTED_LAWS", raising=False)
    world, _ = open_world()
    reply = claim(world, 2)
    brain = json.loads(json.dumps(reply["brain"]))
    brain["gains"]["law"] = "evil_law:law"
    with pytest.raises(AgentExit) as exc:
        AgentNode(FakeSession(), RUN, 2, {**reply, "brain": brain}, wait_world=False)
    assert exc.value.code == ExitCode.REFUSED and "--trust-law evil_law:law" in exc.value.message
    assert not marker.exists() and "evil_law" not in sys.modules
    node = AgentNode(FakeSession(), RUN, 2, {**reply, "brain": brain}, wait_world=False, trusted={"evil_law:law"})
    assert marker.exists() and node.brain is not None
