"""`VectorSwarmEnv`: B independent swarms of one scenario stepped as arrays over the batch
engine (docs/guides/learning.md#vector).

    from swarm.env import VectorSwarmEnv
    env = VectorSwarmEnv("scenarios/case2.toml", num_envs=256, seed=0)   # swarm b: seed 0 + b
    obs, info = env.reset()                       # obs (B, A, F) float32
    obs, rewards, terminated, truncated, info = env.step(actions)   # actions (B, A) rad/s
    # rewards (B, A) float64, terminated / truncated (B, A) bool, info["done"] (B,) bool

Constructor: `VectorSwarmEnv(scenario, num_envs=1, *, seed=0, agents="followers",
k_nearest=6, duration=None, rate_weight=1.0, position_jitter=0.0, heading_jitter=0.0)`;
scenario a Scenario, a scenario file, or a number of agents n: `random_scenario(n)`, the
random swarm of n agents `swarm study swarms` makes (seed 0: 2 leaders, n - 2 followers);
A = the agents it controls (`possible_agents`, in scenario order: the followers, or every
agent with agents="all"). `step(actions)` takes a real (B, A) array. So
`VectorSwarmEnv(10, 4096, seed=0, agents="all")` is 4096 swarms of 10 agents, all controlled.

The same episode as `SwarmEnv`, swarm by swarm and to the bit: swarm b of a vector env
seeded s is `SwarmEnv` reset with seed s + b (tests/pure/test_env_vector.py), with the
same observation arrays, the default reward (`radial_rate_reward(rate_weight)`),
saturation of actions and scripted dropouts. How, tick by tick (SwarmEnv's order):
scripted dropouts due -> every swarm's frames as arrays (world/batch.py, with who is
present) -> every agent's brain at once (agents/batch.py: out-neighbours, hop counts, the
uncontrolled agents' turn rates) -> observations of the controlled agents, built from the
same numbers `observation_array` reads -> `step`: actions replace the controlled agents'
turn rates -> the world steps -> rewards.

What it runs: the scenarios the batch engine runs (swarm/offline/batch.py `refusal`: the
built-in laws), and of scripted faults the dropouts: `kill` (the agent is terminated) and
`freeze` (truncated), leaving the world or coasting as run.on_dropout says. It refuses
(EnvError, naming the fault) what would bring an agent back (`restart`, `thaw`: a vector
env's agents are fixed columns) and network faults (`loss`, `delay`, `partition`, `noise`:
per-message draws that the per-agent engine makes), and a [safety] table: `SwarmEnv` runs
all of them. Every swarm has the same episode length, so all of them end at the same step:
`info["done"]` is per swarm, and a swarm that is done is reset in the same call (its first
observation returned, its last in `info["final_observation"]`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from swarm.agents import batch_maths as bm
from swarm.agents.batch import BatchBrains
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.orbits import wrap_array as wrap
from swarm.contracts.scenario import Scenario, load_scenario, parse_scenario
from swarm.env import checks
from swarm.env.observation import K_NEAREST, size, turn_rate
from swarm.offline.batch import refusal
from swarm.world.batch import BatchFrames, BatchWorld, sensing_matrices

DROPOUTS = ("kill", "freeze")  # the scripted faults a vector env carries out


def _take(a: np.ndarray, j: np.ndarray) -> np.ndarray:
    """a[b, j[b, ...]] for (B, N) a and column indices j (B, ...) (clipped: mask the -1s)."""
    rows = (np.arange(a.shape[0]) * a.shape[1]).reshape((-1,) + (1,) * (j.ndim - 1))
    return np.take(a.reshape(-1), np.maximum(j, 0) + rows)


class _World(BatchWorld):
    """BatchWorld with agents that leave: `present` (sensed by the others: active or
    coasting) and `active` (in the world and controlled)."""

    def __init__(self, scenarios: list[Scenario]):
        super().__init__(scenarios)
        self.present = np.ones(self.x.shape, dtype=bool)
        self.active = np.ones(self.x.shape, dtype=bool)
        self.everyone = True  # nobody has left yet: the batch engine's own frames

    def frames(self) -> _Frames:
        return _Frames(self)


class _Frames(BatchFrames):
    """This tick's frames with presence; every member's sensing matrices made once."""

    def __init__(self, w: _World):
        super().__init__(w)
        self.world = w
        s, rng = sensing_matrices(w.x, w.y, w.heading, w.sense_range, w.fov, w.fov_on)
        if not w.everyone:
            s &= w.present[:, None, :] & w.present[:, :, None]
        self.sensed, self.range = s, rng

    def matrices(self, m: np.ndarray) -> Any:
        return self.sensed[m], self.range[m]

    def sensed_pairs(self, j: np.ndarray, b: Any = slice(None)) -> np.ndarray:
        s = super().sensed_pairs(j, b)
        w = self.world
        return s if w.everyone else s & _take(w.present[b], j)


def random_scenario(n: int = 10, seed: int = 0, selection: str = "sticky", duration: float = 10_000.0) -> Scenario:
    """`swarm study swarms`' random swarm `seed` of n agents (swarm.study.swarms.random_swarm
    with SwarmSetting(n=n, selection=selection), made here again: swarm.env sits below the
    study): 2 leaders (ids 1, 2) orbiting ccw at omega = 1 rad/s, uniform in a 120 m square,
    speeds 15-40 m/s, unlimited sensing, dt 0.05 s, gains 1.0 / 0.5."""
    leaders = 2
    rng = np.random.default_rng([seed, n, leaders])
    xy = rng.uniform(-60.0, 60.0, size=(n, 2))
    heading = rng.uniform(-math.pi, math.pi, size=n)
    speed = rng.uniform(15.0, 40.0, size=n)
    agents = []
    for k in range(n):
        a: dict[str, Any] = {"id": k + 1, "role": "leader" if k < leaders else "follower", "x": float(xy[k, 0])}
        a.update(y=float(xy[k, 1]), heading=float(heading[k]), speed=float(speed[k]))
        if k < leaders:
            a["orbit_radius"] = float(speed[k])
        agents.append(a)
    data = {
        "name": f"study-{seed}",
        "run": {"dt": 0.05, "duration": duration, "seed": seed},
        "gains": {"c1": 1.0, "c2": 0.5},
        "sensing": {"selection": selection},
        "agents": agents,
    }
    return parse_scenario(data, f"random swarm (seed {seed})")


class VectorSwarmEnv:
    """B swarms of one scenario as arrays: observations (B, A, F), actions (B, A)."""

    def __init__(
        self,
        scenario: Scenario | str | Path,
        num_envs: int = 1,
        *,
        seed: int | Sequence[int] = 0,
        agents: Literal["followers", "all"] = "followers",
        k_nearest: int = K_NEAREST,
        duration: float | None = None,
        rate_weight: float = 1.0,
        position_jitter: float = 0.0,
        heading_jitter: float = 0.0,
    ):
        """scenario: a Scenario, a scenario file or a number of agents (`random_scenario`); num_envs: B; seed: swarm b's
        is seed + b (or a sequence of B seeds): it seeds the swarm's start jitter, as
        SwarmEnv.reset(seed) does; agents, k_nearest, duration, position_jitter,
        heading_jitter: as SwarmEnv's; rate_weight: the default reward's
        (`radial_rate_reward(rate_weight)`, computed on arrays)."""
        if isinstance(scenario, int | np.integer) and not isinstance(scenario, bool):
            if scenario < 3:
                raise checks.EnvError(f"scenario: a random swarm needs 3 agents or more (2 leaders), not {scenario}")
            scenario = random_scenario(int(scenario))
        if not isinstance(scenario, Scenario) and not isinstance(scenario, str | Path):
            raise checks.EnvTypeError(
                f"scenario must be a Scenario, a file path or a number of agents, not {type(scenario).__name__}"
            )
        self.base = base = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer):
            raise checks.EnvTypeError(f"num_envs must be an int >= 1, not {type(num_envs).__name__} {num_envs!r}")
        if num_envs < 1:
            raise checks.EnvError(f"num_envs must be an int >= 1, not {num_envs}")
        self.num_envs = B = int(num_envs)
        if agents not in ("followers", "all"):
            raise checks.EnvError(f"agents must be 'followers' or 'all', not {agents!r}")
        self.k = checks.k_nearest(k_nearest)
        self.dt = dt = checks.run_dt(base.run.dt)
        n = len(base.agents)
        ticks = checks.duration_ticks(duration, dt, n * B)
        self.ticks = ticks if ticks is not None else base.run.ticks
        self.rate_weight = checks.real(rate_weight, "rate_weight")
        if not math.isfinite(self.rate_weight) or self.rate_weight < 0:
            raise checks.EnvError(f"rate_weight must be a finite number >= 0, not {self.rate_weight!r}")
        self.position_jitter = checks.jitter(position_jitter, "position_jitter")
        self.heading_jitter = checks.jitter(heading_jitter, "heading_jitter")
        why = refusal(base.model_copy(update={"faults": []}))
        if why is not None:
            raise checks.EnvError(f"VectorSwarmEnv cannot run {base.name or 'this scenario'}: {why}; SwarmEnv can")
        if base.safety is not None:
            raise checks.EnvError(
                f"VectorSwarmEnv cannot run {base.name or 'this scenario'}: it has a [safety] table; SwarmEnv can"
            )
        col = {a.id: k for k, a in enumerate(base.agents)}
        self.faults: dict[int, list[tuple[int, str]]] = {}  # tick -> (column, kind) due then
        for i, f in enumerate(base.faults):
            if f.kind not in DROPOUTS:
                raise checks.EnvError(
                    f"VectorSwarmEnv runs scripted dropouts (kill, freeze), not faults[{i}] = {f.kind!r}: "
                    "an agent brought back or a network fault needs SwarmEnv"
                )
            t = int(round(f.at / dt))
            if t < self.ticks and f.agent is not None:
                self.faults.setdefault(t, []).append((col[f.agent], f.kind))
        self.cols = np.array(
            [k for k, a in enumerate(base.agents) if agents == "all" or a.role == "follower"], dtype=np.int64
        )
        ctrl = [base.agents[k] for k in self.cols.tolist()]
        self.possible_agents = [f"agent_{a.id}" for a in ctrl]
        self.n_agents = len(ctrl)
        self.limits = np.array([checks.action_limit(a.max_turn_rate, dt) for a in ctrl], dtype=float)
        self.seeds = self._seeds(seed)
        self.rngs = [np.random.default_rng(s) for s in self.seeds]
        self.confs = [BrainConf.from_scenario(base, a.id) for a in base.agents]
        # the observation's constant fields and the reward's leaders, per column
        self.is_leader = np.array([a.role == "leader" for a in base.agents], dtype=bool)
        self.orbit = np.array([a.orbit_radius if a.role == "leader" else np.nan for a in base.agents], dtype=float)
        self.direction = np.array([a.direction_sign if a.role == "leader" else 0 for a in base.agents], dtype=float)
        self._own = np.array(
            [[1.0 if a.role == "leader" else 0.0, a.speed, a.max_turn_rate or 0.0] for a in ctrl], dtype=float
        )
        self.tick = 0
        self.world: _World | None = None

    # -- seeds and episodes ------------------------------------------------------------------
    def _seeds(self, seed: Any) -> list[int]:
        if isinstance(seed, Sequence) and not isinstance(seed, str | bytes):
            if len(seed) != self.num_envs:
                raise checks.EnvError(f"seed: {len(seed)} seeds for {self.num_envs} swarms")
            return [checks.seed(s, f"seed[{b}]") or 0 for b, s in enumerate(seed)]
        s = checks.seed(seed)
        if s is None:
            raise checks.EnvTypeError("seed must be an int or a sequence of num_envs ints, not None")
        if s + self.num_envs - 1 > 2**63 - 1:
            raise checks.EnvError(f"seed {s} + {self.num_envs - 1} swarms is past 2**63 - 1")
        return [s + b for b in range(self.num_envs)]

    def reset(self, seed: int | Sequence[int] | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """A new episode of every swarm. seed: as the constructor's (reseeds every swarm's
        generator); without it each swarm's generator goes on, as SwarmEnv.reset() does."""
        if seed is not None:
            self.seeds = self._seeds(seed)
            self.rngs = [np.random.default_rng(s) for s in self.seeds]
        self._start()
        return self.obs.astype(np.float32), self._info()

    def _start(self) -> None:
        base, B, n = self.base, self.num_envs, len(self.base.agents)
        w = self.world = _World([base] * B)
        p, h = self.position_jitter, self.heading_jitter
        if p > 0 or h > 0:  # SwarmEnv._episode_scenario's draws: per agent dx, dy, dh, uniform in +-p, +-p, +-h
            u = np.array([rng.random(3 * n) for rng in self.rngs]).reshape(B, n, 3)
            w.x = w.x + (-p + (p - -p) * u[..., 0])
            w.y = w.y + (-p + (p - -p) * u[..., 1])
            w.heading = w.heading + (-h + (h - -h) * u[..., 2])
        c = self.confs
        self.brains = BatchBrains(
            [[x.agent for x in c]] * B, [c[0].gains] * B, [c[0].sensing] * B, self.dt, c[0].n_agents
        )
        lead = self.brains.leaders  # leaders the policy steers: their brains' turn rates are replaced
        lead.given = np.isin(lead.i, self.cols)  # by the actions, so they plan no path (~0.2 s each)
        self.out = np.full((B, n), -1, dtype=np.int64)  # Engine.out, as columns
        self.live = np.ones((B, self.n_agents), dtype=bool)  # controlled agents in the world
        self.ended = np.zeros((B, self.n_agents), dtype=bool)  # ended at the last tick begun
        self.ended_terminated = np.zeros((B, self.n_agents), dtype=bool)
        self.obs = np.zeros((B, self.n_agents, size(self.k)))
        self.tick = 0
        self._begin_tick()

    # -- one tick ------------------------------------------------------------------------------
    def _begin_tick(self) -> None:
        """Dropouts due, frames, every brain's decision, the controlled agents' observations."""
        w = self.world
        assert w is not None
        self.ended = np.zeros_like(self.live)
        for k, kind in self.faults.get(self.tick, ()):
            if not w.active[0, k]:  # (every swarm has the same faults: the same agents are in)
                continue
            w.active[:, k] = False
            w.present[:, k] = self.base.run.on_dropout == "coast"
            w.everyone = False
            w.hops[:, k] = -1
            self.out[:, k] = -1
            a = np.flatnonzero(self.cols == k)
            if a.size:
                self.live[:, a] = False
                self.ended[:, a] = True
                self.ended_terminated[:, a] = kind == "kill"
        frames = w.frames()
        brains = self.brains
        last_u = brains.last_u.copy()  # what the controlled agents' observations say they commanded
        if brains.sticky is not None:
            brains.sticky.chosen = {}
        self.decision = d = brains.decide(self.tick, frames)
        brains.last_u[:, self.cols] = last_u[:, self.cols]  # the action sets it (step)
        fresh = self._observe(frames, d.out, last_u)
        if self.live.all():
            fresh[..., 0] = 1.0
            self.obs = fresh
        else:  # the agents that ended keep their last array, marked not fresh (SwarmEnv's _stale)
            self.obs = np.where(self.live[..., None], fresh, self.obs)
            self.obs[..., 0] = np.where(self.live, 1.0, 0.0)

    def _observe(self, frames: _Frames, out: np.ndarray, last_u: np.ndarray) -> np.ndarray:
        """`observation_array` of every controlled agent of every swarm (float64, cast later)."""
        w, C, k = self.world, self.cols, self.k
        assert w is not None
        B, A = self.num_envs, self.n_agents
        o = np.zeros((B, A, size(k)))
        g = w.heading[:, C]
        o[..., 1:4] = self._own
        o[..., 4] = last_u[:, C]
        o[..., 5], o[..., 6] = np.cos(g), np.sin(g)
        sensed = frames.sensed[:, C, :]
        rng = frames.range[:, C, :]
        o[..., 7] = sensed.sum(axis=-1)
        lead = np.flatnonzero(self.is_leader[C])
        if lead.size:  # leaders' target block, math's hypot and atan2 per element (as observation_array)
            lc = C[lead]
            tx, ty = frames.target(np.arange(B)[:, None], lc[None, :])
            o[:, lead, 8] = 1.0
            o[:, lead, 9] = bm.hypot(tx, ty)
            o[:, lead, 10] = wrap(bm.atan2(ty, tx) - g[:, lead])
            o[:, lead, 11] = self.orbit[lc]
            o[:, lead, 12] = self.direction[lc]
        # the out-neighbour: the frame's contact of it (range, bearing, heading, hops)
        j = out[:, C]
        has = j >= 0
        dx, dy = _take(w.x, j) - w.x[:, C], _take(w.y, j) - w.y[:, C]
        block = [np.hypot(dx, dy), np.arctan2(dy, dx), _take(w.heading, j), _take(frames.hops, j).astype(float)]
        chosen = {} if self.brains.sticky is None else self.brains.sticky.chosen
        if chosen:  # sticky followers stepped one by one: the contact they chose (a predicted one while coasting)
            pos = {int(c): a for a, c in enumerate(C.tolist())}
            for (b, i), c in chosen.items():
                a = pos.get(i)
                if a is not None and c is not None:
                    for f, v in zip(block, (c.range, c.bearing, c.heading, float(c.hops))):
                        f[b, a] = v
        rel = (1.0, block[0], wrap(block[1] - g), wrap(block[2] - g), block[3])
        for f, v in enumerate(rel):
            o[..., 13 + f] = np.where(has, v, 0.0)
        if k:  # the k nearest contacts, by range then id
            n = w.n
            r = np.where(sensed, rng, np.inf)
            if w.ids_sorted:  # columns in id order: a stable sort by range breaks ties by id
                order = np.argsort(r, axis=-1, kind="stable")[..., : min(k, n)]
            else:
                order = np.lexsort((np.broadcast_to(w.ids[:, None, :], r.shape), r), axis=-1)[..., : min(k, n)]
            rows = np.arange(B)[:, None, None]
            valid = np.take_along_axis(sensed, order, axis=-1)

            flat = order + rows * n

            def at(a: np.ndarray) -> np.ndarray:
                return np.take(a.reshape(-1), flat)

            cdx, cdy = at(w.x) - w.x[:, C, None], at(w.y) - w.y[:, C, None]
            fields = (
                1.0,
                np.take_along_axis(r, order, axis=-1),
                wrap(np.arctan2(cdy, cdx) - g[..., None]),
                wrap(at(w.heading) - g[..., None]),
                at(frames.hops).astype(float),
            )
            for f, v in enumerate(fields):
                o[..., 18 + f : 18 + 5 * order.shape[-1] : 5] = np.where(valid, v, 0.0)
        return o

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
        """actions: (B, A) turn rates (rad/s), saturated at each agent's limit (max_turn_rate,
        or pi / dt); NaN, inf, a wrong shape or type are errors naming the entry. Actions of
        agents that have ended are ignored. Returns observations (B, A, F) float32, rewards
        (B, A) float64 (0.0 for agents not in the world during the step), terminated and
        truncated (B, A) bool (True at the step an agent ends; the end of the episode
        truncates every live agent) and info: "live" (B, A) agents in the world now, "done"
        (B,) swarms whose episode ended at this step (then reset: the returned observations
        are the new episode's first, "final_observation" the last ones)."""
        w = self.world
        if w is None:
            raise RuntimeError("step() before reset()")
        u_act = checks.actions_array(actions, (self.num_envs, self.n_agents), self._name)
        u_act = np.minimum(self.limits, np.maximum(-self.limits, u_act))
        d, C = self.decision, self.cols
        u = d.u.copy()
        live_before = self.live.copy()
        u[:, C] = np.where(live_before, u_act, u[:, C])
        self.brains.last_u[:, C] = np.where(live_before, u_act, self.brains.last_u[:, C])
        # Engine.command for the active agents (the others have no frame, so no command)
        prev_u, prev_hops = w.u, w.hops
        ok = w.latch(u, d.hops)
        act = w.active
        if not w.everyone:
            w.u = np.where(act, w.u, prev_u)
            w.hops = np.where(act, w.hops, prev_hops)
        self.out = np.where(act & ok, d.out, self.out)  # a refused command changes nothing (Engine.command)
        # Engine.end_tick: coasting agents go straight on, the gone stay where they are
        if w.everyone:
            w.step()
        else:
            x, y, hd = w.x, w.y, w.heading
            w.step(np.where(act, w.u, 0.0), None)
            w.x, w.y, w.heading = (np.where(w.present, a, b) for a, b in ((w.x, x), (w.y, y), (w.heading, hd)))
        self.tick += 1
        rewards = np.where(live_before, self._rewards(), 0.0)
        B = self.num_envs
        if self.tick >= self.ticks:
            final = self.obs.copy()
            final[..., 0] = 0.0
            terminated = np.zeros_like(live_before)
            truncated = live_before
            self._start()
            info = self._info(done=np.ones(B, dtype=bool))
            info["final_observation"] = final.astype(np.float32)
            return self.obs.astype(np.float32), rewards, terminated, truncated, info
        self._begin_tick()
        terminated = self.ended & self.ended_terminated
        truncated = self.ended & ~self.ended_terminated
        return self.obs.astype(np.float32), rewards, terminated, truncated, self._info(done=np.zeros(B, dtype=bool))

    def _info(self, done: np.ndarray | None = None) -> dict:
        return {
            "live": self.live.copy(),
            "done": np.zeros(self.num_envs, dtype=bool) if done is None else done,
            "tick": self.tick,
        }

    def _name(self, b: int, a: int) -> str:
        return f"swarm {b}, {self.possible_agents[a]}"

    # -- the reward ----------------------------------------------------------------------------
    def _rewards(self) -> np.ndarray:
        """radial_rate_reward(rate_weight) of every controlled agent on the world now, with
        the arithmetic of swarm/env/parallel.py's, in the same order (the same bits)."""
        w, C, wt = self.world, self.cols, self.rate_weight
        assert w is not None
        alive = w.active
        lead = self.is_leader[None, :] & alive
        cur = np.broadcast_to(C, (self.num_envs, len(C))).copy()
        for _ in range(w.n + 1):  # orbits.roots: follow the out-neighbours to a live leader
            stop = (cur < 0) | _take(lead, cur)
            if stop.all():  # (every walk has ended: the rest of the loop would change nothing)
                break
            nxt = np.where(_take(alive, cur), _take(self.out, cur), -1)
            cur = np.where(stop, cur, nxt)
        root = np.where((cur >= 0) & _take(lead, cur), cur, -1)
        v, v_l = w.speed[:, C], _take(w.speed, root)
        r_l = self.orbit[np.maximum(root, 0)]
        omega = self.direction[np.maximum(root, 0)] * v_l / r_l
        big_r = v * r_l / v_l
        rx, ry = w.x[:, C] - w.target[:, :1], w.y[:, C] - w.target[:, 1:]
        r2 = rx * rx + ry * ry
        g = w.heading[:, C]
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.where(r2 > 0, (rx * v * np.sin(g) - ry * v * np.cos(g)) / r2, 0.0)
            radial = np.minimum(np.abs(np.sqrt(r2) - big_r) / big_r, 1.0)
            r = -(radial + wt * np.minimum(np.abs(rate - omega) / np.abs(omega), 1.0))
        return np.where(root >= 0, r, -(1.0 + wt))

    def close(self) -> None:
        self.world = None


Policy = Callable[[np.ndarray], Any]


def vector_actions(policy: Policy, obs: np.ndarray) -> np.ndarray:
    """The (B, A) actions of `policy` (observation array -> turn rate, what `policy_law`
    runs as a law) on observations (B, A, F): called on each array in turn, or once on
    the whole batch when it says it works on the last axis (`policy.vectorised = True`)."""
    if getattr(policy, "vectorised", False) is True:
        return np.asarray(policy(obs), dtype=float).reshape(obs.shape[:2])
    return np.array([[turn_rate(policy(o)) for o in row] for row in obs], dtype=float).reshape(obs.shape[:2])
