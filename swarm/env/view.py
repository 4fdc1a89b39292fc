"""`VectorSwarmView`: the PettingZoo `ParallelEnv` view of a one-swarm `VectorSwarmEnv`
(docs/guides/learning.md#vector).

PettingZoo's ParallelEnv is one environment whose agents act by name; the vector env's
point is B of them stepped at once. A view of swarm b of B could not step alone (the
other swarms step with it), so the view is of a vector env of one swarm (num_envs = 1):
learning code that speaks PettingZoo runs on the same arrays, and the same episodes, as
code that speaks arrays. For B swarms in PettingZoo's terms use B `SwarmEnv`s, or the
arrays themselves.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv  # type: ignore[import-untyped]  # pettingzoo ships no py.typed

from swarm.env import checks
from swarm.env.observation import size
from swarm.env.vector import VectorSwarmEnv


class VectorSwarmView(ParallelEnv[str, np.ndarray, np.ndarray]):
    """A one-swarm VectorSwarmEnv as a PettingZoo ParallelEnv: agents "agent_<id>",
    observations the vector env's arrays, actions turn rates (checked and saturated as
    SwarmEnv's). An agent that ends (kill, freeze) leaves `agents`; the end of the episode
    truncates everyone. A live agent left out of the actions keeps its last turn rate."""

    metadata = {"name": "swarm_vector_v0", "render_modes": []}

    def __init__(self, env: VectorSwarmEnv):
        if not isinstance(env, VectorSwarmEnv):
            raise checks.EnvTypeError(f"env must be a VectorSwarmEnv, not {type(env).__name__}")
        if env.num_envs != 1:
            raise checks.EnvError(
                f"a PettingZoo view is of a vector env of one swarm, not {env.num_envs}: its swarms step together"
            )
        self.env = env
        self.possible_agents = list(env.possible_agents)
        self.agents: list[str] = []
        self.render_mode = None
        box = spaces.Box(-np.inf, np.inf, shape=(size(env.k),), dtype=np.float32)
        self._obs_spaces = dict.fromkeys(self.possible_agents, box)
        self._act_spaces = {
            n: spaces.Box(-lim, lim, shape=(1,), dtype=np.float32) for n, lim in zip(self.possible_agents, env.limits)
        }
        self._next: tuple[np.ndarray, dict] | None = None  # the episode the vector env began when the last ended
        self._last = np.zeros((1, len(self.possible_agents)))

    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """A new episode: with a seed, the vector env's reset(seed); without one, the episode
        it began when the last one ended (its generator goes on, as SwarmEnv.reset() does)."""
        seed = checks.seed(seed)
        if seed is not None:
            for n, name in enumerate(self.possible_agents):
                self._act_spaces[name].seed(seed + n)
        if seed is None and self._next is not None:
            obs, info = self._next
        else:
            obs, info = self.env.reset(seed=seed)
        self._next = None
        self._last = np.zeros((1, len(self.possible_agents)))
        self.agents = [n for n, live in zip(self.possible_agents, info["live"][0]) if live]
        return self._dicts(obs, info)[0], {n: {"tick": info["tick"]} for n in self.agents}

    def _dicts(self, obs: np.ndarray, info: dict) -> tuple[dict, list[str]]:
        names = [n for a, n in enumerate(self.possible_agents) if n in self.agents]
        col = {n: a for a, n in enumerate(self.possible_agents)}
        return {n: obs[0, col[n]] for n in names}, names

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if not self.agents:
            raise RuntimeError("step() before reset() or after the episode ended")
        actions = checks.actions_dict(actions)
        checks.unknown_agents(actions, self.possible_agents)
        u = self._last.copy()
        for a, n in enumerate(self.possible_agents):
            if n in actions and n in self.agents:
                u[0, a] = checks.action(n, actions[n], float(self.env.limits[a]))
        self._last = u
        obs, rew, term, trunc, info = self.env.step(u)
        before = list(self.agents)
        col = {n: a for a, n in enumerate(self.possible_agents)}
        if info["done"][0]:
            self._next = (obs, {k: v for k, v in info.items() if k != "final_observation"})
            obs = info["final_observation"]
            self.agents = []
        else:
            self.agents = [n for n in before if info["live"][0, col[n]]]
        out = (
            {n: obs[0, col[n]] for n in before},
            {n: float(rew[0, col[n]]) for n in before},
            {n: bool(term[0, col[n]]) for n in before},
            {n: bool(trunc[0, col[n]]) for n in before},
            {n: {"tick": info["tick"]} for n in before},
        )
        return out

    def render(self) -> None:
        return None

    def close(self) -> None:
        self.env.close()
