"""The safety filter in runs: `swarm sim` with a [safety] table, the batch engine, summary.json,
and `swarm up --clock lockstep` equal to `swarm sim` to the bit with the filter at work.

The scenario: two leaders on one orbit (r = 10 m, ccw), the faster one behind: without the
filter it runs through the slower one (a collision); with it, it passes beside it.
"""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest
from cli_invoke import invoke
from runtime_helpers import sim_results, start_up

from swarm.contracts.scenario import ScenarioError, parse_scenario
from swarm.contracts.vocabulary import EventKind, ExitCode
from swarm.offline.batch import run_batch
from swarm.offline.sim import run_sim
from swarm.world.recording import write_run

OVERTAKE = """
name = "overtake"
description = "Two leaders on one orbit, the faster behind the slower: it runs through it without [safety]"

[run]
dt = 0.01
duration = {duration}

[gains]
c1 = 0.5
c2 = 0.25

[[agents]]
id = 1
role = "leader"
x = 10.0
y = 0.0
heading = 1.5707963
speed = 5.0
orbit_radius = 10.0
max_turn_rate = 2.0

[[agents]]
id = 2
role = "leader"
x = 0.0
y = -10.0
heading = 0.0
speed = 6.0
orbit_radius = 10.0
max_turn_rate = 2.0
"""
RADIUS = 1.0


def overtake(safety: dict | None = None, duration: float = 40.0):
    data = tomllib.loads(OVERTAKE.format(duration=duration))
    if safety is not None:
        data["safety"] = safety
    return parse_scenario(data, "overtake")


def distance(arrays) -> np.ndarray:
    return np.hypot(arrays["x"][:, 0] - arrays["x"][:, 1], arrays["y"][:, 0] - arrays["y"][:, 1])


@pytest.mark.slow
def test_without_the_filter_they_collide_and_with_it_they_do_not():
    # 20 s (was 40 s): the collision spell is over by then (200 ticks from about 14.7 s, its
    # least distance 0.002 m), and the filter's two spells are in it, as over 40 s
    bare = run_sim(overtake(duration=20.0))
    assert "safety" not in bare.summary()
    a = bare.recorder.arrays()
    assert distance(a).min() < RADIUS
    measuring = run_sim(overtake({"radius": RADIUS, "enabled": False}, duration=20.0))  # (its arrays and summary)
    measured = measuring.summary()
    # enabled = false: the same run, measured: one collision spell, no intervention
    np.testing.assert_array_equal(measuring.recorder.arrays()["x"], a["x"])
    s = measured["safety"]
    assert s["collisions"] == 1 and s["collision_ticks"] > 0 and s["min_distance"] < RADIUS
    assert s["interventions"] == 0 and not any(e["kind"] == EventKind.SAFETY for e in measured["events"])

    filtered = run_sim(overtake({"radius": RADIUS}, duration=20.0))
    summ = filtered.summary()
    s = summ["safety"]
    assert s["collisions"] == 0 and s["collision_ticks"] == 0
    assert s["min_distance"] >= RADIUS
    assert distance(filtered.recorder.arrays()).min() == pytest.approx(s["min_distance"])
    assert s["interventions"] > 0 and s["infeasible"] == 0 and s["boundary_exits"] == 0
    events = [e for e in summ["events"] if e["kind"] == EventKind.SAFETY]
    assert len(events) == s["spells"] == sum(a["safety"]["spells"] for a in summ["agents"].values())
    assert sum(a["safety"]["interventions"] for a in summ["agents"].values()) == s["interventions"]
    for e in events:  # the first tick of a spell: what the law asked, what was applied, and why
        assert e["u"] != e["u_law"] and e["by"] and e["infeasible"] is False
        assert e["reason"].startswith("turn rate ")
    # the recorded turn rates are the ones applied (the filter's), within the limits
    u = filtered.recorder.arrays()["u"][:-1]
    assert np.all(np.abs(u) <= 2.0)


@pytest.mark.slow
def test_an_arena_is_kept_and_exits_are_counted_without_the_filter():
    """An arena whose west wall cuts the orbit (x = -9 m, the orbit reaches -10 m): without the
    filter both leaders leave it on every lap (each spell one exit); with it they stay in, turned
    by the wall, sometimes with no safe turn rate at their constant speed (recorded) and at
    their turn-rate limit (saturations). Over 20 s (was 40 s): four exits unfiltered (seven in
    40 s); filtered, 91 ticks with no safe turn rate in 5 spells and 48 saturations."""
    arena = [-9.0, -11.0, 11.0, 11.0]
    out = run_sim(overtake({"radius": RADIUS, "arena": arena, "enabled": False}, duration=20.0)).summary()["safety"]
    summ = run_sim(overtake({"radius": RADIUS, "arena": arena}, duration=20.0)).summary()
    kept = summ["safety"]
    assert out["boundary_exits"] >= 4 and out["outside_ticks"] > 0 and out["saturations"] == 0
    assert kept["boundary_exits"] == 0 and kept["outside_ticks"] == 0 and kept["collisions"] == 0
    assert kept["infeasible"] > 0 and kept["saturations"] > 0
    # an event on the first tick of each spell of changes, and of each spell with no safe command
    events = [e for e in summ["events"] if e["kind"] == EventKind.SAFETY]
    assert len(events) == kept["spells"] + kept["infeasible_spells"]
    stuck = [e for e in events if e["infeasible"]]
    assert len(stuck) == kept["infeasible_spells"] > 0
    assert all(e["reason"].startswith("no safe turn rate: the least violating applied") for e in stuck)
    assert kept["arena"] == [[-9.0, -11.0], [11.0, -11.0], [11.0, 11.0], [-9.0, 11.0]]


@pytest.mark.slow
def test_the_batch_engine_equals_sim_with_the_filter():
    """Equal to the bit over 15 s (was 20 s): the filter at work in both (the overtake's 258
    interventions, none before 10 s; with the arena, 35 ticks with no safe turn rate, 3 such spells,
    and 20 saturations too: equality over a prefix holds on the whole run)."""
    arena = [-9.0, -11.0, 11.0, 11.0]
    scens = [overtake({"radius": RADIUS}, duration=15.0), overtake({"radius": RADIUS, "arena": arena}, duration=15.0)]
    for s, b in zip(scens, run_batch(scens)):
        r = run_sim(s)
        ra, ba = r.recorder.arrays(), b.recorder.arrays()
        for key in ("x", "y", "heading", "u"):
            np.testing.assert_array_equal(ba[key], ra[key], err_msg=key)
        rs, bs = r.summary(), b.summary()
        assert rs["safety"]["interventions"] > 0  # the prefix has the filter at work
        if s.safety.corners:
            assert rs["safety"]["infeasible_spells"] > 0 and rs["safety"]["saturations"] > 0
        assert bs["events"] == rs["events"]
        assert bs["safety"] == rs["safety"]
        assert {k: v["safety"] for k, v in bs["agents"].items()} == {k: v["safety"] for k, v in rs["agents"].items()}


@pytest.mark.slow  # a whole run and its files (about 0.5 s): the long tier
def test_summary_json_carries_the_figures(tmp_path):
    summ = write_run(run_sim(overtake({"radius": RADIUS}, duration=10.0)), tmp_path)
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert on_disk["safety"]["collisions"] == summ["safety"]["collisions"] == 0
    for key in ("min_distance", "collisions", "boundary_exits", "saturations", "interventions", "infeasible"):
        assert key in on_disk["safety"]
    assert set(on_disk["agents"]["1"]["safety"]) >= {"interventions", "spells", "saturations", "boundary_exits"}


def test_the_table_is_checked():
    with pytest.raises(ScenarioError, match="safety.arena"):
        overtake({"radius": RADIUS, "arena": [[0.0, 0.0], [1.0, 0.0]]})
    with pytest.raises(ScenarioError, match="outside safety.arena"):
        overtake({"radius": RADIUS, "arena": [-5.0, -5.0, 5.0, 5.0]})
    with pytest.raises(ScenarioError, match="safety.radius"):
        overtake({"radius": -1.0})
    with pytest.raises(ScenarioError, match="safety.gama: unknown key"):
        overtake({"radius": RADIUS, "gama": 1.0})
    assert overtake({"radius": RADIUS}).safety.lookahead_m == pytest.approx(0.25 * RADIUS)


@pytest.mark.slow
def test_lockstep_up_equals_sim_with_the_filter(rt, tmp_path):
    """`swarm up --clock lockstep` runs the filter in the world process: the same turn rates,
    poses, "safety" events and figures as `swarm sim`, to the bit. Over 10 s (1000 ticks): seven
    "safety" events, infeasible spells and saturations among them, in `swarm sim` of it."""
    scen = tmp_path / "overtake.toml"
    scen.write_text(OVERTAKE.format(duration=10.0) + f"\n[safety]\nradius = {RADIUS}\narena = [-9, -11, 11, 11]\n")
    up = start_up(rt.tracker, scen, tmp_path / "up", "--clock", "lockstep")
    # `swarm sim` in this process while the run goes (its process is not the claim: its files are)
    res = invoke("sim", scen, "--out", tmp_path / "sim", "--no-plots")
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    sim, sim_summ = sim_results(tmp_path / "sim")
    rc = up.launcher.wait(120)
    assert rc == ExitCode.OK, up.launcher.text()[-3000:]
    traj, summ = up.trajectory(), up.summary()
    for key in ("t", "x", "y", "heading", "u", "out", "alive"):
        np.testing.assert_array_equal(traj[key], sim[key], err_msg=key)
    strip = lambda evs: [{k: v for k, v in e.items() if k != "wall_time"} for e in evs if e["kind"] == "safety"]  # noqa: E731
    assert strip(summ["events"]) == strip(sim_summ["events"]) != []
    assert summ["safety"] == sim_summ["safety"]
    assert summ["safety"]["collisions"] == 0 and math.isfinite(summ["safety"]["min_distance"])


class _Plant:
    """A plant (world/plant.py) that moves its unicycles itself, at the speeds the core gives."""

    def __init__(self):
        self.sent: list[tuple[np.ndarray, np.ndarray]] = []

    def prepare(self): ...

    def start(self, core, event): ...

    def hold(self): ...

    def stop(self): ...

    def figures(self):
        return {}

    def step(self, core, u):
        from swarm.world.kinematics import step

        self.sent.append((np.array(u), np.array(core.speed)))
        core.x, core.y, core.heading = step(core.x, core.y, core.heading, core.speed, u, core.dt)


@pytest.mark.slow  # 2000 ticks in this process (the speed cuts start at tick 1371): the long tier
def test_a_plant_gets_the_filtered_turn_rates_and_speeds():
    """Robots mode: the plant is handed the filter's turn rates and, with speed = true, drives
    at its speeds (slowed for the overtake), the agents' own speeds untouched."""
    from swarm.world.engine import Engine

    s = overtake({"radius": RADIUS, "speed": True}, duration=20.0)
    plant = _Plant()
    e = Engine(s, 2000, plant=plant)
    e.start_plant()
    for k in range(2000):
        for aid in e.frames():
            e.command(aid, k, 0.5 if aid == 1 else 0.6, None, 0)  # both orbit (v / r) and close in
        e.end_tick()
    res = e.result({})
    speeds = np.array([v for _, v in plant.sent])
    assert (speeds < [5.0, 6.0]).any() and np.all(speeds <= [5.0, 6.0]) and np.all(speeds >= 0.0)
    np.testing.assert_array_equal(e.core.speed, [5.0, 6.0])
    summ = res.summary()["safety"]
    assert summ["speed_cuts"] > 0 and summ["collisions"] == 0
    np.testing.assert_array_equal(np.array([u for u, _ in plant.sent]), res.recorder.arrays()["u"][:2000])


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["per-agent", "batch"])
def test_a_study_row_carries_the_figures_and_the_filter_may_be_swept(engine):
    """`swarm study scenario --safety 0,1`: the same starts with the filter off (measured) and
    on; every row has collisions, boundary exits, saturations and the least distance."""
    from swarm.study.scenario import Jitter, Template, run_chunk, run_one, settings_of, summarise

    # 20 s: the unfiltered runs collide (at about 17 s) and leave the arena 4 times (was 40 s: 7 times)
    arena = [-9.0, -11.0, 11.0, 11.0]
    template = Template(overtake({"radius": RADIUS, "arena": arena}, duration=20.0).model_dump(), "overtake")
    settings = settings_of({"safety": [0.0, 1.0]})
    work = run_one if engine == "per-agent" else run_chunk
    rows = [r for st in settings for r in work((template, st, Jitter(positions=0.5), (0, 1)))]
    assert len(rows) == 4
    off, on = rows[:2], rows[2:]
    assert all(r["collisions"] >= 1 and r["boundary_exits"] >= 1 and r["interventions"] == 0 for r in off)
    assert all(r["collisions"] == 0 and r["boundary_exits"] == 0 and r["interventions"] > 0 for r in on)
    assert all(r["min_distance"] >= RADIUS for r in on) and all(r["min_distance"] < RADIUS for r in off)
    summary = summarise(rows, settings)
    assert [s["safe_runs"] for s in summary] == [0, 2] and summary[1]["collisions"] == 0


def test_a_robots_file_carries_the_table_for_its_robots():
    """robots mode: the robots file's [safety] replaces the scenario's; a bad one is refused
    naming the field."""
    from swarm.robots.config import RobotsError, parse_robots
    from swarm.robots.plant import robot_scenario

    robots = {"robots": [{"agent": 1}, {"agent": 2, "namespace": "/tb3_1"}]}
    s = overtake({"radius": 5.0})
    assert robot_scenario(s, parse_robots(robots)).safety == s.safety  # none in the file: the scenario's
    file = parse_robots({**robots, "safety": {"radius": 0.3, "speed": True, "arena": [-12, -12, 12, 12]}})
    got = robot_scenario(s, file).safety
    assert (
        got is not None
        and got.radius == 0.3
        and got.speed
        and got.corners
        == [
            (-12.0, -12.0),
            (12.0, -12.0),
            (12.0, 12.0),
            (-12.0, 12.0),
        ]
    )
    with pytest.raises(RobotsError, match="safety.gamma"):
        parse_robots({**robots, "safety": {"radius": 0.3, "gamma": 0}})


def test_swarm_check_shows_the_table_and_warns_of_unbounded_turn_rates(tmp_path):
    path = tmp_path / "s.toml"
    text = OVERTAKE.format(duration=20.0).replace("max_turn_rate = 2.0\n", "", 1)
    path.write_text(text + "\n[safety]\nradius = 1.0\narena = [[-20, -15], [20, -15], [0, 25]]\n")
    res = invoke("check", path)
    assert res.exit_code == 0, res.output
    assert "safety: filter, radius=1 m, lookahead=0.25 m, gamma=2/s, speed may not change" in res.output
    assert "arena: (-20, -15) (20, -15) (0, 25)" in res.output
    assert "agents 1 have no max_turn_rate" in res.output


@pytest.mark.slow  # a whole run (20 s: the collision is at about 17 s) through the CLI: the long tier
def test_swarm_sim_prints_the_figures(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(OVERTAKE.format(duration=20.0) + "\n[safety]\nradius = 1.0\nenabled = false\n")
    res = invoke("sim", path, "--no-plots", "-o", tmp_path / "run")
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("safety"))
    assert line.startswith("safety (measured only, radius 1 m): collisions 1, boundary exits 0, saturations 0")
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["safety"]["collisions"] == 1


def test_the_world_info_carries_the_figures_so_far():
    from swarm.world.engine import Engine
    from swarm.world.report import run_info
    from swarm.world.roster import AgentBook

    s = overtake({"radius": RADIUS, "enabled": False})
    e = Engine(s, 10)
    for k in range(10):
        for aid in e.frames():
            e.command(aid, k, 0.5, None, 0)
        e.end_tick()
    info = run_info(e, {a.id: AgentBook() for a in s.agents}, {"run": "r"})
    assert info["safety"]["enabled"] is False and info["safety"]["min_distance"] > RADIUS
    assert "safety" not in run_info(Engine(overtake(), 1), {1: AgentBook(), 2: AgentBook()}, {"run": "r"})


def test_the_builder_makes_the_table():
    import swarm

    b = swarm.Builder("demo", dt=0.05, duration=5.0, c1=1.0, c2=0.5)
    b.leader(1, x=2, y=0, heading=1.57, speed=1.0, orbit_radius=2.0, max_turn_rate=1.0)
    b.follower(2, x=0, y=-3, heading=0.0, speed=1.5, max_turn_rate=2.0)
    s = b.safety(0.3, arena=[-5, -5, 5, 5], speed=True).build()
    assert s.safety is not None and s.safety.radius == 0.3 and s.safety.speed
    assert swarm.simulate(s).summary.safety.collisions == 0
    with pytest.raises(swarm.ScenarioError, match="outside safety.arena"):
        b.safety(0.3, arena=[-1, -1, 1, 1]).build()


@pytest.mark.slow  # three runs of a 6-agent swarm: the long tier
def test_a_swarms_study_measures_collisions_at_a_radius():
    """`swarm study swarms --safety-radius R`: random swarms with a measuring [safety] table,
    the same rows through either engine, the law unchanged."""
    from swarm.study.batch import run_swarm_chunk
    from swarm.study.swarms import SwarmSetting, random_swarm, run_swarm

    setting = SwarmSetting(n=6, duration=15.0, safety_radius=2.0)  # (was 30 s: the same claims on any length)
    assert random_swarm(setting, 0).safety is not None and not random_swarm(setting, 0).safety.enabled
    one = run_swarm((setting, 0))
    (batched,) = run_swarm_chunk((setting, (0,)))
    for key in ("collisions", "boundary_exits", "saturations", "min_distance", "interventions", "converged"):
        assert one[key] == batched[key], key
    assert one["interventions"] == 0 and one["min_distance"] > 0
    bare = run_swarm((SwarmSetting(n=6, duration=15.0), 0))  # the same swarm, not measured
    assert bare["collisions"] is None and bare["min_distance"] is None
    assert (bare["converged"], bare["switches"]) == (one["converged"], one["switches"])  # the law unchanged
