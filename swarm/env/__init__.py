"""Learning: a scenario as a PettingZoo `ParallelEnv`, and a policy run as a law
(docs/guides/learning.md).

    from swarm.env import SwarmEnv, policy_law
    env = SwarmEnv("scenarios/case2.toml")          # needs the `env` extra: pettingzoo, gymnasium
    obs, infos = env.reset(seed=0)
    law = policy_law(lambda a: 0.5 * a[16])          # obs array -> turn rate, as a law

`VectorSwarmEnv` (swarm/env/vector.py) steps B swarms at once as arrays over the batch
engine, each equal to `SwarmEnv` to the bit; `VectorSwarmView` is its PettingZoo view.

`policy_law` and the observation layout (swarm/env/observation.py) need only numpy: agent
processes import them when they run such a law. `SwarmEnv` (swarm/env/parallel.py) imports
pettingzoo and gymnasium when it is first asked for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from swarm.env.observation import FIELDS, K_NEAREST, fields, index, observation_array, policy_law, size, turn_rate

if TYPE_CHECKING:
    from swarm.env.checks import EnvError, EnvTypeError
    from swarm.env.parallel import SwarmEnv, WorldView, agent_id, agent_name, radial_rate_reward
    from swarm.env.vector import VectorSwarmEnv, vector_actions
    from swarm.env.view import VectorSwarmView

__all__ = [
    "FIELDS",
    "K_NEAREST",
    "EnvError",
    "EnvTypeError",
    "SwarmEnv",
    "VectorSwarmEnv",
    "VectorSwarmView",
    "WorldView",
    "agent_id",
    "agent_name",
    "fields",
    "index",
    "observation_array",
    "policy_law",
    "radial_rate_reward",
    "size",
    "turn_rate",
    "vector_actions",
]
_PARALLEL = {"SwarmEnv", "WorldView", "agent_id", "agent_name", "radial_rate_reward"}
_LAZY = {"EnvError": "checks", "EnvTypeError": "checks", "VectorSwarmEnv": "vector", "vector_actions": "vector"}
_LAZY["VectorSwarmView"] = "view"  # needs the `env` extra, as SwarmEnv


def __getattr__(name: str) -> Any:
    if name in _PARALLEL:
        # lazy: pettingzoo and gymnasium are an optional extra; a policy law's agent process needs neither
        from swarm.env import parallel

        return getattr(parallel, name)
    if _LAZY.get(name) == "checks":
        # lazy: the checks import the scenario's limits (pydantic), which a policy law's agent process does without
        from swarm.env import checks

        return getattr(checks, name)
    if _LAZY.get(name) == "vector":
        # lazy: the batch engine, only for who asks for the vector env
        from swarm.env import vector

        return getattr(vector, name)
    if _LAZY.get(name) == "view":
        # lazy: pettingzoo and gymnasium, as for SwarmEnv
        from swarm.env import view

        return getattr(view, name)
    raise AttributeError(f"module 'swarm.env' has no attribute {name!r}")
