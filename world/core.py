"""Ground truth of one run: poses, who is in the world, one step at a time.

`WorldCore` is the physics and the sensors, nothing else: the in-process engine and
the world process both drive it, which is why their trajectories agree. Per agent
it keeps one of three states:

- "active":   controlled by a live agent process; integrates the last command.
- "coasting": its process died and the scenario says on_dropout = "coast": it stays
              in the world (others still sense it) and moves straight (u = 0).
- "gone":     not in the world (dropped, or not joined yet): nobody senses it; its
              pose is kept so that a restarted process rejoins from where it dropped.

Commands are sanitised here, where physics is: a non-finite turn rate is never
integrated (the last good one is held), and one above the agent's limit is saturated.

With a plant (world/plant.py: real robots), the plant is the physics: `step` hands it the
turn rates `applied` gives and it sets x, y and heading from its poses; nothing is
integrated here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from swarm.contracts.scenario import Scenario
from swarm.contracts.scenario_tables import AgentSpec
from swarm.contracts.vocabulary import AgentState, SwitchReason
from swarm.world.core_cache import ACTIVE, COASTING, GONE, _Roster, _Sensed, _States
from swarm.world.kinematics import step, step_one
from swarm.world.sensing import (
    GRID_MIN_AGENTS,
    SensorFrame,
    build_frames,
    pairs_matrices,
    sensing_matrix,
    sensing_pairs,
)

STEP_ONE_BY_ONE = 32  # agents: up to this many, `step` goes agent by agent (world/kinematics.py)


class Physics(Protocol):
    """What the core asks of a plant (world/plant.py `Plant`, which imports this module)."""

    def step(self, core: WorldCore, u: np.ndarray) -> None: ...


class WorldCore:
    def __init__(self, scenario: Scenario, *, joined: bool = True, plant: Physics | None = None):
        """joined: the agents start in the world; plant: moves the agents instead of the
        kinematics (world/plant.py), None for the simulated unicycles."""
        self.scenario = scenario
        self.plant = plant
        agents = scenario.agents
        self.ids = np.array([a.id for a in agents], dtype=np.int64)
        self.index = {a.id: k for k, a in enumerate(agents)}
        self.x = np.array([a.x for a in agents], dtype=float)
        self.y = np.array([a.y for a in agents], dtype=float)
        self.heading = np.array([a.heading for a in agents], dtype=float)
        self.speed = np.array([a.speed for a in agents], dtype=float)
        self.limit = np.array([a.max_turn_rate or math.inf for a in agents], dtype=float)
        self.is_leader = np.array([a.role == "leader" for a in agents], dtype=bool)
        self.u = np.zeros(len(agents))  # last applied turn rate (rad/s)
        # advertised hops to a leader (-1 none); leaders advertise 0 from the start
        self.hops = np.where(self.is_leader, 0, -1).astype(np.int64)
        self.state = [ACTIVE if joined else GONE for _ in agents]
        self.target = (scenario.target.x, scenario.target.y)
        self.dt = scenario.run.dt
        self.tick = 0
        self.rejected = 0  # non-finite commands refused
        self._sensing: _Sensed | None = None  # this tick's sensing, until poses or presence change

    @property
    def time(self) -> float:
        """Simulated time of the current tick (s)."""
        return self.tick * self.dt

    @property
    def state(self) -> list[AgentState]:
        """Each agent's state, by index (ACTIVE, COASTING, GONE): change it in place or assign
        a new list; either way what is derived from it follows (`_roster`)."""
        return self._state

    @state.setter
    def state(self, states: list[AgentState]) -> None:
        self._state = _States(states)
        self._roster_of: _Roster | None = None

    def _roster(self) -> _Roster:
        """Who is where, made again only when the states have changed since it was made."""
        r, st = self._roster_of, self._state
        if r is None or r.states is not st or r.version != st.version:
            r = self._roster_of = _Roster(st, self.ids)
        return r

    def active_ids(self) -> list[int]:
        return list(self._roster().active_ids)

    def present_mask(self) -> np.ndarray:
        return self._roster().present.copy()

    def alive_mask(self) -> np.ndarray:
        return self._roster().alive.copy()

    def frames(self, only: list[int] | None = None) -> dict[int, SensorFrame]:
        """Sensor frames of the current tick for the active agents (or `only` those)."""
        wanted = self.active_ids() if only is None else only
        receivers = [self.index[i] for i in wanted]
        sens = self.scenario.sensing
        return build_frames(
            self.tick,
            self.time,
            self.ids,
            self.x,
            self.y,
            self.heading,
            self.present_mask(),
            receivers,
            self.is_leader,
            self.target,
            sens.range,
            sens.fov,
            self.hops,
            self.sensing(),
        )

    def sensing(self) -> Any:
        """(S, bearing, range) matrices of the current tick: S[i, j] when i senses j.
        Computed once per tick (and again after a drop, join or add); do not modify them.
        With a sensing range and at least GRID_MIN_AGENTS agents they come from the grid
        (world/sensing.py `sensing_grid`, O(N k)): the same S, and the same bearing and range
        wherever S (NaN and inf elsewhere); otherwise from every pair (`sensing_matrix`)."""
        if self._sensing is None:
            self._sensing = _Sensed()
        got = self._sensing
        if got.matrices is None:
            if self.uses_grid():
                got.matrices = pairs_matrices(len(self.ids), *self.sensed_pairs())
            else:
                sens = self.scenario.sensing
                got.matrices = sensing_matrix(self.x, self.y, self.heading, self.present_mask(), sens.range, sens.fov)
        return got.matrices

    def sensed_pairs(self) -> Any:
        """(i, j, bearing, range) arrays of this tick's sensed pairs (agent i senses agent j),
        sorted by i, then j, what wire.encode_sense_pairs takes: through the grid
        (`sensing_pairs`, no (N, N) matrix made) where `sensing` uses it, else from
        `sensing`'s matrices. Computed once per tick like them; do not modify them."""
        if self._sensing is None:
            self._sensing = _Sensed()
        got = self._sensing
        if got.pairs is None:
            if self.uses_grid():
                sens = self.scenario.sensing
                assert sens.range is not None  # (uses_grid: a sensing range)
                got.pairs = sensing_pairs(self.x, self.y, self.heading, self.present_mask(), sens.range, sens.fov)
            else:
                s, bearing, rng = self.sensing()
                i, j = np.nonzero(s)
                got.pairs = (i, j, bearing[i, j], rng[i, j])
        return got.pairs

    def in_sight(self, k: int, j: int) -> bool:
        """Whether the agent at index k senses the one at index j this tick (`sensing`'s
        S[k, j]), from the form this tick has: where the grid is used and no matrices were
        made, from the sensed pairs (sorted by i: k's run of them), without making any."""
        got = self._sensing
        if (got is not None and got.matrices is not None) or not self.uses_grid():
            return bool(self.sensing()[0][k, j])
        i, sensed, _, _ = self.sensed_pairs()
        return j in sensed[i.searchsorted(k) : i.searchsorted(k + 1)].tolist()

    def uses_grid(self) -> bool:
        """Whether this tick's sensing goes through the grid (a sensing range, GRID_MIN_AGENTS
        agents or more): then `sensed_pairs` is the cheaper form for encoding the frames."""
        return self.scenario.sensing.range is not None and len(self.ids) >= GRID_MIN_AGENTS

    def set_command(self, agent_id: int, u: float, hops: int | None = None) -> bool:
        """Latch agent_id's turn rate for the next step, and the hop count it advertises
        (None or out of range: not rooted); False if the command was refused."""
        k = self.index[agent_id]
        if not math.isfinite(u):
            self.rejected += 1
            return False
        lim = self.limit.item(k)  # a float: numpy scalars are slow to compare
        self.u[k] = u if -lim <= u <= lim else max(-lim, min(lim, u))
        self.hops[k] = hops if hops is not None and 0 <= hops <= len(self.ids) else -1
        return True

    def applied(self) -> np.ndarray:
        """Turn rates that the next step will integrate (NaN for agents not in the world)."""
        out = self.u.copy()
        r = self._roster()
        for k in r.coasting:
            out[k] = 0.0
        for k in r.gone:
            out[k] = math.nan
        return out

    def advance_held(self) -> None:
        """The plant held this step (world/engine.py: commands from poses a stall made stale)
        and read its poses back: the tick goes on without a command sent."""
        self._sensing = None
        self.tick += 1

    def step(self, u: np.ndarray | None = None, speed: np.ndarray | None = None) -> None:
        """Advance every agent in the world by one dt with the latched commands (agent by
        agent in a small swarm, where that is faster; the same bits either way), or let the
        plant move them (it sends `applied()` and reads the poses back). `u`, `speed`: this
        step's turn rates and speeds instead of `applied()` and each agent's own (the safety
        filter's, world/safety_watch.py; `u` as `applied()` gives it: 0.0 coasting, NaN gone)."""
        self._sensing = None
        if self.plant is not None:
            own = self.speed
            if speed is not None:  # the plant drives each robot at core.speed: the filter's, for this step
                self.speed = speed
            try:
                self.plant.step(self, self.applied() if u is None else u)
            finally:
                self.speed = own
            self.tick += 1
            return
        if len(self.ids) <= STEP_ONE_BY_ONE:
            self._step_one_by_one(u, speed)
            return
        if u is None:
            u = self.applied()
        moving = ~np.isnan(u)
        v = self.speed if speed is None else speed
        nx, ny, ng = step(self.x, self.y, self.heading, v, np.where(moving, u, 0.0), self.dt)
        self.x = np.where(moving, nx, self.x)
        self.y = np.where(moving, ny, self.y)
        self.heading = np.where(moving, ng, self.heading)
        self.tick += 1

    def _step_one_by_one(self, u_now: np.ndarray | None = None, speed: np.ndarray | None = None) -> None:
        x, y, g = self.x.tolist(), self.y.tolist(), self.heading.tolist()
        u, v, dt = (
            (self.u if u_now is None else u_now).tolist(),
            (self.speed if speed is None else speed).tolist(),
            self.dt,
        )
        for k, s in enumerate(self.state):
            if s != GONE:  # a coasting agent moves straight on (u = 0), as `applied` says
                x[k], y[k], g[k] = step_one(x[k], y[k], g[k], v[k], u[k] if s == ACTIVE else 0.0, dt)
        self.x, self.y, self.heading = np.array(x), np.array(y), np.array(g)
        self.tick += 1

    def drop(self, agent_id: int) -> AgentState:
        """An agent's process died: it leaves the world or coasts (scenario on_dropout)."""
        self._sensing = None
        k = self.index[agent_id]
        self.state[k] = COASTING if self.scenario.run.on_dropout == "coast" else GONE
        self.hops[k] = -1  # nobody relays for a dead agent
        return self.state[k]

    def join(self, agent_id: int) -> None:
        """An agent's process (re)joined: controlled again from its current pose."""
        self._sensing = None
        k = self.index[agent_id]
        if self.state[k] != ACTIVE:
            self.u[k] = 0.0
            self.hops[k] = 0 if self.is_leader[k] else -1
        self.state[k] = ACTIVE

    def add_agent(self, spec: AgentSpec) -> None:
        """A new agent (not in the scenario file) enters the run, not yet joined ("gone")."""
        self._sensing = None
        if spec.id in self.index:
            raise ValueError(f"agent {spec.id} already exists")
        self.scenario = self.scenario.model_copy(update={"agents": [*self.scenario.agents, spec]})
        self.index[spec.id] = len(self.ids)
        self.ids = np.append(self.ids, spec.id)
        self.x = np.append(self.x, spec.x)
        self.y = np.append(self.y, spec.y)
        self.heading = np.append(self.heading, spec.heading)
        self.speed = np.append(self.speed, spec.speed)
        self.limit = np.append(self.limit, spec.max_turn_rate or math.inf)
        self.is_leader = np.append(self.is_leader, spec.role == "leader")
        self.u = np.append(self.u, 0.0)
        self.hops = np.append(self.hops, 0 if spec.role == "leader" else -1)
        self.state.append(GONE)

    def switch_reason(self, agent_id: int, old: int | None, new: int | None, hops_sent: np.ndarray) -> SwitchReason:
        """Why `agent_id` changed its out-neighbour from `old` to `new` this tick (`switch_reason`
        below): what ground truth and the hop counts sent in this tick's frames (`hops_sent`,
        (N,)) say about the old one."""
        spec = self.scenario.agents[self.index[agent_id]]
        j = self.index.get(old) if old is not None else None
        return switch_reason(
            sticky=self.scenario.sensing.selection == "sticky",
            new=new is not None,
            pinned_missed=self.scenario.sensing.selection == "fixed" and spec.follow is not None and new != spec.follow,
            old=old is not None,
            old_left=lambda: j is None or self.state[j] == GONE,
            old_in_sight=lambda: j is not None and self.in_sight(self.index[agent_id], j),
            old_hopless=lambda: j is not None and j < len(hops_sent) and bool(hops_sent[j] < 0),
        )

    def pose(self, agent_id: int) -> tuple[float, float, float]:
        k = self.index[agent_id]
        return float(self.x[k]), float(self.y[k]), float(self.heading[k])


def switch_reason(
    *,
    sticky: bool,
    new: bool,
    pinned_missed: bool,
    old: bool,
    old_left: Callable[[], bool],
    old_in_sight: Callable[[], bool],
    old_hopless: Callable[[], bool],
) -> SwitchReason:
    """The reason of a "switch" event, the rule both engines follow (`WorldCore.switch_reason`,
    world/batch.py `BatchWorld.switch_reason`): `new` / `old`, whether the follower has a new
    / had an old out-neighbour; `pinned_missed`, the new one is not the agent it is pinned to
    (selection = "fixed"); about the old one, asked in this order and only as far as needed:
    it left the world, it is in the follower's sight, its frame advertised no path to a leader."""
    if not new:
        return SwitchReason.NONE_SEARCHING if sticky else SwitchReason.NONE_LOITERING
    if pinned_missed:
        return SwitchReason.PINNED_NOT_SENSED
    if not old:
        return SwitchReason.CHOSEN
    if old_left():
        return SwitchReason.LEFT
    if not old_in_sight():
        return SwitchReason.OUT_OF_SIGHT
    if old_hopless():
        return SwitchReason.NO_PATH
    return SwitchReason.ANOTHER
