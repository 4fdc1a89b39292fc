"""swarm.env.VectorSwarmEnv (docs/guides/learning.md#vector): B swarms over the batch engine
are B SwarmEnvs to the bit: at B = 1 the same observations, rewards, terminations and
truncations over whole episodes with dropouts (and the auto-reset's next episode), swarm b
of B the SwarmEnv seeded seed + b; bad input is a one-line error; its PettingZoo view
passes pettingzoo's API test; one policy object runs in both environments and as a law."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pettingzoo")  # the `env` extra

from pettingzoo.test import parallel_api_test  # noqa: E402

from swarm.contracts.scenario import Scenario, load_scenario, parse_scenario  # noqa: E402
from swarm.env import (  # noqa: E402
    EnvError,
    EnvTypeError,
    SwarmEnv,
    VectorSwarmEnv,
    VectorSwarmView,
    index,
    observation_array,
    policy_law,
    size,
    vector_actions,
)

ROOT = Path(__file__).resolve().parents[2]
OUT, HEADING, BEARING = index("out.present"), index("out.heading"), index("out.bearing")
DROPOUTS = [{"at": 0.5, "kind": "kill", "agent": 4}, {"at": 1.2, "kind": "freeze", "agent": 2}]


def gains_policy(a: np.ndarray) -> float:
    """The paper's bearing law on one observation array (not vectorised: an `if`)."""
    if a[OUT] == 0.0:
        return 0.5
    return 1.0 * float(a[HEADING]) + 0.5 * math.sin(float(a[BEARING]))


def scenario(name: str = "case2", faults=DROPOUTS, duration: float = 2.0, **run) -> Scenario:
    data = tomllib.loads((ROOT / "scenarios" / f"{name}.toml").read_text())
    data["faults"] = list(faults)
    data["run"].update(duration=duration, **run)
    return parse_scenario(data, name)


def assert_same_episodes(s: Scenario, num_envs: int, seed: int, episodes: int = 1, **kwargs) -> dict:
    """Step a VectorSwarmEnv and num_envs SwarmEnvs (seeded seed + b) with the same policy;
    every observation, reward, termination and truncation equal, over `episodes` episodes
    (the vector env auto-resets, the SwarmEnvs reset without a seed). Returns what happened."""
    vec = VectorSwarmEnv(s, num_envs, seed=seed, **kwargs)
    names = vec.possible_agents
    envs = [SwarmEnv(s, **kwargs) for _ in range(num_envs)]
    obs = [e.reset(seed=seed + b)[0] for b, e in enumerate(envs)]
    vobs, vinfo = vec.reset()
    seen = {"steps": 0, "terminated": 0, "truncated": 0, "ended_early": set()}
    for _ in range(episodes):
        while True:
            acts = np.zeros((num_envs, len(names)))
            for b, e in enumerate(envs):
                assert [n for n, live in zip(names, vinfo["live"][b]) if live] == e.agents
                for a, n in enumerate(names):
                    if n in e.agents:
                        np.testing.assert_array_equal(vobs[b, a], obs[b][n])
                        acts[b, a] = gains_policy(obs[b][n])
            got = [e.step({n: acts[b, a] for a, n in enumerate(names) if n in e.agents}) for b, e in enumerate(envs)]
            vobs, rew, term, trunc, vinfo = vec.step(acts)
            seen["steps"] += 1
            for b, (o, r, t, tr, _) in enumerate(got):
                last = vinfo["final_observation"] if vinfo["done"][b] else vobs
                for a, n in enumerate(names):
                    if n not in r:
                        assert rew[b, a] == 0.0 and not term[b, a] and not trunc[b, a]
                        continue
                    assert rew[b, a] == r[n], (b, n, seen["steps"])  # to the bit
                    assert (term[b, a], trunc[b, a]) == (t[n], tr[n])
                    np.testing.assert_array_equal(last[b, a], o[n])
                    seen["terminated"] += t[n]
                    seen["truncated"] += tr[n]
                    if (t[n] or tr[n]) and not vinfo["done"][b]:
                        seen["ended_early"].add((n, "terminated" if t[n] else "truncated", envs[b].engine_tick))
                obs[b] = o
            if vinfo["done"].any():
                assert vinfo["done"].all()  # one episode length: every swarm ends at the same step
                break
        obs = [e.reset()[0] for e in envs]
    return seen


@pytest.mark.slow
def test_one_swarm_is_swarm_env_to_the_bit_over_episodes_with_dropouts():
    seen = assert_same_episodes(scenario(), 1, 7, episodes=2, position_jitter=3.0, heading_jitter=0.2)
    assert seen["steps"] == 400
    assert seen["ended_early"] == {("agent_4", "terminated", 50), ("agent_2", "truncated", 120)}


@pytest.mark.slow
def test_swarm_b_of_many_is_swarm_env_seeded_seed_plus_b():
    seen = assert_same_episodes(scenario(duration=1.0), 3, 11, position_jitter=5.0, heading_jitter=0.3)
    assert seen["terminated"] == 3 and seen["steps"] == 100


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "faults", "run", "agents"),
    [
        ("case2-leader-loss", [{"at": 0.4, "kind": "kill", "agent": 1}], {}, "all"),  # a leader controlled, killed
        ("case2-range", [{"at": 0.3, "kind": "kill", "agent": 3}], {"on_dropout": "coast"}, "followers"),
        ("case2-fov", [{"at": 0.3, "kind": "freeze", "agent": 5}], {}, "all"),
        ("rooted", [{"at": 0.3, "kind": "kill", "agent": 3}], {}, "followers"),
        ("case1-fixed", [], {}, "all"),
    ],
)
def test_every_selection_rule_sensing_and_dropout_is_swarm_env(name, faults, run, agents):
    s = scenario(name, faults, duration=1.0, **run)
    assert_same_episodes(s, 2, 3, agents=agents, position_jitter=2.0, heading_jitter=0.1)


@pytest.mark.parametrize("k", [0, 1, 12])  # no contact blocks; one; more blocks than contacts (padding)
def test_any_number_of_contacts_is_swarm_env(k):
    assert_same_episodes(scenario(duration=0.4), 2, 1, k_nearest=k, agents="all", heading_jitter=0.5)


def test_observations_are_the_documented_arrays_and_rewards_are_finite():
    vec = VectorSwarmEnv(scenario(faults=[], duration=0.5), 4, k_nearest=3)
    obs, info = vec.reset()
    assert obs.shape == (4, 4, size(3)) and obs.dtype == np.float32
    assert vec.possible_agents == ["agent_2", "agent_3", "agent_4", "agent_5"] and info["live"].all()
    obs, rew, term, trunc, info = vec.step(np.full((4, 4), 1e308))  # saturated at pi / dt
    assert rew.shape == (4, 4) and np.isfinite(rew).all() and np.isfinite(obs).all()
    assert (obs[..., index("own.last_u", 3)] == np.float32(math.pi / 0.01)).all()


def test_a_number_of_agents_is_the_random_swarm_of_swarm_study_swarms():
    from swarm.study.swarms import SwarmSetting, random_swarm

    vec = VectorSwarmEnv(10, 2, agents="all", duration=0.5)
    ref = random_swarm(SwarmSetting(n=10, duration=0.5), 0)
    assert vec.base.agents == ref.agents and vec.base.sensing == ref.sensing and vec.base.gains == ref.gains
    obs, _ = vec.reset()
    assert obs.shape == (2, 10, size(6)) and vec.possible_agents == [f"agent_{i}" for i in range(1, 11)]


# -- one policy object: the vector env, SwarmEnv, and a law --------------------------------------
def test_one_policy_object_acts_in_both_environments_and_as_a_law():
    s = scenario(faults=[], duration=0.3)
    vec = VectorSwarmEnv(s, 2)
    obs, _ = vec.reset()
    acts = vector_actions(gains_policy, obs)  # one array at a time
    assert acts.shape == (2, 4)
    assert acts.tolist() == [[gains_policy(o) for o in row] for row in obs]

    def vectorised(a: np.ndarray) -> np.ndarray:  # the same law on the last axis
        return np.where(a[..., OUT] == 0.0, 0.5, 1.0 * a[..., HEADING] + 0.5 * np.sin(a[..., BEARING]))

    vectorised.vectorised = True  # type: ignore[attr-defined]
    np.testing.assert_allclose(vector_actions(vectorised, obs), acts, rtol=1e-6)
    # the same policy object as a law: what it answers on the observation a law is given
    env = SwarmEnv(s)
    sobs, _ = env.reset(seed=0)
    law = policy_law(gains_policy)
    env.step({n: gains_policy(o) for n, o in sobs.items()})
    kept = [o for _, _, o in env.pending if o is not None]  # the Observations the followers' laws would be given
    assert len(kept) == 4
    vlaw = policy_law(vectorised)  # the vectorised one runs as a law too, on one array
    for o in kept:
        assert law(o) == gains_policy(observation_array(o))
        assert vlaw(o) == float(vectorised(observation_array(o)))


# -- the PettingZoo view --------------------------------------------------------------------------
@pytest.mark.slow
def test_the_pettingzoo_view_passes_the_api_test_and_is_swarm_env(capsys):
    s = scenario(duration=1.0)
    parallel_api_test(VectorSwarmView(VectorSwarmEnv(s, 1)), num_cycles=250)
    assert "Passed Parallel API test" in capsys.readouterr().out
    view, env = VectorSwarmView(VectorSwarmEnv(s, 1, seed=4)), SwarmEnv(s)
    for seed in (4, None):  # a seeded episode, then the next one
        vo, _ = view.reset(seed=seed)
        so, _ = env.reset(seed=seed)
        while env.agents:
            assert view.agents == env.agents
            for n in so:
                np.testing.assert_array_equal(vo[n], so[n])
            acts = {n: gains_policy(o) for n, o in so.items()}
            vo, vr, vt, vtr, _ = view.step(acts)
            so, sr, st, str_, _ = env.step(acts)
            assert (vr, vt, vtr) == (sr, st, str_)
        assert view.agents == []


# -- bad input ---------------------------------------------------------------------------------------
BAD_ACTIONS = [
    (np.full((2, 4), np.nan), EnvError, r"actions\[0, 0\] \(swarm 0, agent_2\) is nan: a turn rate must be finite"),
    (np.array([[0, 0, 0, 0], [0, 0, np.inf, 0]]), EnvError, r"actions\[1, 2\] \(swarm 1, agent_4\) is inf"),
    (np.zeros((4, 2)), EnvError, r"actions must have shape \(2, 4\) \(swarms x agents\), not \(4, 2\)"),
    (np.zeros(8), EnvError, r"actions must have shape \(2, 4\) .*not \(8,\)"),
    (np.zeros((0,)), EnvError, r"actions must have shape \(2, 4\) .*not \(0,\)"),
    ("0.5", EnvTypeError, r"actions must be a real array of shape \(2, 4\) \(swarms x agents\), not str"),
    (None, EnvTypeError, r"actions must be a real array .*not None"),
    (0.5, EnvTypeError, r"actions must be a real array .*not float"),
    ({"agent_2": 0.1}, EnvTypeError, r"actions must be a real array .*not dict"),
    (np.zeros((2, 4), dtype=complex), EnvTypeError, r"actions must be a real array of shape \(2, 4\), not .*complex"),
    (np.full((2, 4), "0.5"), EnvTypeError, r"not an array of <U3"),
]


@pytest.mark.parametrize(("actions", "kind", "pattern"), BAD_ACTIONS, ids=[str(i) for i in range(len(BAD_ACTIONS))])
def test_bad_vector_actions_are_one_line_errors_naming_the_entry(actions, kind, pattern):
    vec = VectorSwarmEnv(scenario(faults=[], duration=0.1), 2)
    vec.reset()
    with pytest.raises(kind, match=pattern) as err:
        vec.step(actions)
    assert "\n" not in str(err.value)
    assert vec.tick == 0  # nothing moved
    vec.step(np.zeros((2, 4, 1)))  # (B, A, 1) is fine too
    assert vec.tick == 1


BAD_CONSTRUCTION = [
    ({"num_envs": 0}, EnvError, r"num_envs must be an int >= 1, not 0"),
    ({"num_envs": "4"}, EnvTypeError, r"num_envs must be an int >= 1, not str '4'"),
    ({"num_envs": 2.0}, EnvTypeError, r"num_envs must be an int >= 1, not float"),
    ({"seed": "1"}, EnvTypeError, r"seed must be an int or None, not str '1'"),
    ({"seed": -1}, EnvError, r"seed must be in 0 \.\. 2\*\*63 - 1, not -1"),
    ({"seed": None}, EnvTypeError, r"seed must be an int or a sequence of num_envs ints, not None"),
    ({"seed": [1, 2, 3]}, EnvError, r"seed: 3 seeds for 2 swarms"),
    ({"seed": [1, 2.5]}, EnvTypeError, r"seed\[1\] must be an int or None, not float 2.5"),
    ({"duration": math.nan}, EnvError, r"duration must be a finite number of seconds > 0, not nan"),
    ({"duration": -1}, EnvError, r"duration must be a finite number of seconds > 0, not -1"),
    ({"k_nearest": -1}, EnvError, r"k_nearest must be an int >= 0, not -1"),
    ({"k_nearest": 1.5}, EnvTypeError, r"k_nearest must be an int >= 0, not float 1.5"),
    ({"rate_weight": math.inf}, EnvError, r"rate_weight must be a finite number >= 0, not inf"),
    ({"agents": "some"}, EnvError, r"agents must be 'followers' or 'all', not 'some'"),
    ({"scenario": 2}, EnvError, r"scenario: a random swarm needs 3 agents or more \(2 leaders\), not 2"),
    ({"scenario": 3.0}, EnvTypeError, r"scenario must be a Scenario, a file path or a number of agents, not float"),
]


@pytest.mark.parametrize(("kwargs", "kind", "pattern"), BAD_CONSTRUCTION, ids=[str(c[0]) for c in BAD_CONSTRUCTION])
def test_bad_construction_is_a_one_line_error_naming_the_argument(kwargs, kind, pattern):
    kwargs = {"num_envs": 2, **kwargs}
    s = kwargs.pop("scenario", scenario(faults=[], duration=0.5))
    with pytest.raises(kind, match=pattern) as err:
        VectorSwarmEnv(s, **kwargs)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("faults", "pattern"),
    [
        ([{"at": 0.5, "kind": "restart", "agent": 4}], r"not faults\[0\] = 'restart'.*needs SwarmEnv"),
        ([{"at": 0.1, "kind": "loss", "probability": 0.3, "duration": 1.0}], r"not faults\[0\] = 'loss'"),
    ],
)
def test_what_it_does_not_run_it_refuses_saying_why(faults, pattern):
    with pytest.raises(EnvError, match=pattern):
        VectorSwarmEnv(scenario(faults=faults), 2)
    with pytest.raises(EnvError, match=r"cannot run lab10: it has a \[safety\] table; SwarmEnv can"):
        VectorSwarmEnv(load_scenario(ROOT / "scenarios" / "lab10.toml"), 2)
    with pytest.raises(EnvError, match=r"a PettingZoo view is of a vector env of one swarm, not 2"):
        VectorSwarmView(VectorSwarmEnv(scenario(faults=[]), 2))


@pytest.mark.slow
def test_leaders_the_policy_steers_plan_no_path(monkeypatch):
    """A leader whose turn rate the actions give plans no circle-circle path (~0.2 s a leader,
    thrown away): with agents="all" the planner is never called; with the leaders left to
    their law it is, once per leader and start."""
    import swarm.agents.batch_leader as batch_leader

    calls = []
    real = batch_leader.plan_cc
    monkeypatch.setattr(batch_leader, "plan_cc", lambda *a: calls.append(a) or real(*a))
    batch_leader._plan.cache_clear()
    env = VectorSwarmEnv(10, 4, seed=0, agents="all", position_jitter=5.0, duration=0.5)
    env.reset(seed=0)
    env.step(np.zeros((4, env.n_agents)))
    assert calls == []
    VectorSwarmEnv(10, 4, seed=0, position_jitter=5.0, duration=0.5).reset(seed=0)
    assert len(calls) == 8  # 2 leaders x 4 swarms, each its own start
