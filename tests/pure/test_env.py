"""swarm.env (docs/guides/learning.md): the PettingZoo ParallelEnv over the in-process engine
passes pettingzoo's own API test, its agents leave and come back as the scenario's faults
say, a policy acting in it gives the run `swarm sim` gives with the policy as a law, its
observation array has the documented layout, its actions are saturated like a law's
answers, its rewards can be replaced, its episodes are reproducible from a seed; and the
example (examples/train_policy) trains, then runs its law under lockstep `swarm up` and
`swarm sim` with the same trajectories."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import sys
import tomllib
import uuid
from pathlib import Path

import numpy as np
import pytest

import swarm

pytest.importorskip("pettingzoo")  # the `env` extra

from pettingzoo.test import parallel_api_test  # noqa: E402

from swarm.contracts.frames import Contact  # noqa: E402
from swarm.contracts.observation import Observation  # noqa: E402
from swarm.contracts.scenario import Scenario, parse_scenario  # noqa: E402
from swarm.env import (  # noqa: E402
    FIELDS,
    SwarmEnv,
    WorldView,
    index,
    observation_array,
    policy_law,
    radial_rate_reward,
    size,
)

ROOT = Path(__file__).resolve().parents[2]
CASE2 = ROOT / "scenarios" / "case2.toml"
EXAMPLE = ROOT / "examples" / "train_policy"
OUT, HEADING, BEARING = index("out.present"), index("out.heading"), index("out.bearing")

# Process faults within 3 s of case 2: follower 4 killed and restarted, follower 2 frozen
# and thawed, and a lossy, noisy network over part of it.
FAULTS = [
    {"at": 0.5, "kind": "kill", "agent": 4},
    {"at": 1.0, "kind": "restart", "agent": 4},
    {"at": 1.5, "kind": "freeze", "agent": 2},
    {"at": 2.0, "kind": "thaw", "agent": 2},
    {"at": 0.2, "kind": "loss", "probability": 0.3, "duration": 1.0},
    {"at": 1.2, "kind": "noise", "std": 0.05, "duration": 1.0},
]


def case2(**changes) -> dict:
    data = tomllib.loads(CASE2.read_text())
    data.update(changes)
    return data


def faulty(law: dict | None = None, duration: float = 3.0) -> Scenario:
    data = case2(faults=FAULTS)
    data["run"]["duration"] = duration
    if law:
        data["law"] = law
    return parse_scenario(data, "faulty", law_dirs=(ROOT,))


def gains_policy(a: np.ndarray) -> float:
    """The paper's bearing law on the observation array (a small, stable policy)."""
    if a[OUT] == 0.0:
        return 0.5
    return 1.0 * float(a[HEADING]) + 0.5 * math.sin(float(a[BEARING]))


@pytest.mark.slow
def test_parallel_api_test_passes_with_dropouts_and_returns(capsys):
    parallel_api_test(SwarmEnv(faulty(), agents="all"), num_cycles=400)
    parallel_api_test(SwarmEnv(CASE2, duration=1.0), num_cycles=200)
    assert capsys.readouterr().out.count("Passed Parallel API test") == 2


@pytest.mark.slow
def test_agents_leave_and_come_back_as_the_faults_say():
    env = SwarmEnv(faulty())
    assert env.possible_agents == ["agent_2", "agent_2#1", "agent_3", "agent_4", "agent_4#1", "agent_5"]
    obs, infos = env.reset(seed=0)
    assert env.agents == ["agent_2", "agent_3", "agent_4", "agent_5"] == list(obs) == list(infos)
    seen: dict[str, tuple[int, str]] = {}  # name -> (tick, what)
    stale = 0
    while env.agents:
        before = set(env.agents)
        obs, rew, term, trunc, info = env.step({a: gains_policy(o) for a, o in obs.items()})
        tick = env.engine_tick
        assert set(obs) == set(rew) == set(term) == set(trunc) == set(info) >= before
        for name in set(obs) - before:
            seen[name] = (tick, "came")
        for name in before:
            if term[name] or trunc[name]:
                seen.setdefault(name, (tick, "terminated" if term[name] else "truncated"))
        stale += sum(o[0] == 0.0 for o in obs.values())
    assert seen == {
        "agent_4": (50, "terminated"),  # killed at 0.5 s
        "agent_4#1": (100, "came"),  # restarted at 1.0 s: a new agent
        "agent_2": (150, "truncated"),  # frozen at 1.5 s
        "agent_2#1": (200, "came"),  # thawed at 2.0 s
        "agent_3": (300, "truncated"),  # the end of the episode
        "agent_5": (300, "truncated"),
    }
    assert env.agents == [] and sum(term.values()) == 0 and all(trunc.values())
    assert stale > 0, "the lossy network delivered every frame: no stale observation was seen"


@pytest.mark.slow
def test_a_policy_in_the_env_is_the_run_swarm_sim_gives_with_it_as_a_law(tmp_path, monkeypatch):
    """Faults of every kind, every agent a policy (leaders too): the same trajectories,
    out-neighbours and events, to the bit."""
    mod = f"envpolicy_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{mod}.py").write_text(
        "import math\nfrom swarm.env import index, policy_law\n"
        "OUT, H, B, T = index('out.present'), index('out.heading'), index('out.bearing'), index('target.bearing')\n"
        "def policy(a):\n"
        "    if a[1] == 1.0:\n"  # a leader: turn towards the target, then hold an orbit rate
        "        return 2.0 * math.sin(a[T]) + a[2] / a[11]\n"
        "    return 0.5 if a[OUT] == 0.0 else 1.0 * a[H] + 0.5 * math.sin(a[B])\n"
        "law = policy_law(policy)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    scenario = parse_scenario(
        {
            **faulty().model_dump(mode="json", exclude_none=True),
            "law": {"follower": f"{mod}:law", "leader": f"{mod}:law"},
        },
        "faulty",
        law_dirs=(tmp_path,),
    )
    policy = __import__(mod).policy
    sim = swarm.simulate(scenario)  # swarm sim's engine, as the Python API returns its run
    env = SwarmEnv(scenario, agents="all")
    obs, _ = env.reset()
    while env.agents:
        obs, *_ = env.step({a: policy(o) for a, o in obs.items()})
    got = env.result()
    assert type(got) is type(sim) and got.run_dir is None
    for key in ("t", "x", "y", "heading", "u", "out", "alive", "missed"):
        np.testing.assert_array_equal(got.arrays[key], sim.arrays[key], err_msg=key)
    sim_events = [(e.tick, e.kind, e.agent) for e in sim.summary.events]
    assert [(e.tick, e.kind, e.agent) for e in got.summary.events] == sim_events
    assert {"drop", "rejoin", "switch"} <= {k for _, k, _ in sim_events}
    assert got.summary.engine == "env" and got.summary.agents == sim.summary.agents
    assert got.summary.converged == sim.summary.converged and got.summary.faults == sim.summary.faults


def _contact(i: int, bearing: float, heading: float, rng: float, hops: int = -1) -> Contact:
    return Contact(i, bearing, heading, rng, hops)


def test_the_observation_array_has_the_documented_layout():
    far, near, mid = _contact(7, 0.5, 1.0, 30.0, 2), _contact(3, 3.0, -3.0, 10.0, 0), _contact(5, 0.1, 0.2, 20.0)
    obs = Observation(
        2, "follower", 4, 0.04, 0.01, 22.0, 0.3, 3.0, (far, near, mid), far, None, None, 1,
        1.0, 0.5, {}, {}, 0.25,
    )  # fmt: skip
    a = observation_array(obs, k=4)
    assert a.dtype == np.float32 and a.shape == (size(4),) == (38,)
    assert len(FIELDS) == size() == 48
    own = dict(zip(FIELDS[:8], a[:8].tolist()))
    assert own == pytest.approx(
        {"own.fresh": 1, "own.leader": 0, "own.speed": 22, "own.max_turn_rate": 3, "own.last_u": 0.25,
         "own.cos_heading": math.cos(0.3), "own.sin_heading": math.sin(0.3), "own.contacts": 3}
    )  # fmt: skip
    assert a[index("target.present") : index("target.direction") + 1].tolist() == [0.0] * 5
    assert a[index("out.present") : index("out.hops") + 1] == pytest.approx([1, 30, 0.2, 0.7, 2])
    # nearest first, angles relative to own heading and wrapped to (-pi, pi]
    assert a[index("contact0.present") : index("contact0.hops") + 1] == pytest.approx(
        [1, 10, 2.7, -3.3 + 2 * math.pi, 0], abs=1e-6
    )
    assert a[index("contact1.range", 4)] == 20.0 and a[index("contact2.range", 4)] == 30.0
    assert a[index("contact3.present", 4) :].tolist() == [0.0] * 5  # padded: mask 0
    leader = obs._replace(role="leader", out=None, target=(0.0, -10.0), orbit_radius=28.0, direction=-1)
    b = observation_array(leader, k=1, fresh=False)
    assert b[0] == 0.0 and b[1] == 1.0
    assert b[index("target.present", 1) : index("target.direction", 1) + 1] == pytest.approx(
        [1, 10, -math.pi / 2 - 0.3, 28, -1]
    )
    assert b[index("out.present", 1)] == 0.0 and b[index("contact0.range", 1)] == 10.0


def test_actions_are_saturated_and_a_missing_one_holds_the_last_turn_rate():
    data = case2()
    for a in data["agents"]:
        if a["role"] == "follower":
            a["max_turn_rate"] = 2.0
    env = SwarmEnv(parse_scenario(data), duration=0.05)
    assert env.action_space("agent_2").high.tolist() == [2.0]
    obs, _ = env.reset()
    env.step({a: np.array([50.0]) for a in obs})
    env.step({a: -0.75 for a in obs})
    env.step({})  # no action: the last command held
    env.step({a: 1e308 for a in obs})  # saturated, never integrated as it is
    u = env.result().u
    assert u[0, 1:5].tolist() == [2.0] * 4
    assert u[1, 1:5].tolist() == [-0.75] * 4
    assert u[2, 1:5].tolist() == [-0.75] * 4
    assert u[3, 1:5].tolist() == [2.0] * 4


def test_rewards_are_replaceable_and_the_default_is_radial_and_rate_error():
    env = SwarmEnv(CASE2, duration=0.02, reward=lambda view, aid: float(aid) + view.time)
    obs, _ = env.reset()
    _, rew, *_ = env.step({a: 0.0 for a in obs})
    assert rew == {f"agent_{i}": pytest.approx(i + 0.01) for i in (2, 3, 4, 5)}
    # On the orbit: a leader at (28, 0) heading +y at 28 m/s, R = 28 (omega 1 rad/s); a follower
    # rooted at it at (0, -35) heading +x at 35 m/s (R = 35): both exactly right, reward 0.
    ids = np.array([1, 2, 3])
    view = WorldView(
        1, 0.01, ids, {1: 0, 2: 1, 3: 2}, np.array([28.0, 0.0, 5.0]), np.array([0.0, -35.0, 5.0]),
        np.array([math.pi / 2, 0.0, 0.0]), np.array([28.0, 35.0, 10.0]), np.zeros(3), np.ones(3, bool),
        np.array([-1, 1, -1]), np.array([True, False, False]), np.array([28.0, np.nan, np.nan]),
        np.array([1.0, 0.0, 0.0]), (0.0, 0.0), {1: 1, 2: 1, 3: None},
    )  # fmt: skip
    r = radial_rate_reward(rate_weight=2.0)
    assert r(view, 1) == pytest.approx(0.0, abs=1e-12) and r(view, 2) == pytest.approx(0.0, abs=1e-12)
    assert r(view, 3) == -3.0  # rooted at nobody: the worst
    off = view._replace(x=np.array([28.0, 0.0, 5.0]), y=np.array([0.0, -42.0, 5.0]))  # 7 m out: 20%
    assert r(off, 2) == pytest.approx(-(0.2 + 2.0 * abs(35.0 / 42.0 - 1.0)))


@pytest.mark.slow
def test_episodes_are_reproducible_from_the_seed():
    def episode(env: SwarmEnv, seed: int | None) -> tuple[np.ndarray, list[float]]:
        obs, _ = env.reset(seed=seed)
        first = np.concatenate(list(obs.values()))
        total = []
        while env.agents:
            obs, rew, *_ = env.step({a: gains_policy(o) for a, o in obs.items()})
            total.append(sum(rew.values()))
        return first, total

    env = SwarmEnv(faulty(duration=1.0), position_jitter=5.0, heading_jitter=0.3)
    a, b, c = episode(env, 3), episode(env, 3), episode(env, 4)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1] == b[1]
    assert not np.array_equal(a[0], c[0]) and a[1] != c[1]
    d, e = episode(env, None), episode(env, None)  # the generator goes on: new starts
    assert not np.array_equal(d[0], e[0])


def test_the_guides_first_block_runs_and_its_result_is_swarm_sims_results(tmp_path):
    # issue 33: env.result() was documented as swarm sim's results but was a RunResult, whose
    # summary is a method (res.summary.converged: AttributeError). The block of
    # docs/guides/learning.md as written, but 1 s of case 2 and its run directory in tmp_path.
    text = (ROOT / "docs" / "guides" / "learning.md").read_text()
    block = re.search(r"```python\n(.*?)```", text, re.S)[1]
    code = block.replace('SwarmEnv("scenarios/case2.toml")', f"SwarmEnv({str(CASE2)!r}, duration=1.0)")
    code = code.replace('"runs/', f'"{tmp_path}/')
    assert code.count(str(CASE2)) == 1 and code.count(str(tmp_path)) == 1, block  # the block still reads so
    space: dict = {"my_policy": gains_policy}
    exec(compile(code, "learning.md", "exec"), space)
    res = space["res"]
    assert isinstance(res, swarm.Results) and res.x.shape == (101, 6)
    assert res.summary.converged is False and res.converged is False  # 1 s: far from its orbit yet
    assert res.summary.engine == "env" and isinstance(res.summary.agents[3].radial_error, float)
    assert res.agent(3).x.shape == (101,)
    saved = swarm.open_run(res.run_dir)  # res.save(...) wrote trajectory.npz and summary.json
    assert saved.summary.to_dict() == res.summary.to_dict()
    np.testing.assert_array_equal(saved.x, res.x)


@pytest.mark.slow
def test_policy_law_is_a_law_a_scenario_can_name_and_swarm_env_stays_light(tmp_path):
    law = policy_law(gains_policy)
    assert law.__name__ == "policy_law(gains_policy)"
    assert math.isclose(law(Observation(2, "follower", 0, 0.0, 0.01, 22.0, 0.0, None, (), None, None, None, 1,
                                        1.0, 0.5, {}, {}, 0.0)), 0.5)  # fmt: skip
    s = parse_scenario(
        case2(law={"follower": "policy:law"}), "example", law_dirs=(EXAMPLE,)
    )  # the example's law, checked as [law] follower
    assert s.law.follower == "policy:law"
    code = "import sys, swarm.env; print('pettingzoo' in sys.modules, 'gymnasium' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert out.stdout.split() == ["False", "False"]


@pytest.mark.slow
def test_the_example_trains_then_lockstep_up_equals_sim(tmp_path):
    """examples/train_policy with a tiny budget (a copy: its gains.json is written next to
    its policy.py): the trained gains score no worse than the initial ones, and the law run
    under lockstep `swarm up` gives `swarm sim`'s trajectories to 0 m."""
    ex = tmp_path / "train_policy"
    shutil.copytree(EXAMPLE, ex, ignore=shutil.ignore_patterns("gains.json", "__pycache__", "runs"))
    cmd = [sys.executable, str(ex / "train.py"), "--generations", "2", "--population", "2", "--episode", "3",
           "--episodes", "1", "--workers", "1", "--duration", "3", "--out", str(tmp_path / "runs")]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    print(res.stdout)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    trained = json.loads((ex / "gains.json").read_text())
    rewards = [g["reward"] for g in trained["history"]]
    assert len(rewards) == 3 and rewards == sorted(rewards), rewards  # elitist: never worse
    assert trained["gains"] == trained["history"][-1]["gains"]
    sim = np.load(tmp_path / "runs" / "sim" / "trajectory.npz")
    up = np.load(tmp_path / "runs" / "up" / "trajectory.npz")
    assert sim["x"].shape == up["x"].shape == (301, 6)
    assert np.abs(up["x"] - sim["x"]).max() == 0.0 and np.abs(up["y"] - sim["y"]).max() == 0.0
    np.testing.assert_array_equal(up["out"], sim["out"])
    summary = json.loads((tmp_path / "runs" / "up" / "summary.json").read_text())
    assert summary["clock"] == "lockstep" and summary["completed"] is True
    assert "max |dx|, |dy| = 0 m" in res.stdout
