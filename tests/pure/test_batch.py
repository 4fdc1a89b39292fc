"""The batch engine (swarm/offline/batch.py, world/batch.py, agents/batch*.py):
equal to `swarm sim`'s per-agent engine within 1e-9 m over whole runs (to the bit on this
project's machines; case 1 over a prefix that holds its events), with the same switch events
and summaries; many seeds in one batch
equal each seed run alone; `swarm sim --batch` and `swarm study --batch` write what the
per-agent paths write; what it does not run, it refuses, saying why."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_invoke import invoke

from swarm.agents.batch_maths import wrap as batch_wrap
from swarm.contracts.orbits import wrap
from swarm.contracts.scenario import load_scenario, parse_scenario
from swarm.offline.batch import BatchRefused, refusal, run_batch
from swarm.offline.sim import run_sim
from swarm.study.swarms import SwarmSetting, random_swarm

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
TOL = 1e-9  # m, over the whole trajectory


def deviation(a, b) -> float:
    """Max |x - x'|, |y - y'| over every tick and agent (m)."""
    a, b = a.recorder.arrays(), b.recorder.arrays()
    assert a["x"].shape == b["x"].shape
    return max(float(np.max(np.abs(a[k] - b[k]))) for k in ("x", "y"))


def summary(res) -> str:
    s = dict(res.summary())
    s.pop("engine")
    return json.dumps(s, default=str)


def assert_same_run(ref, got, *, full: bool = True) -> None:
    """`got` (batch) is `ref` (run_sim): trajectory within TOL, the same out-neighbours,
    switch events (reasons included) and summary ("engine" apart)."""
    assert deviation(ref, got) <= TOL
    a, b = ref.recorder.arrays(), got.recorder.arrays()
    np.testing.assert_array_equal(a["out"], b["out"])
    np.testing.assert_array_equal(a["follow"], b["follow"])  # the same follow states (summary: state_s)
    if full:
        np.testing.assert_allclose(a["u"], b["u"], rtol=0, atol=1e-9, equal_nan=True)
    assert got.events == ref.events
    assert summary(got) == summary(ref)
    assert got.extra["engine"] == "sim-batch"


def assert_same_as_written(out: Path, got) -> None:
    """`got` (batch) is the `swarm sim` run written in `out` (conftest.shipped_sim: the
    session's one run of a shipped scenario): assert_same_run, read from its trajectory.npz
    and summary.json (events included; "engine" and the wall-clock figures apart)."""
    with np.load(out / "trajectory.npz") as z:
        a = {k: z[k] for k in z.files}
    b = got.recorder.arrays()
    assert a["x"].shape == b["x"].shape
    assert max(float(np.max(np.abs(a[k] - b[k]))) for k in ("x", "y")) <= TOL
    np.testing.assert_array_equal(a["out"], b["out"])
    np.testing.assert_array_equal(a["follow"], b["follow"])
    np.testing.assert_allclose(a["u"], b["u"], rtol=0, atol=1e-9, equal_nan=True)
    ref = json.loads((out / "summary.json").read_text())
    mine = json.loads(json.dumps(got.summary(), default=lambda o: o.item()))  # as written
    assert ref.pop("engine") == "sim" and mine.pop("engine") == "sim-batch"
    for k in ("wall_time", "sim_seconds_per_wall_second"):
        ref.pop(k)
    assert mine["events"] == ref["events"]
    assert json.dumps(mine, sort_keys=True) == json.dumps(ref, sort_keys=True)


# -- whole runs --------------------------------------------------------------------------------
# The shipped scenarios' `swarm sim` runs are the session's (conftest.shipped_sim), shared with
# the tests that check them (tests/pure/test_cli_offline.py, the lockstep tests): only the batch
# run is this file's. Case 2 and its two limited-sensing variants share (dt, ticks, agents, rule):
# their whole runs are one batch (each member equals its run alone: the many-seeds test below),
# 12 s of CPU instead of 6 + 9 + 8 s run one by one.
CASE2S = ("case2", "case2-range", "case2-fov")


@pytest.fixture(scope="module")
def case2_batch() -> dict:
    """The batch engine's whole runs of case2, case2-range and case2-fov, in one batch."""
    scenarios = [load_scenario(SCENARIOS / f"{name}.toml") for name in CASE2S]
    return dict(zip(CASE2S, run_batch(scenarios)))


@pytest.mark.slow  # 3,000 ticks each way
def test_case1_equals_swarm_sim_over_a_prefix_that_holds_its_events():
    """Case 1 over its first 30 s: every switch (tick 0) and follow-state change (by tick 4),
    the leaders' CC paths flown into their orbit hold (by 1.2 s) and the followers' approach.
    The batch engine's own whole run of case 1 costs 17 s of CPU (0.58 ms a tick for 5 agents,
    three times `swarm sim`'s): the whole-run comparisons are case 2's three below."""
    s = load_scenario(SCENARIOS / "case1.toml")
    ref, (got,) = run_sim(s, duration=30.0), run_batch([s], duration=30.0)
    assert_same_run(ref, got)
    assert ref.events and max(e["tick"] for e in ref.events) < 3000 // 10  # the events well inside the prefix
    f = ref.recorder.arrays()["follow"]
    assert not (f[300:] != f[300]).any()  # no follow-state change after 3 s


@pytest.mark.slow
def test_case2_whole_run_equals_swarm_sim(shipped_sim, case2_batch):
    res, out = shipped_sim("case2")
    assert res.exit_code == 0, res.output
    got = case2_batch["case2"]
    assert_same_as_written(out, got)
    assert [e["kind"] for e in got.events] == ["switch"] * 5  # 2 tracks 1 for a tick, then 4


@pytest.mark.slow
def test_random_30_agent_swarm_whole_run_equals_swarm_sim():
    # a 60 m range: followers lose their out-neighbours, loiter and switch (every reason)
    s = random_swarm(SwarmSetting(n=30, leaders=3, range=60.0, duration=100.0), 1)
    ref, (got,) = run_sim(s), run_batch([s])
    assert_same_run(ref, got)
    reasons = {e["reason"] for e in ref.events}
    assert {"out-neighbour chosen", "no out-neighbour: searching", "out-neighbour out of sight"} <= reasons


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, make",
    [
        ("range 40 m", lambda: random_swarm(SwarmSetting(range=40.0, duration=150.0), 7)),
        ("range 60 m, fov 180 deg", lambda: random_swarm(SwarmSetting(range=60.0, fov=math.pi, duration=150.0), 8)),
        ("case2-range", None),  # shipped: `swarm sim`'s run is the session's
        ("case2-fov", None),
    ],
)
def test_limited_sensing_whole_run_equals_swarm_sim(name, make, shipped_sim, request):
    """Holds, coasts, shadows and searches (the followers' slow path, one by one) beside
    keeps over arrays: the same bits, the same events, the same loss figures."""
    if make is None:
        res, out = shipped_sim(name)
        assert res.exit_code == 0, res.output
        got = request.getfixturevalue("case2_batch")[name]  # (only these two need it)
        assert_same_as_written(out, got)  # the summaries' loss figures among the rest
        a = json.loads((out / "summary.json").read_text())["agents"]
    else:
        s = make()
        ref, (got,) = run_sim(s), run_batch([s])
        assert_same_run(ref, got)
        a = ref.summary()["agents"]
    b = got.summary()["agents"]
    assert {k: (v.get("losses"), v.get("loss_switches_max")) for k, v in a.items()} == {
        k: (v.get("losses"), v.get("loss_switches_max")) for k, v in b.items()
    }
    assert sum(v.get("losses", 0) for v in a.values()) > 0  # the rule's other states were exercised


# -- every rule, briefly -----------------------------------------------------------------------


def _with(s, **sensing):
    return s.model_copy(update={"sensing": s.sensing.model_copy(update=sensing)})


@pytest.mark.parametrize(
    "name, make",
    [
        (
            "nearest, range, hysteresis",
            lambda: _with(
                random_swarm(SwarmSetting(n=10, selection="nearest", range=70.0, duration=15.0), 2), hysteresis=0.2
            ),
        ),
        ("rooted", lambda: random_swarm(SwarmSetting(n=10, selection="rooted", duration=15.0), 3)),
        ("rooted, range", lambda: random_swarm(SwarmSetting(n=10, selection="rooted", range=60.0, duration=15.0), 3)),
        ("sticky, fov", lambda: random_swarm(SwarmSetting(n=10, range=80.0, fov=3.0, duration=15.0), 1)),
        ("rooted, hysteresis 0.2 (rooted.toml)", lambda: load_scenario(SCENARIOS / "rooted.toml")),
        ("fixed (case2-fixed)", lambda: load_scenario(SCENARIOS / "case2-fixed.toml")),
        ("turn-rate limits (turtlebot)", lambda: load_scenario(SCENARIOS / "turtlebot.toml")),
    ],
)
@pytest.mark.slow  # a whole run in-process
def test_every_rule_equals_swarm_sim(name, make):
    s = make()
    ref, (got,) = run_sim(s, duration=8.0), run_batch([s], duration=8.0)
    assert_same_run(ref, got)


def test_fixed_fallback_reason(base):
    # tests/pure/test_sim.py's case: both followers pinned to a leader they cannot sense
    base["sensing"]["range"] = 4.5
    base["agents"][1].update(x=-2.0, y=-3.0, follow=1)
    base["agents"][2]["follow"] = 1
    s = parse_scenario(base)
    ref, (got,) = run_sim(s, duration=1.0), run_batch([s], duration=1.0)
    assert_same_run(ref, got)
    assert {e["reason"] for e in got.events if e["tick"] == 0} == {"pinned out-neighbour not sensed"}


@pytest.mark.parametrize("selection", ["sticky", "nearest", "rooted"])
def test_equal_ranges_go_to_the_lowest_id_whatever_the_order(base, selection):
    # ids out of order; follower 5 at the origin is exactly 10 m from leaders 7 and 3
    base["sensing"] = {"selection": selection}
    base["agents"] = [
        {"id": 7, "role": "leader", "x": 10.0, "y": 0.0, "heading": 1.0, "speed": 1.0, "orbit_radius": 10.0},
        {"id": 3, "role": "leader", "x": -10.0, "y": 0.0, "heading": 2.0, "speed": 1.0, "orbit_radius": 10.0},
        {"id": 5, "role": "follower", "x": 0.0, "y": 0.0, "heading": 0.5, "speed": 1.0},
    ]
    s = parse_scenario(base)
    ref, (got,) = run_sim(s, duration=0.5), run_batch([s], duration=0.5)
    assert_same_run(ref, got)
    assert got.events[0]["to"] == 3


@pytest.mark.slow  # a whole run in-process
def test_many_seeds_in_one_batch_equal_each_seed_alone():
    # 12 leaders: more than batch_leader.SCALAR_MAX, so the array orbit hold runs
    setting = SwarmSetting(n=8, leaders=2, range=55.0, duration=12.0)
    scenarios = [random_swarm(setting, seed) for seed in range(6)]
    together = run_batch(scenarios, lean=True)
    for s, got in zip(scenarios, together):
        ref = run_sim(s)
        assert deviation(ref, got) <= TOL
        np.testing.assert_array_equal(ref.recorder.arrays()["out"], got.recorder.arrays()["out"])
        assert got.events == ref.events and summary(got) == summary(ref)


def test_exact_wrap_matches_the_scalar_one():
    rng = np.random.default_rng(5)
    a = np.concatenate(
        [
            rng.uniform(-8, 8, 2000),
            rng.uniform(-100, 100, 200),
            [math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 3 * math.pi, 0.0, -0.0],
        ]
    )
    assert batch_wrap(a).tolist() == [wrap(v) for v in a.tolist()]


# -- refusals ------------------------------------------------------------------------------------


def test_faults_and_own_laws_are_refused_with_the_reason(base, monkeypatch):
    faults = load_scenario(SCENARIOS / "faults.toml")
    assert "faults" in refusal(faults)
    with pytest.raises(BatchRefused, match="faults"):
        run_batch([faults])
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "support"))
    base["gains"]["law"] = "helpers_law:constant_law"
    own = parse_scenario(base)
    with pytest.raises(BatchRefused, match="only the built-in 'bearing' law"):
        run_batch([own])
    assert refusal(load_scenario(SCENARIOS / "case2.toml")) is None


def test_members_of_one_batch_must_share_dt_ticks_agents_and_rule():
    a = random_swarm(SwarmSetting(n=6, duration=5.0), 0)
    for b in (
        random_swarm(SwarmSetting(n=7, duration=5.0), 0),
        random_swarm(SwarmSetting(n=6, duration=6.0), 0),
        random_swarm(SwarmSetting(n=6, duration=5.0, selection="nearest"), 0),
    ):
        with pytest.raises(ValueError, match="one batch needs"):
            run_batch([a, b])


# -- the commands --------------------------------------------------------------------------------


@pytest.mark.slow  # a whole run in-process
def test_sim_batch_writes_what_sim_writes(tmp_path):
    common = (SCENARIOS / "case2.toml", "--duration", "5", "--no-plots")
    assert invoke("sim", *common, "--out", tmp_path / "a").exit_code == 0
    res = invoke("sim", *common, "--out", tmp_path / "b", "--batch")
    assert res.exit_code == 0, res.output
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in "ab")
    assert b.pop("engine") == "sim-batch" and a.pop("engine") == "sim"
    for k in ("wall_time", "sim_seconds_per_wall_second"):
        a.pop(k), b.pop(k)
    assert a == b
    with np.load(tmp_path / "a" / "trajectory.npz") as za, np.load(tmp_path / "b" / "trajectory.npz") as zb:
        assert za.files == zb.files
        for k in za.files:
            np.testing.assert_array_equal(za[k], zb[k], err_msg=k)
    assert (tmp_path / "b" / "recording.mcap").stat().st_size > 1000


def test_sim_batch_refuses_a_scenario_with_faults(tmp_path):
    res = invoke("sim", SCENARIOS / "faults.toml", "--batch", "--out", tmp_path / "x")
    assert res.exit_code == 2
    assert "faults" in res.output and "without --batch" in res.output
    assert not (tmp_path / "x").exists()


@pytest.mark.slow  # a whole run in-process
def test_study_batch_rows_equal_per_agent_rows(tmp_path):
    args = (
        "study",
        "swarms",
        "--seeds",
        "3",
        "--n",
        "6",
        "--range",
        "inf,50",
        "--duration",
        "10",
        "-j",
        "1",
        "--no-plot",
    )
    assert invoke(*args, "--out", tmp_path / "p", "--per-agent").exit_code == 0
    res = invoke(*args, "--out", tmp_path / "b")
    assert res.exit_code == 0, res.output
    assert "batches" in res.output

    def rows(d):
        with (tmp_path / d / "runs.csv").open() as f:
            return sorted(tuple((k, v) for k, v in r.items() if k != "wall_s") for r in csv.DictReader(f))

    assert len(rows("b")) == 6 and rows("b") == rows("p")
