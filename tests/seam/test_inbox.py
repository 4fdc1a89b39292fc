"""The world's inbox items, typed (world/inbox_messages.py): what `Classifier` makes of each kind
of command sample and liveliness key, garbage and rogue included; that the zenoh callback's side
(world/fairness.py) and the main thread's (world/inbox.py) count the same for the same inputs;
and that `Inbox.handle` dispatches each item by its type. Against a fake session
(tests/support/fakes.py)."""

from __future__ import annotations

import random

import zenoh
from fakes import FakeQuery
from test_shells import RUN, join, open_world

from swarm.contracts import wire
from swarm.contracts.vocabulary import Phase
from swarm.world.inbox_messages import (
    Admin,
    Command,
    Garbage,
    Ignored,
    Info,
    Join,
    Rogue,
    Supervise,
    Token,
)


def _cmd(aid: int, key: int | None, tick: int = 0, out: int | None = None, on: int | None = None) -> tuple[str, bytes]:
    """Agent `aid`'s command for `tick` carrying claim key `key`, on agent `on`'s key (default its own)."""
    phase = Phase.TRACK if out is not None else Phase.LOST
    payload = wire.encode_cmd_fields(aid, tick, 0.1, out, phase, None, key or 0)
    return wire.agent_key(RUN, aid if on is None else on, "cmd"), payload


def _two():
    world, _ = open_world()
    return world, join(world, 1), join(world, 2)


def test_classify_tells_every_kind_of_command():
    world, k1, k2 = _two()
    c = world.queue.classifier
    key2 = wire.agent_key(RUN, 2, "cmd")

    good = c.classify(*_cmd(2, k2, out=1))
    assert type(good) is Command and (good.key, good.aid, good.cmd.u, good.cmd.out) == (key2, 2, 0.1, 1)
    assert c.admit(good) is good  # taken as it is: nothing made anew

    garbage = {
        "undecodable": (key2, b"garbage"),
        "not an agent key": ("elsewhere/agent/x/cmd", _cmd(2, k2)[1]),
        "another agent's command": _cmd(1, k1, on=2),
        "follows itself": _cmd(2, k2, out=2),
        "follows nobody the run has": _cmd(2, k2, out=99),
    }
    for what, (key, payload) in garbage.items():
        v = c.classify(key, payload)
        assert type(v) is Garbage and v.key == key, what
        assert v.aid == (None if what == "not an agent key" else 2), what

    v = c.classify(*_cmd(2, k2, tick=5))
    assert type(v) is Ignored and v == (2, "inactive")  # a tick not reached yet
    v = c.classify(*_cmd(2, k2 ^ 1))
    assert type(v) is Rogue and v == (2, True)  # not the owner's claim key

    world.inbox.on_cmd(*_cmd(2, k2), None)
    assert world.book[2].commands == 1
    v = c.classify(*_cmd(2, k2))
    assert type(v) is Ignored and v.why == "duplicate"

    world.inbox.on_alive(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.DELETE, None)
    v = c.classify(*_cmd(1, k1))
    assert type(v) is Ignored and v.why == "inactive"  # dropped


def test_a_command_on_an_id_nobody_claimed_is_rogue_whatever_key_it_carries():
    """An agent whose token came without a join claim has no claim key: every command on its key is
    a rogue's, but not `claimed` (the callback queues it; the main thread counts it)."""
    world, _ = open_world()
    world.inbox.on_alive(wire.agent_key(RUN, 1, "alive"), zenoh.SampleKind.PUT, None)
    assert world.core.active_ids() == [1] and world.book[1].key is None
    for key in (0, 12345):
        v = world.queue.classifier.classify(*_cmd(1, key))
        assert type(v) is Rogue and v == (1, False)
    world.queue.command(*_cmd(1, 7))
    assert world.queue.qsize() == 1 and not world.queue.rogue  # queued, not diverted
    world.inbox.drain(None, 0)
    assert world.book[1].rogue == 1 and world.book[1].commands == 0


def test_a_claimed_agents_rogue_is_counted_in_the_callback_and_never_queued():
    world, _, k2 = _two()
    world.queue.command(*_cmd(2, k2 ^ 1))
    assert world.queue.qsize() == 0 and world.queue.rogue == {2: 1}
    world.inbox.drain(None, 0)
    assert world.book[2].rogue == 1 and [e["kind"] for e in world.engine.events].count("rogue") == 1


def test_classify_tells_liveliness_keys():
    world, _ = open_world()
    c = world.queue.classifier
    assert c.token(wire.agent_key(RUN, 2, "alive")) == 2
    v = c.token("not/an/agent/key")
    assert type(v) is Garbage and v.aid is None
    v = c.token(wire.agent_key(RUN, 77, "alive"))
    assert type(v) is Ignored and v == (77, "unknown")
    before = (world.state.garbage, world.state.ignored)
    world.inbox.on_alive("not/an/agent/key", zenoh.SampleKind.PUT, None)
    world.inbox.on_alive(wire.agent_key(RUN, 77, "alive"), zenoh.SampleKind.PUT, None)
    assert (world.state.garbage, world.state.ignored) == (before[0] + 1, before[1] + 1)


def _counts(world) -> tuple:
    st = world.state
    books = tuple((a, b.commands, b.garbage, b.rogue, b.last_cmd_tick) for a, b in sorted(world.book.items()))
    kinds = [e["kind"] for e in world.engine.events if e["kind"] != "rogue"]  # rogue: at most one a second
    return st.garbage, st.ignored, books, kinds, world.core.u.tolist()


def test_the_callbacks_side_and_the_main_threads_count_the_same():
    """The same 400 random command samples, good and bad, handled at once (`Inbox.on_cmd`: classified
    on the main thread) and through the queue (`FairQueue.command` in the callback, then `drain`):
    the same counts, events and latched commands."""
    rng = random.Random(5)
    direct, k1, k2 = _two()
    queued, _, _ = _two()
    queued.book[1].key, queued.book[2].key = k1, k2  # the same claim keys, so the same samples
    samples = []
    for _ in range(400):
        aid = rng.choice([1, 2])
        key = {1: k1, 2: k2}[aid]
        kind = rng.choice(["good", "rogue", "garbage", "other", "out_self", "future", "stranger"])
        if kind == "good":
            samples.append(_cmd(aid, key, tick=0, out=rng.choice([None, 3 - aid])))
        elif kind == "rogue":
            samples.append(_cmd(aid, key ^ rng.randrange(1, 1 << 16)))
        elif kind == "garbage":
            samples.append((wire.agent_key(RUN, aid, "cmd"), rng.randbytes(rng.randrange(0, 40))))
        elif kind == "other":
            samples.append(_cmd(3 - aid, key, on=aid))
        elif kind == "out_self":
            samples.append(_cmd(aid, key, out=aid))
        elif kind == "future":
            samples.append(_cmd(aid, key, tick=3))
        else:
            samples.append(_cmd(77, 1))
    for key, payload in samples:
        direct.inbox.on_cmd(key, payload, None)
        queued.queue.command(key, payload)
    while queued.inbox.drain(None, 0):
        pass
    got, want = _counts(queued), _counts(direct)
    assert got == want
    garbage, ignored, books, kinds, _ = want
    assert garbage > 0 and ignored > 0 and sum(b[3] for b in books) > 0 and sum(b[1] for b in books) == 2
    assert "switch" in kinds
    for w in (direct, queued):
        assert {e["agent"] for e in w.engine.events if e["kind"] == "rogue"} == {1, 2}
    assert not queued.queue.waiting


def test_handle_dispatches_each_item_by_its_type(monkeypatch):
    world, k1, k2 = _two()
    inbox = world.inbox
    seen: list[tuple[str, object]] = []
    monkeypatch.setattr(inbox.joins, "on_join", lambda q: seen.append(("join", q)))
    monkeypatch.setattr(inbox, "on_info", lambda q: seen.append(("info", q)))
    monkeypatch.setattr(inbox, "on_admin", lambda q: seen.append(("admin", q)))
    monkeypatch.setattr(inbox.reports, "on_supervise", lambda q: seen.append(("supervise", q)))
    queries = {name: FakeQuery(key_expr=f"swarm/{RUN}/{name}") for name in ("join", "info", "admin", "supervise")}
    for msg in (
        Join(queries["join"]),
        Info(queries["info"]),
        Admin(queries["admin"]),
        Supervise(queries["supervise"]),
    ):
        inbox.handle(msg, None)
    assert seen == [(name, q) for name, q in queries.items()]

    pending = {1, 2}
    cmd = world.queue.classifier.decode(*_cmd(2, k2))
    assert type(cmd) is Command
    inbox.handle(cmd, pending)
    assert pending == {1} and world.book[2].commands == 1

    inbox.handle(Garbage(wire.agent_key(RUN, 1, "cmd"), 1), pending)
    assert world.state.garbage == 1 and world.book[1].garbage == 1

    key = wire.agent_key(RUN, 1, "alive")
    world.queue.token(key, zenoh.SampleKind.DELETE)
    item = world.queue.get(0)
    assert type(item) is Token and item.key == key
    inbox.handle(item, pending)
    assert 1 not in world.core.active_ids() and pending == set()

    inbox.handle(("cmd", wire.agent_key(RUN, 2, "cmd"), _cmd(2, k2, tick=0)[1]), None)  # type: ignore[arg-type]
    assert world.book[2].commands == 1 and world.state.ignored == 0  # a bare tuple is no item: nothing happens


def test_queries_count_against_their_own_key():
    world, _ = open_world()
    fq = world.queue
    q = FakeQuery(key_expr=wire.world_admin_key(RUN))
    fq.enqueue(Admin(q))
    assert fq.waiting == {wire.world_admin_key(RUN): 1}
    assert Join(object()).key == "join" and Supervise(object()).key == "supervise"  # no key: its kind's
    item = fq.get(0)
    assert type(item) is Admin and item.query is q
    fq.taken(item)
    assert fq.waiting == {}
