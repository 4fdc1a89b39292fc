"""The in-process engine (swarm.offline.sim), its recording (swarm.world.recording), the world core
(swarm.world.core) and the run metrics (swarm.world.metrics)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from swarm.contracts.orbits import root_of, roots
from swarm.contracts.scenario import load_scenario, parse_scenario
from swarm.contracts.scenario_tables import AgentSpec
from swarm.offline.sim import run_sim
from swarm.world.core import ACTIVE, COASTING, GONE, WorldCore
from swarm.world.metrics import agent_metrics, angular_rate, converged, settling_time
from swarm.world.recording import write_run

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
KEYS = {
    *("ids", "role", "speed", "orbit_radius", "target", "dt", "t", "x", "y", "heading", "u", "out", "alive", "missed"),
    "follow",
}


# -- engine ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_run_sim_is_deterministic():
    s = load_scenario(SCENARIOS / "case2.toml")
    r1, r2 = run_sim(s, duration=5.0), run_sim(s, duration=5.0)
    a1, a2 = r1.recorder.arrays(), r2.recorder.arrays()
    assert set(a1) == KEYS
    for k in KEYS:
        np.testing.assert_array_equal(a1[k], a2[k], err_msg=k)
    assert r1.events == r2.events
    assert json.dumps(r1.summary(), default=str) == json.dumps(r2.summary(), default=str)


def test_recording_layout(base):
    s = parse_scenario(base)
    res = run_sim(s, duration=1.0)
    a = res.recorder.arrays()
    n, ticks = 3, 20
    assert a["ids"].tolist() == [1, 2, 3]
    assert a["role"].tolist() == ["leader", "follower", "follower"]
    assert a["speed"].tolist() == [1.0, 1.5, 0.6]
    assert a["orbit_radius"][0] == 2.0 and np.isnan(a["orbit_radius"][1:]).all()
    assert a["target"].tolist() == [0.0, 0.0] and float(a["dt"]) == 0.05
    for k in ("x", "y", "heading", "u", "out", "alive"):
        assert a[k].shape == (ticks + 1, n), k
    assert np.allclose(a["t"], np.arange(ticks + 1) * 0.05)
    # row 0 is the initial pose
    assert a["x"][0].tolist() == [2.0, 0.0, -3.0] and a["y"][0].tolist() == [0.0, -3.0, 1.0]
    # the last row has no command after it
    assert np.isnan(a["u"][-1]).all() and np.isfinite(a["u"][:-1]).all()
    # leaders have no out-neighbour; fixed graph 2 -> 1, 3 -> 2
    assert (a["out"][:-1] == [-1, 1, 2]).all()
    assert a["alive"].all()
    assert res.extra["engine"] == "sim" and res.extra["rejected_commands"] == 0


def test_recorded_rows_are_consistent_with_kinematics(base):
    from swarm.world.kinematics import step

    a = run_sim(parse_scenario(base), duration=1.0).recorder.arrays()
    for k in range(len(a["t"]) - 1):
        nx, ny, ng = step(a["x"][k], a["y"][k], a["heading"][k], a["speed"], a["u"][k], 0.05)
        assert np.array_equal(nx, a["x"][k + 1]) and np.array_equal(ng, a["heading"][k + 1])


def test_duration_argument_overrides_scenario(base):
    base["run"]["duration"] = 100.0
    res = run_sim(parse_scenario(base), duration=0.5)
    assert res.summary()["ticks"] == 10


def test_progress_callback(base):
    calls = []
    run_sim(parse_scenario(base), duration=0.5, progress=lambda k, n: calls.append((k, n)))
    assert calls[0] == (0, 10) and calls[-1] == (10, 10)


def test_switch_events_with_nearest_selection(base):
    base["sensing"] = {"selection": "nearest"}
    for a in base["agents"][1:]:
        del a["follow"]
    res = run_sim(parse_scenario(base), duration=0.5)
    first = [e for e in res.events if e["tick"] == 0]
    assert {e["agent"] for e in first} == {2, 3}  # every follower picks at tick 0
    assert all(e["kind"] == "switch" and e["from"] is None for e in first)
    assert all(e["reason"] == "out-neighbour chosen" for e in first)
    # agent 3 at (-3, 1): nearest is 2 at (0, -3)? |(3, -4)| = 5; leader at (2, 0): |(5, -1)| = 5.10
    assert {e["agent"]: e["to"] for e in first} == {2: 1, 3: 2}


def test_fallback_event_when_pinned_out_of_range(base):
    # range 4.5 m; leader 1 at (2, 0); agent 2 at (-2, -3) is 5 m from it and 4.12 m from
    # agent 3 at (-3, 1), which is 5.10 m from the leader: both pinned to 1, neither senses it.
    base["sensing"]["range"] = 4.5
    base["agents"][1].update(x=-2.0, y=-3.0, follow=1)
    base["agents"][2]["follow"] = 1
    res = run_sim(parse_scenario(base), duration=0.1)
    first = {e["agent"]: e for e in res.events if e["tick"] == 0}
    assert first[2]["to"] == 3 and first[3]["to"] == 2
    assert first[2]["reason"] == first[3]["reason"] == "pinned out-neighbour not sensed"


def test_write_run(tmp_path, base):
    res = run_sim(parse_scenario(base), duration=1.0)
    summary = write_run(res, tmp_path / "run")
    assert (tmp_path / "run" / "trajectory.npz").is_file()
    assert not (tmp_path / "run" / "summary.json.tmp").exists()
    on_disk = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert on_disk == json.loads(json.dumps(summary))
    assert on_disk["ticks"] == 20 and on_disk["dt"] == 0.05 and on_disk["scenario"] == "base"
    assert on_disk["sim_time"] == pytest.approx(1.0)
    assert set(on_disk["agents"]) == {"1", "2", "3"}
    lead = on_disk["agents"]["1"]
    assert lead["expected_radius"] == 2.0 and lead["root"] == 1 and lead["hops"] == 0
    assert on_disk["agents"]["3"]["hops"] == 2 and on_disk["agents"]["3"]["expected_radius"] == pytest.approx(1.2)
    with np.load(tmp_path / "run" / "trajectory.npz") as z:
        assert set(z.files) == KEYS
        assert z["x"].shape == (21, 3)


# -- world core ---------------------------------------------------------------------------


def test_world_sanitises_commands(base):
    base["agents"][1]["max_turn_rate"] = 0.5
    w = WorldCore(parse_scenario(base))
    assert w.set_command(2, 3.0) and w.u[1] == 0.5
    assert w.set_command(2, -3.0) and w.u[1] == -0.5
    assert not w.set_command(2, math.nan) and w.u[1] == -0.5
    assert not w.set_command(3, math.inf)
    assert w.rejected == 2
    assert w.set_command(3, 123.0) and w.u[2] == 123.0  # no limit


def test_world_dropout_leave(base):
    w = WorldCore(parse_scenario(base))
    assert w.drop(2) == GONE
    assert w.active_ids() == [1, 3]
    assert set(w.frames()) == {1, 3}
    assert all(c.id != 2 for f in w.frames().values() for c in f.contacts)
    pose = w.pose(2)
    w.set_command(1, 0.5)
    w.step()
    assert w.pose(2) == pose and np.isnan(w.applied()[1])
    w.join(2)
    assert w.state[1] == ACTIVE and w.u[1] == 0.0 and w.pose(2) == pose


def test_world_dropout_coast(base):
    base["run"]["on_dropout"] = "coast"
    w = WorldCore(parse_scenario(base))
    w.set_command(2, 1.0)
    assert w.drop(2) == COASTING
    assert 2 in [c.id for c in w.frames()[1].contacts]  # still sensed
    x, y, g = w.pose(2)
    w.step()
    assert w.applied()[1] == 0.0
    assert w.pose(2) == pytest.approx((x + 1.5 * 0.05 * math.cos(g), y + 1.5 * 0.05 * math.sin(g), g))
    assert not w.alive_mask()[1] and w.present_mask()[1]


def test_what_the_core_derives_from_the_states_follows_every_change(base):
    """active_ids, the masks and applied are kept from one change of `state` to the next
    (world/core.py `_roster`): however the states change, they say what the states say now,
    and what a caller gets is its own copy."""
    w = WorldCore(parse_scenario(base), joined=False)

    def check():
        st = list(w.state)
        assert w.active_ids() == [int(w.ids[k]) for k, s in enumerate(st) if s == ACTIVE]
        assert w.alive_mask().tolist() == [s == ACTIVE for s in st]
        assert w.present_mask().tolist() == [s != GONE for s in st]
        want = np.where([s == ACTIVE for s in st], w.u, np.where([s == COASTING for s in st], 0.0, np.nan))
        np.testing.assert_array_equal(w.applied(), want)

    check()
    w.join(1)
    check()
    w.join(2)
    w.set_command(2, 0.3)
    check()
    w.drop(2)
    check()
    w.state[0] = COASTING  # straight into the list
    check()
    w.state[:] = [ACTIVE, ACTIVE, GONE]
    check()
    w.state = [GONE, COASTING, ACTIVE]  # a new list
    check()
    w.add_agent(AgentSpec(id=9, role="follower", x=5.0, y=5.0, heading=0.0, speed=1.0))
    check()
    w.join(9)
    w.active_ids().append(1)
    w.alive_mask()[:] = False
    w.present_mask()[:] = False
    check()
    assert w.active_ids() == [3, 9]


def test_world_not_joined(base):
    w = WorldCore(parse_scenario(base), joined=False)
    assert w.active_ids() == [] and w.frames() == {}
    w.step()
    assert w.tick == 1 and w.time == pytest.approx(0.05) and w.pose(1) == (2.0, 0.0, math.pi / 2)


# -- metrics --------------------------------------------------------------------------------


def test_root_of():
    leaders = {1, 6}
    out = {2: 1, 3: 2, 4: 3, 5: 6, 7: 8, 8: 7, 9: None, 10: 11}
    assert root_of(1, out, leaders) == (1, 0)
    assert root_of(2, out, leaders) == (1, 1)
    assert root_of(4, out, leaders) == (1, 3)
    assert root_of(5, out, leaders) == (6, 1)
    assert root_of(7, out, leaders) == (None, None)  # follower-only cycle
    assert root_of(9, out, leaders) == (None, None)  # lost
    assert root_of(10, out, leaders) == (None, None)  # points at an unknown agent


def test_roots_in_one_pass_equal_root_of_for_every_agent():
    import random

    rng = random.Random(5)
    for _ in range(300):
        n = rng.randint(1, 30)
        leaders = {i for i in range(n) if rng.random() < 0.2}
        out = {i: (None if i in leaders or rng.random() < 0.1 else rng.randrange(-1, n + 2)) for i in range(n)}
        got = roots(out, leaders)
        assert got == {i: root_of(i, out, leaders)[0] for i in out}, (out, leaders)


def test_settling_time_synthetic():
    t = np.linspace(0.0, 10.0, 1001)
    R = 10.0
    r = R + 5.0 * np.exp(-t)  # |r - R| <= 0.2  <=>  t >= ln 25
    ts = settling_time(t, r, R)
    assert ts == pytest.approx(math.log(25.0), abs=0.011)
    assert settling_time(t, r, R, band=1e-5) is None  # still outside at the end
    assert settling_time(t, np.full_like(t, R), R) == 0.0
    # leaving the band and coming back counts the last entry
    r2 = np.full_like(t, R)
    r2[500] = 2 * R
    assert settling_time(t, r2, R) == pytest.approx(t[501])


def test_angular_rate_synthetic():
    t = np.linspace(0.0, 20.0, 2001)
    w = -0.7
    x, y = 3.0 + 2.0 * np.cos(w * t), -1.0 + 2.0 * np.sin(w * t)
    assert angular_rate(t, x, y, (3.0, -1.0), 5.0) == pytest.approx(w, rel=1e-9)
    assert math.isnan(angular_rate(t[:1], x[:1], y[:1], (0.0, 0.0), 1.0))


def test_agent_metrics_and_converged():
    # leader 1: R 2, v 1 (omega 0.5); follower 2 (v 2 -> R 4) on its circle; 3 -> 2 (v 0.5 -> R 1)
    # but 1 % off; 4 in a cycle with 5.
    t = np.linspace(0.0, 10.0, 101)
    ids = np.array([1, 2, 3, 4, 5])
    radii = np.array([2.0, 4.0, 1.01, 3.0, 3.0])
    x = np.cos(0.5 * t)[:, None] * radii
    y = np.sin(0.5 * t)[:, None] * radii
    m = agent_metrics(
        ids=ids,
        roles=np.array(["leader"] + ["follower"] * 4),
        speeds=np.array([1.0, 2.0, 0.5, 1.0, 1.0]),
        orbit_radius=np.array([2.0] + [math.nan] * 4),
        t=t,
        x=x,
        y=y,
        alive=np.ones((101, 5), dtype=bool),
        out_final=np.array([-1, 1, 2, 5, 4]),
        target=(0.0, 0.0),
    )
    assert m["1"]["expected_radius"] == 2.0 and m["1"]["radial_error"] == pytest.approx(0.0, abs=1e-12)
    assert m["2"]["expected_radius"] == 4.0 and m["2"]["root"] == 1 and m["2"]["hops"] == 1
    assert m["3"]["expected_radius"] == 1.0 and m["3"]["hops"] == 2
    assert m["3"]["relative_error"] == pytest.approx(0.01)
    assert m["4"]["root"] is None and m["4"]["expected_radius"] is None
    assert m["2"]["angular_rate"] == pytest.approx(0.5)
    assert m["2"]["settling_time"] == 0.0
    assert not converged(m)  # agents 4, 5 have no root
    del m["4"], m["5"]
    assert not converged(m)  # agent 3 is 1 % off
    assert converged(m, tol=0.011)
    m["3"]["alive"] = False
    assert converged(m)  # dead agents do not count
    assert not converged({})


def test_dead_agents_have_no_root():
    t = np.linspace(0.0, 1.0, 11)
    alive = np.ones((11, 2), dtype=bool)
    alive[-1, 0] = False  # the leader dropped
    m = agent_metrics(
        ids=np.array([1, 2]),
        roles=np.array(["leader", "follower"]),
        speeds=np.array([1.0, 1.0]),
        orbit_radius=np.array([1.0, math.nan]),
        t=t,
        x=np.ones((11, 2)),
        y=np.zeros((11, 2)),
        alive=alive,
        out_final=np.array([-1, 1]),
        target=(0.0, 0.0),
    )
    assert m["1"]["alive"] is False and m["1"]["root"] is None
    assert m["2"]["root"] is None and m["2"]["out_neighbour"] == 1
    assert not converged(m)
