"""Bad input to swarm.env (issue 36, docs/guides/learning.md#bad-input): every case a
one-line error of swarm.env's own types naming the argument (EnvError: a swarm.UsageError,
a ValueError; EnvTypeError: also a TypeError), or the documented saturation (an action of
1e308 is a hard turn, never a poisoned episode); pettingzoo's API test still passes."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import swarm

pytest.importorskip("pettingzoo")  # the `env` extra

from pettingzoo.test import parallel_api_test  # noqa: E402

from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.env import SwarmEnv  # noqa: E402
from swarm.env.checks import EnvError, EnvTypeError  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
CASE2 = ROOT / "scenarios" / "case2.toml"
AGENTS = ["agent_2", "agent_3", "agent_4", "agent_5"]


def one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text, text
    return text


def raises(kind: type, pattern: str, fn, *args, **kwargs) -> str:
    with pytest.raises(kind) as err:
        fn(*args, **kwargs)
    assert isinstance(err.value, EnvError) and isinstance(err.value, swarm.UsageError)
    text = one_line(err)
    assert re.search(pattern, text), text
    return text


def started(**kwargs) -> tuple[SwarmEnv, dict]:
    env = SwarmEnv(CASE2, duration=0.5, **kwargs)
    obs, _ = env.reset(seed=0)
    return env, obs


# -- actions ------------------------------------------------------------------------------------
BAD_ACTIONS = [
    (math.nan, EnvError, r"actions\['agent_3'\] is nan: a turn rate must be finite"),
    (math.inf, EnvError, r"actions\['agent_3'\] is inf"),
    (-math.inf, EnvError, r"actions\['agent_3'\] is -inf"),
    (np.array([np.nan]), EnvError, r"actions\['agent_3'\] is nan"),
    (np.zeros((2, 2)), EnvError, r"actions\['agent_3'\] must be a number or an array of one, not .*shape \(2, 2\)"),
    (np.array([]), EnvError, r"actions\['agent_3'\] must be a number or an array of one, not .*shape \(0,\)"),
    ([1.0, 2.0], EnvError, r"actions\['agent_3'\] .*shape \(2,\)"),
    ("0.5", EnvTypeError, r"actions\['agent_3'\] must be a turn rate .*not str"),
    (None, EnvTypeError, r"actions\['agent_3'\] must be a turn rate .*not None"),
    (1 + 2j, EnvTypeError, r"actions\['agent_3'\] must be a turn rate .*not complex"),
    (np.array([1 + 0j]), EnvTypeError, r"actions\['agent_3'\] must hold a real number, not an array of complex128"),
    (True, EnvTypeError, r"actions\['agent_3'\] must be a turn rate .*not bool"),
    (np.array(["0.5"]), EnvTypeError, r"actions\['agent_3'\] must hold a real number"),
    ([[1.0], [2.0, 3.0]], EnvTypeError, r"actions\['agent_3'\] must be a turn rate"),
]


@pytest.mark.parametrize(("value", "kind", "pattern"), BAD_ACTIONS, ids=[repr(c[0])[:20] for c in BAD_ACTIONS])
def test_a_bad_action_is_an_error_naming_the_agent_and_nothing_moves(value, kind, pattern):
    env, obs = started()
    tick = env.engine_tick
    actions = dict.fromkeys(obs, 0.1)
    actions["agent_3"] = value
    raises(kind, pattern, env.step, actions)
    assert env.engine_tick == tick  # nothing was commanded: the step can be made again
    env.step(dict.fromkeys(obs, 0.1))
    assert env.engine_tick == tick + 1


@pytest.mark.parametrize(
    ("actions", "kind", "pattern"),
    [
        ([0.1, 0.1, 0.1, 0.1], EnvTypeError, r"actions must be a dict of agent name -> turn rate, not list"),
        (np.zeros(4), EnvTypeError, r"actions must be a dict .*not ndarray"),
        (None, EnvTypeError, r"actions must be a dict .*not None"),
        (0.5, EnvTypeError, r"actions must be a dict .*not float"),
        ({"agent_99": 0.1}, EnvError, r"actions: unknown agent 'agent_99' \(this environment's agents: agent_2, "),
        ({2: 0.1}, EnvError, r"actions: unknown agent 2 "),
    ],
)
def test_bad_actions_arguments_are_errors_naming_them(actions, kind, pattern):
    env, _ = started()
    raises(kind, pattern, env.step, actions)


def test_out_of_range_actions_saturate_and_never_poison_the_episode():
    env, obs = started()
    limit = math.pi / 0.01  # case 2's followers have no max_turn_rate: pi / dt
    assert env.action_space("agent_2").high.tolist() == [np.float32(limit)]
    sign = 1.0
    while env.agents:
        obs, rew, *_ = env.step({a: sign * 1e308 for a in env.agents})
        sign = -sign
        assert all(np.isfinite(o).all() for o in obs.values())
        assert all(math.isfinite(r) for r in rew.values())
    u = env.result().u[:-1, 1:5]
    assert set(np.abs(u).ravel().tolist()) == {limit}


def test_missing_agents_hold_their_last_command():
    env, obs = started()
    env.step({"agent_2": 0.3, "agent_3": -0.2, "agent_4": 0.0, "agent_5": 0.0})
    env.step({"agent_2": 0.5})  # the others: their last command held
    u = env.result().u
    assert u[1, 1:3].tolist() == [0.5, -0.2]


# -- the constructor and reset -------------------------------------------------------------------
def bad_dt():
    s = load_scenario(CASE2)
    return s.model_copy(update={"run": s.run.model_copy(update={"dt": math.nan})})


BAD_ARGUMENTS = [
    ({"duration": math.nan}, EnvError, r"duration must be a finite number of seconds > 0, not nan"),
    ({"duration": -1}, EnvError, r"duration must be a finite number of seconds > 0, not -1"),
    ({"duration": 0}, EnvError, r"duration must be a finite number of seconds > 0, not 0"),
    ({"duration": math.inf}, EnvError, r"duration must be a finite number of seconds > 0, not inf"),
    ({"duration": 0.001}, EnvError, r"duration 0.001 s is shorter than one tick \(run.dt = 0.01 s\)"),
    ({"duration": 1e12}, EnvError, r"duration 1e\+12 s is .* more than the recording limit"),
    ({"duration": "10"}, EnvTypeError, r"duration must be a real number, not str '10'"),
    ({"k_nearest": -1}, EnvError, r"k_nearest must be an int >= 0, not -1"),
    ({"k_nearest": 2.5}, EnvTypeError, r"k_nearest must be an int >= 0, not float 2.5"),
    ({"k_nearest": "3"}, EnvTypeError, r"k_nearest must be an int >= 0, not str '3'"),
    ({"k_nearest": True}, EnvTypeError, r"k_nearest must be an int >= 0, not bool True"),
    ({"k_nearest": None}, EnvTypeError, r"k_nearest must be an int >= 0, not None"),
    ({"position_jitter": -1.0}, EnvError, r"position_jitter must be a finite number >= 0, not -1.0"),
    ({"heading_jitter": math.nan}, EnvError, r"heading_jitter must be a finite number >= 0, not nan"),
    ({"reward": 3}, EnvTypeError, r"reward must be a function \(view, agent id\) -> float, not 3"),
    ({"agents": "some"}, EnvError, r"agents must be 'followers' or 'all', not 'some'"),
    ({"scenario": 42}, EnvTypeError, r"scenario must be a Scenario or a file path, not int"),
    ({"scenario": bad_dt}, EnvError, r"scenario run.dt must be a finite number of seconds > 0, not nan"),
]


def case_id(kwargs: dict) -> str:
    """A test id the same in every xdist worker (a function's name, not its address)."""
    return ",".join(f"{k}={getattr(v, '__name__', repr(v))}" for k, v in kwargs.items())


@pytest.mark.parametrize(("kwargs", "kind", "pattern"), BAD_ARGUMENTS, ids=[case_id(c[0]) for c in BAD_ARGUMENTS])
def test_a_bad_constructor_argument_is_an_error_naming_it(kwargs, kind, pattern):
    kwargs = dict(kwargs)
    scenario = kwargs.pop("scenario", CASE2)
    raises(kind, pattern, SwarmEnv, scenario() if callable(scenario) else scenario, **kwargs)


@pytest.mark.parametrize(
    ("seed", "kind", "pattern"),
    [
        ("1", EnvTypeError, r"seed must be an int or None, not str '1'"),
        (1.5, EnvTypeError, r"seed must be an int or None, not float 1.5"),
        (True, EnvTypeError, r"seed must be an int or None, not bool True"),
        (-1, EnvError, r"seed must be in 0 .. 2\*\*63 - 1, not -1"),
        (2**63, EnvError, r"seed must be in 0 .. 2\*\*63 - 1, not 9223372036854775808"),
    ],
)
def test_a_bad_seed_is_an_error_naming_it(seed, kind, pattern):
    raises(kind, pattern, SwarmEnv(CASE2, duration=0.1).reset, seed=seed)


def test_k_nearest_zero_is_the_out_block_only_and_numpy_ints_are_fine():
    env = SwarmEnv(CASE2, duration=0.1, k_nearest=np.int64(0))
    obs, _ = env.reset(seed=np.int64(1))
    assert {o.shape for o in obs.values()} == {(18,)}


@pytest.mark.slow
def test_parallel_api_test_still_passes(capsys):
    parallel_api_test(SwarmEnv(CASE2, duration=1.0, k_nearest=0), num_cycles=120)
    assert "Passed Parallel API test" in capsys.readouterr().out
