"""`SwarmEnv`: a PettingZoo `ParallelEnv` over the in-process engine (docs/guides/learning.md).

One tick of the run is one `step`, driven exactly as `swarm sim` (swarm/offline/sim.py)
drives `swarm.world.engine.Engine`: faults due -> frames -> commands -> record ->
integrate. Every agent keeps its `AgentBrain`: it chooses its out-neighbour and builds the
`Observation` a law would be given; for an agent the environment controls, the brain's
law is a stand-in that keeps that observation, and the action given to `step` is the
turn rate (saturated at max_turn_rate, as the brain does with a law's answer, or at
pi / dt for an agent without one; bad actions are errors: swarm/env/checks.py). So a
policy acting here on `observation_array`s produces the same run as `policy_law(policy)`
under `swarm sim`, to the bit (while its answers stay within pi / dt), and `swarm up
--clock lockstep` equals `swarm sim`.

Agents: "agent_<id>" for each controlled agent of the scenario (its followers, or all its
agents with agents="all"); the others run the scenario's laws. A scripted kill ends an
agent (terminated), a freeze too (truncated); a restart or a thaw brings it back as a new
agent "agent_<id>#<n>" (PettingZoo never revives an agent), all of them in
`possible_agents` from the start. The end of the run truncates everyone.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv  # type: ignore[import-untyped]  # pettingzoo ships no py.typed

from swarm.agents.brain import AgentBrain, Decision
from swarm.api.runs import Results, in_memory
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.observation import Observation
from swarm.contracts.orbits import expected_radius, roots
from swarm.contracts.scenario import Scenario, load_scenario
from swarm.contracts.vocabulary import EventKind
from swarm.env import checks
from swarm.env.observation import K_NEAREST, observation_array, size
from swarm.world.core import ACTIVE
from swarm.world.engine import Engine

PROCESS_RETURNS = ("restart", "thaw")  # scripted faults that bring an agent back: a new env agent


class WorldView(NamedTuple):
    """Ground truth after a step, for a reward (arrays in scenario order, column k of agent
    id ids[k], `column[id]` = k). Read-only: the engine's own arrays."""

    tick: int  # the tick just reached
    time: float  # its simulated time (s)
    ids: np.ndarray
    column: dict[int, int]
    x: np.ndarray  # m
    y: np.ndarray
    heading: np.ndarray  # rad
    speed: np.ndarray  # m/s
    u: np.ndarray  # turn rates integrated over the step (rad/s)
    alive: np.ndarray  # bool: controlled by a live agent
    out: np.ndarray  # chosen out-neighbour id, -1 none
    is_leader: np.ndarray  # bool
    orbit_radius: np.ndarray  # leaders' R (m), NaN for followers
    direction: np.ndarray  # leaders' +1 ccw / -1 cw, 0 for followers
    target: tuple[float, float]
    root: dict[int, int | None]  # the live leader at the end of each live agent's out-path, None: none


Reward = Callable[[WorldView, int], float]  # (view, agent id) -> reward of that agent for the step


def radial_rate_reward(rate_weight: float = 1.0) -> Reward:
    """The default reward: minus the agent's relative radial error and (weighted) relative
    angular-rate error, each capped at 1, so in [-(1 + rate_weight), 0]:

        -( min(|r_i - R_i| / R_i, 1) + rate_weight * min(|w_i - w| / |w|, 1) )

    r_i: distance to the target; w_i: angular rate about it, (r x v) / r^2; w = d v_L / R_L
    and R_i = v_i / |w| from the leader L the agent is rooted at now (itself for a leader;
    d its direction), the paper's circumnavigation (Theorem 1). An agent rooted at no live
    leader gets the worst, -(1 + rate_weight)."""

    def reward(view: WorldView, agent: int) -> float:
        root = view.root.get(agent)
        if root is None:
            return -(1.0 + rate_weight)
        k, c = view.column[agent], view.column[root]
        v, v_l, r_l = float(view.speed[k]), float(view.speed[c]), float(view.orbit_radius[c])
        omega = float(view.direction[c]) * v_l / r_l
        big_r = expected_radius(v, v_l, r_l)
        rx, ry = float(view.x[k]) - view.target[0], float(view.y[k]) - view.target[1]
        r2 = rx * rx + ry * ry
        g = float(view.heading[k])
        rate = (rx * v * math.sin(g) - ry * v * math.cos(g)) / r2 if r2 > 0 else 0.0
        radial = min(abs(math.sqrt(r2) - big_r) / big_r, 1.0)
        return -(radial + rate_weight * min(abs(rate - omega) / abs(omega), 1.0))

    return reward


def base_scenario(scenario: Any) -> Scenario:
    """A Scenario, or one loaded from a scenario file (its errors name the file and field)."""
    if isinstance(scenario, Scenario):
        return scenario
    if not isinstance(scenario, str | Path):
        raise checks.EnvTypeError(f"scenario must be a Scenario or a file path, not {type(scenario).__name__}")
    return load_scenario(scenario)


def agent_name(aid: int, life: int = 0) -> str:
    """The PettingZoo name of agent `aid` in its `life`-th stay in the world (0: from the start)."""
    return f"agent_{aid}" if life == 0 else f"agent_{aid}#{life}"


def agent_id(name: str) -> int:
    """The scenario's agent id of a PettingZoo name."""
    return int(name.removeprefix("agent_").partition("#")[0])


class SwarmEnv(ParallelEnv[str, np.ndarray, np.ndarray]):
    """A scenario as a PettingZoo ParallelEnv: one step per tick, observations
    `observation_array`s (swarm/env/observation.py), actions turn rates (rad/s)."""

    metadata = {"name": "swarm_v0", "render_modes": []}

    def __init__(
        self,
        scenario: Scenario | str | Path,
        *,
        agents: Literal["followers", "all"] = "followers",
        k_nearest: int = K_NEAREST,
        duration: float | None = None,
        reward: Reward | None = None,
        position_jitter: float = 0.0,
        heading_jitter: float = 0.0,
    ):
        """scenario: a Scenario or a scenario file; agents: which agents the environment
        controls ("followers", or "all": leaders too); k_nearest: contacts in an
        observation; duration: simulated seconds of an episode (default: the scenario's);
        reward: (view, agent id) -> float (default `radial_rate_reward()`);
        position_jitter (m), heading_jitter (rad): each episode moves every agent's start
        by a uniform draw in +-that, from the environment's seeded generator."""
        self.base = base_scenario(scenario)
        if agents not in ("followers", "all"):
            raise checks.EnvError(f"agents must be 'followers' or 'all', not {agents!r}")
        self.k = checks.k_nearest(k_nearest)
        self.controlled = [a.id for a in self.base.agents if agents == "all" or a.role == "follower"]
        dt = checks.run_dt(self.base.run.dt)
        ticks = checks.duration_ticks(duration, dt, len(self.base.agents))
        self.ticks = ticks if ticks is not None else self.base.run.ticks
        if reward is not None and not callable(reward):
            raise checks.EnvTypeError(f"reward must be a function (view, agent id) -> float, not {reward!r}")
        self.reward_fn = reward if reward is not None else radial_rate_reward()
        self.position_jitter = checks.jitter(position_jitter, "position_jitter")
        self.heading_jitter = checks.jitter(heading_jitter, "heading_jitter")
        lives = {  # its stays in the world: one, and one per scripted return within the episode
            aid: 1
            + sum(
                f.kind in PROCESS_RETURNS and f.agent == aid and round(f.at / dt) < self.ticks for f in self.base.faults
            )
            for aid in self.controlled
        }
        self.possible_agents = [agent_name(aid, n) for aid in self.controlled for n in range(lives[aid])]
        box = spaces.Box(-np.inf, np.inf, shape=(size(self.k),), dtype=np.float32)
        self._obs_spaces = {name: box for name in self.possible_agents}
        self._act_spaces = {}
        self.limits: dict[int, float] = {}  # controlled agent -> the largest turn rate an action gives
        for a in self.base.agents:
            if a.id in lives:
                lim = self.limits[a.id] = checks.action_limit(a.max_turn_rate, dt)
                act = spaces.Box(-lim, lim, shape=(1,), dtype=np.float32)
                for n in range(lives[a.id]):
                    self._act_spaces[agent_name(a.id, n)] = act
        self.agents: list[str] = []
        self.render_mode = None
        self._rng: np.random.Generator | None = None
        self._seed: int | None = None
        self.engine: Engine | None = None

    # -- spaces ----------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self._act_spaces[agent]

    # -- episodes --------------------------------------------------------------------------
    def _episode_scenario(self) -> Scenario:
        s = self.base
        if self._seed is not None:
            s = s.model_copy(update={"run": s.run.model_copy(update={"seed": self._seed})})
        if self.position_jitter > 0 or self.heading_jitter > 0:
            assert self._rng is not None
            moved = []
            for a in s.agents:
                p, h = self.position_jitter, self.heading_jitter
                dx, dy, dh = self._rng.uniform(-p, p), self._rng.uniform(-p, p), self._rng.uniform(-h, h)
                moved.append(a.model_copy(update={"x": a.x + dx, "y": a.y + dy, "heading": a.heading + dh}))
            s = s.model_copy(update={"agents": moved})
        return s

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """A new episode. seed: seeds the environment's generator (start jitter) and is the
        run's seed (the fault plan's draws: noise, loss); without it the generator goes on
        (from the scenario's run.seed at first) and the run's seed stays. options: unused."""
        seed = checks.seed(seed)
        if seed is not None:
            self._seed = seed
            self._rng = np.random.default_rng(seed)
            for n, name in enumerate(self.possible_agents):
                self._act_spaces[name].seed(seed + n)
        elif self._rng is None:
            self._rng = np.random.default_rng(self.base.run.seed)
        self.scenario = s = self._episode_scenario()
        self.engine = Engine(s, self.ticks)
        self.life = dict.fromkeys(self.controlled, 0)  # controlled agent -> its stays so far - 1
        self.brains = {a.id: self._brain(a.id) for a in s.agents}
        self.frozen: set[int] = set()
        self.ended_by: dict[int, str] = {}  # controlled agent -> "terminated" | "truncated", last drop
        self.last_obs: dict[int, np.ndarray] = {}
        self.pending: list[tuple[int, Decision | Exception, Observation | None]] = []
        self.agents = []
        self._done = False
        obs, _, _ = self._begin_tick()
        return obs, {name: self._info(name) for name in self.agents}

    def _brain(self, aid: int) -> AgentBrain:
        b = AgentBrain(BrainConf.from_scenario(self.scenario, aid))
        if aid in self.life:
            b.law = self._keep  # the observation is kept; the action decides
        return b

    def _keep(self, obs: Observation) -> float:
        self._kept = obs
        return 0.0

    def _live(self) -> list[str]:
        assert self.engine is not None
        core = self.engine.core
        return [agent_name(aid, self.life[aid]) for aid in self.controlled if core.state[core.index[aid]] == ACTIVE]

    def _begin_tick(self) -> tuple[dict[str, np.ndarray], set[str], set[str]]:
        """Faults due, frames, each agent's decision (controlled ones: their observation).
        Returns the observations of the live agents and which agents ended and came."""
        e = self.engine
        assert e is not None
        before = set(self.agents)
        for _, f in e.due():
            aid = f.agent
            if aid is None:
                continue
            if f.kind == "kill":
                self.frozen.discard(aid)
                if e.drop(aid, "fault: kill") is not None:
                    self.ended_by[aid] = "terminated"
            elif f.kind == "restart":
                self.frozen.discard(aid)
                if e.join(aid, "fault: restart", rejoin=True):
                    self._new_life(aid)
                    self.brains[aid] = self._brain(aid)
            elif f.kind == "freeze":
                if e.drop(aid, "fault: freeze") is not None:
                    self.frozen.add(aid)
                    self.ended_by[aid] = "truncated"
            elif f.kind == "thaw" and aid in self.frozen:
                self.frozen.discard(aid)
                if e.join(aid, "fault: thaw", rejoin=True):
                    self._new_life(aid)
        self.agents = self._live()
        self.pending = []
        fresh: set[int] = set()
        for aid, frame in e.frames().items():
            b = self.brains[aid]
            if aid in self.life:
                last_u = b.last_u
                d = b.decide(frame)
                b.last_u = last_u  # the stand-in's 0.0 is no command: the action sets it
                self.last_obs[aid] = observation_array(self._kept, self.k)
                self.pending.append((aid, d, self._kept))
                fresh.add(aid)
            else:
                try:
                    self.pending.append((aid, b.decide(frame), None))
                except Exception as err:  # its law raised: carried out in `step`, as swarm sim does
                    self.pending.append((aid, err, None))
        obs = {}
        for name in self.agents:
            aid = agent_id(name)
            if aid not in fresh:
                self.last_obs[aid] = self._stale(aid)
            obs[name] = self.last_obs[aid]
        after = set(self.agents)
        return obs, before - after, after - before

    def _new_life(self, aid: int) -> None:
        if aid in self.life:
            self.life[aid] += 1
            self.ended_by.pop(aid, None)
            if agent_name(aid, self.life[aid]) not in self._obs_spaces:  # more returns than scripted
                raise RuntimeError(f"agent {aid} came back more often than its scenario's faults say")

    def _stale(self, aid: int) -> np.ndarray:
        """No frame this tick: the last array, marked not fresh (zeros before the first)."""
        a = self.last_obs.get(aid)
        a = np.zeros(size(self.k), dtype=np.float32) if a is None else a.copy()
        a[0] = 0.0
        return a

    def _info(self, name: str) -> dict:
        aid = agent_id(name)
        return {"id": aid, "fresh": bool(self.last_obs.get(aid, [0.0])[0] == 1.0), "tick": self.engine_tick}

    @property
    def engine_tick(self) -> int:
        return -1 if self.engine is None else self.engine.tick

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Commands for this tick, then the world steps. `actions[name]`: a turn rate (a
        real number or an array of one), saturated at the agent's max_turn_rate (pi / dt
        without one); NaN or inf is an error naming the agent, as are a wrong type or shape
        and a name that is no agent of the environment (`possible_agents`); an action for an
        agent that has ended is ignored. A live agent without an action, or without a fresh
        frame this tick (`own.fresh` 0.0), holds its last command."""
        e = self.engine
        if e is None or self._done:
            raise RuntimeError("step() before reset() or after the episode ended")
        actions = checks.actions_dict(actions)
        checks.unknown_agents(actions, self.possible_agents)
        names = {agent_id(n): n for n in self.agents}
        given = {}  # controlled agent -> its saturated turn rate, every action checked before any is used
        for aid, n in names.items():
            if n in actions:
                given[aid] = checks.action(n, actions[n], self.limits[aid])
        k = e.tick
        for aid, d, _ in self.pending:
            if isinstance(d, Exception):
                cause = f"{type(d).__name__}: {d}"
                e.event(EventKind.CRASH, aid, f"its law raised: {cause}", cause=cause)
                e.drop(aid, "its law raised (crash)")
                self.frozen.discard(aid)
                continue
            u = d.u
            if aid in self.life:
                if aid not in given:
                    continue
                u = self.brains[aid].last_u = given[aid]
            e.command(aid, k, u, d.out, d.hops, d.follow)
        e.end_tick()
        view = self.view()
        live = list(self.agents)
        rewards = {n: float(self.reward_fn(view, agent_id(n))) for n in live}
        if e.tick >= self.ticks:
            e.close()
            self._done = True
            obs = {n: self._stale(agent_id(n)) for n in live}
            terms = dict.fromkeys(live, False)
            truncs = dict.fromkeys(live, True)
            self.agents = []
            return obs, rewards, terms, truncs, {n: self._info(n) for n in live}
        obs, ended, added = self._begin_tick()
        for n in ended:
            obs[n] = self._stale(agent_id(n))
        keys = live + sorted(added)
        for n in added:
            rewards[n] = 0.0
        terms = {n: n in ended and self.ended_by.get(agent_id(n)) == "terminated" for n in keys}
        truncs = {n: n in ended and not terms[n] for n in keys}
        return obs, rewards, terms, truncs, {n: self._info(n) for n in keys}

    # -- what the environment shows ---------------------------------------------------------
    @functools.cached_property
    def _static(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.base
        radius = np.array([a.orbit_radius if a.role == "leader" else np.nan for a in s.agents], dtype=float)
        direction = np.array([a.direction_sign if a.role == "leader" else 0 for a in s.agents], dtype=float)
        return radius, direction

    def view(self) -> WorldView:
        """Ground truth now (what a reward is given)."""
        e = self.engine
        assert e is not None
        c = e.core
        alive = c.alive_mask()
        live_leaders = {int(i) for i, lead, a in zip(c.ids, c.is_leader, alive) if lead and a}
        out = {int(i): (None if o < 0 else int(o)) for i, o, a in zip(c.ids, e.out, alive) if a}
        radius, direction = self._static
        return WorldView(
            c.tick, c.time, c.ids, c.index, c.x, c.y, c.heading, c.speed, c.u, alive, e.out,
            c.is_leader, radius, direction, c.target, roots(out, live_leaders),
        )  # fmt: skip

    def result(self) -> Results:
        """The episode so far as `swarm sim`'s results: a `swarm.Results` kept in memory, what
        `swarm.simulate` returns: the trajectory's arrays as attributes (`res.x`,
        `res.agent(3)`), the summary with attribute access (`res.summary.converged`,
        `res.summary.agents[3].radial_error`; `res.summary.engine` is "env"); `res.save(dir)`
        writes its trajectory.npz and summary.json, `res.plot(dir)` its figures."""
        e = self.engine
        if e is None:
            raise RuntimeError("result() before reset()")
        run = e.result(
            {"engine": "env", "rejected_commands": e.core.rejected, "lost_frames": e.fault_plan.lost_sense,
             "lost_commands": e.fault_plan.lost_cmd},
            {str(aid): b.figures() for aid, b in self.brains.items()},
        )  # fmt: skip
        return in_memory(run)  # (its arrays: the rows written so far, which later steps leave as they are)

    def render(self) -> None:
        return None

    def close(self) -> None:
        self.engine = None
