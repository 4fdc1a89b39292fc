"""The world process's ticks against a fake session (tests/support/fakes.py): the frames it sends
when its sensing goes through the grid (encoded from the sensed pairs) are byte for byte
the ones the (N, N) matrices give, and summary.json's `tick_ms` (world/tick_times.py)."""

from __future__ import annotations

import json
import math
import random

import numpy as np
import pytest
import zenoh
from fakes import FakeQuery, FakeSession

from swarm.contracts import wire
from swarm.contracts.scenario import parse_scenario
from swarm.contracts.vocabulary import Phase
from swarm.world.inbox_messages import Command, Garbage
from swarm.world.process import World, WorldConfig
from swarm.world.sensing import GRID_MIN_AGENTS, sensing_matrix

RUN = "ticks"


def ring(n: int, sense_range: float | None, fov: float | None = None, on_dropout: str = "coast") -> dict:
    """n agents around the target, two leaders; a range under which each senses a few others."""
    rs = random.Random(n)
    agents = []
    for k in range(n):
        a = 2 * math.pi * k / n
        r = 30.0 + rs.uniform(-3.0, 3.0)
        spec = {"id": k + 1, "x": r * math.cos(a), "y": r * math.sin(a), "heading": a + 1.6 + rs.uniform(-0.5, 0.5)}
        if k in (0, n // 2):
            spec.update(role="leader", speed=1.0, orbit_radius=10.0 + 5 * (k > 0))
        else:
            spec.update(role="follower", speed=1.0 + rs.uniform(0.0, 0.5))
        agents.append(spec)
    sensing: dict = {"selection": "nearest"}
    if sense_range is not None:
        sensing["range"] = sense_range
    if fov is not None:
        sensing["fov"] = fov
    return {
        "run": {"dt": 0.05, "duration": 1.0, "on_dropout": on_dropout},
        "gains": {"c1": 1.0, "c2": 0.5},
        "sensing": sensing,
        "agents": agents,
    }


def open_world(scenario: dict, out=None, **cfg) -> tuple[World, FakeSession]:
    world = World(
        WorldConfig(parse_scenario(scenario), RUN, "unixsock-stream//nonexistent", out, progress=False, **cfg)
    )
    ses = FakeSession()
    world._open(ses)
    return world, ses


def join_all(world: World) -> None:
    for aid in world.cfg.scenario.ids:
        q = FakeQuery(wire.encode_join_request(aid, 1000 + aid, "host"), key_expr=wire.agent_key(RUN, aid, "join"))
        world.joins.on_join(q)
        assert wire.decode_join_reply(q.replies[0][1])["ok"]
        world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), zenoh.SampleKind.PUT, None)


def sent_frames(ses: FakeSession) -> dict[int, bytes]:
    out = {}
    for key, payload in ses.sent:
        if key.endswith("/sense"):
            out[wire.agent_of_key(key)] = payload
    ses.sent.clear()
    return out


def frames_from_matrices(world: World, sensed, bearing, rng) -> dict[int, bytes]:
    """What world/process.py sent before it encoded from the pairs: encode_sense_rows of the matrices."""
    c = world.core
    active = c.active_ids()
    tx, ty = c.target
    rows = [c.index[a] for a in active]
    frames = wire.encode_sense_rows(
        c.tick, c.time, rows, c.ids, c.heading, tx - c.x, ty - c.y, c.is_leader, sensed, bearing, rng, c.hops
    )
    return dict(zip(active, frames))


@pytest.mark.slow
def test_frames_from_the_sensed_pairs_are_the_matrices_bytes():
    """A ranged swarm past GRID_MIN_AGENTS, some agents dropped (coasting: sensed, sent nothing)
    and some turning with hop counts of their own, over a few ticks: every frame the world
    sends is the one encode_sense_rows makes of the core's matrices, and of every pair's; who
    is in whose sight (a switch's reason asks) comes from the pairs, no matrix made for it."""
    n = 160
    assert n >= GRID_MIN_AGENTS
    for fov in (None, 2.0):
        world, ses = open_world(ring(n, 6.0, fov))
        join_all(world)
        c = world.core
        assert c.uses_grid()
        for aid in (3, 50, 51, 120):
            world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), zenoh.SampleKind.DELETE, None)
        rs = np.random.default_rng(7)
        contacts = 0
        for _ in range(5):
            sent = world.publish_frames()
            got = sent_frames(ses)
            assert set(got) == sent == set(c.active_ids()) and len(sent) == n - 4
            sens = c.scenario.sensing
            every = sensing_matrix(c.x, c.y, c.heading, c.present_mask(), sens.range, sens.fov)
            for k in rs.choice(n, 12, replace=False).tolist() + [c.index[3]]:  # who is in sight, from the pairs
                assert [c.in_sight(k, j) for j in range(n)] == every[0][k].tolist()
            assert c._sensing is not None and c._sensing.matrices is None, "(N, N) matrices made after all"
            assert got == frames_from_matrices(world, *c.sensing())
            assert got == frames_from_matrices(world, *every)
            assert all(c.in_sight(k, j) == every[0][k, j] for k, j in ((0, 1), (1, 0), (5, 100)))
            contacts += sum(len(wire.decode_sense(b).contacts) for b in got.values())
            for aid in sent:
                c.set_command(aid, float(rs.uniform(-1, 1)), int(rs.integers(-1, 4)))
            world.record_and_step()
        assert contacts > 5 * n, "too few agents in sight: the test would prove little"


def test_summary_says_how_long_each_tick_took(tmp_path):
    """Five lockstep ticks nobody answers (a 1 ms deadline each): `tick_ms` has one figure of
    each kind, in order; a world that never ticked says null."""
    s = ring(3, None)
    world, _ = open_world(s, tmp_path / "none")
    assert world.finish()["tick_ms"] is None
    assert json.loads((tmp_path / "none" / "summary.json").read_text())["tick_ms"] is None
    world, _ = open_world(s, tmp_path / "five", duration=0.25, deadline=0.001)
    join_all(world)
    assert world.run() == 0 and world.core.tick == 5
    assert world.clock.tick_times.n == 5
    summary = json.loads((tmp_path / "five" / "summary.json").read_text()) if world.finish() else {}
    ms = summary["tick_ms"]
    assert list(ms) == ["p50", "p99", "max", "mean"]
    assert 0 < ms["p50"] <= ms["p99"] <= ms["max"] and 0 < ms["mean"] <= ms["max"]
    assert ms["max"] == round(1e3 * world.clock.tick_times.high, 4)


def test_command_keys_are_parsed_once_and_only_the_runs_own():
    """The callbacks keep the id of each agent's own command key (world/fairness.py): another
    spelling of a key or a stranger's key is parsed every time, never kept, so what is kept
    stays one key per agent whatever arrives; what a command decodes to is the same."""
    world, _ = open_world(ring(3, None))
    join_all(world)
    q = world.queue
    own = wire.agent_key(RUN, 2, "cmd")
    cmd = wire.encode_cmd_fields(2, 0, 0.1, None, Phase.TRACK, 1, world.book[2].key)
    for _ in range(2):
        q.command(own, cmd)
    keys = q.classifier.cmd_keys
    assert keys == {own: 2}
    stranger = wire.encode_cmd_fields(77, 0, 0.1, None, Phase.TRACK, 1, 5)
    for key in (wire.agent_key(RUN, 77, "cmd"), own.replace("/2/", "/02/"), own + "/more", "elsewhere/agent/2/cmd"):
        for payload in (cmd, stranger, b"garbage"):
            got = q.classifier.decode(key, payload)
            try:
                aid, decoded = wire.agent_of_key(key), wire.decode_cmd(payload)
            except wire.WireError:
                aid, decoded = None, None
            if decoded is not None and decoded.agent == aid:
                assert type(got) is Command and got == (key, aid, decoded), key
            else:
                assert type(got) is Garbage, key
    assert keys == {own: 2}
    pending = {1, 2, 3}
    while world.inbox.drain(pending, 0):
        pass
    assert pending == {1, 3} and world.book[2].commands == 1 and world.state.ignored == 1  # the second: a duplicate


def test_the_world_closes_once_its_agents_have_left_after_the_end_notice():
    """The end notice first, then the session kept open while agent tokens answer (each agent
    leaves on the notice): closed at once, the notice could go down with the links."""
    world, ses = open_world(ring(3, None))
    ses.token_replies = [3, 1]  # three agents, then one, then none left
    world._close()
    end = wire.world_control_key(RUN)
    assert [wire.decode_control(b) for b in ses.on(end)] == [0]
    notice_at = next(i for i, (k, _) in enumerate(ses.sent) if k == end)
    assert [k for k, _ in ses.token_gets] == [wire.agent_key(RUN, "*", "alive")] * 3
    assert all(puts > notice_at for _, puts in ses.token_gets), "asked for the agents before the notice went"
    assert ses.closed


class FakeClock:
    """time.monotonic and time.sleep for world/process.py: sleeping moves the clock on."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def sleep(self, s: float) -> None:
        self.now += s


def test_an_agent_that_never_leaves_holds_the_world_up_no_longer_than_the_wait(monkeypatch):
    import swarm.world.process as process  # lazy: the module whose clock is replaced here

    world, ses = open_world(ring(3, None))
    clock = FakeClock()
    monkeypatch.setattr(process, "time", clock)
    ses.token_replies, ses.tokens_stay = [1], True  # a stopped agent: its token stays
    world._close()
    assert ses.closed
    waited = clock.now - 1000.0
    assert process.END_WAIT_S <= waited <= process.END_WAIT_S + 0.1, waited
    assert 10 <= len(ses.token_gets) <= process.END_WAIT_S / 0.02 + 2, len(ses.token_gets)


@pytest.mark.slow
def test_a_stalled_realtime_world_re_anchors_instead_of_bursting(tmp_path):
    """Realtime, 20 ticks of 50 ms; the world stalls 0.35 s (7 periods) in tick 5. Before, it
    ran the missed ticks back to back (frames and commands a few ms apart, from stale poses);
    now no two ticks start less than half a period apart (a bound the clock keeps however
    slow the machine: load only widens the gaps), a `late` event says how far behind it fell,
    and summary.json counts the late and skipped ticks. Every tick still runs."""
    import time

    s = ring(3, None)
    world, _ = open_world(s, tmp_path / "rt", duration=1.0, clock="realtime")
    join_all(world)
    period = world.core.dt
    starts: list[float] = []
    publish, step = world.publish_frames, world.record_and_step

    def publish_frames():
        starts.append(time.monotonic())
        return publish()

    def record_and_step():
        if world.core.tick == 5:
            time.sleep(7 * period)
        step()

    world.publish_frames, world.record_and_step = publish_frames, record_and_step  # type: ignore[method-assign]
    assert world.run() == 0 and world.core.tick == 20
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    assert len(gaps) == 19 and min(gaps) >= period / 2, [round(g, 4) for g in gaps]
    summary = world.finish()
    assert summary is not None
    late = [e for e in summary["events"] if e["kind"] == "late"]
    assert late and late[0]["skipped"] >= 6 and late[0]["behind_s"] >= 6 * period, late
    assert summary["late_ticks"] >= 1 and summary["skipped_ticks"] >= 6
