"""The swarms study's job as a VMAS scenario: N unicycles at constant speed, steered by turn
rate, circumnavigating a target at the origin, with swarm.env's default reward.

Needs torch and vmas: run it from the benchmark's own venv (benchmarks/vmas/README.md), never
the project's. The job, as `swarm.study.swarms.random_swarm` draws it (SwarmSetting's
defaults): 10 agents, the first 2 leaders orbiting counter-clockwise at R_L = v_L / omega
(omega = 1 rad/s), the others followers; starts uniform in a 120 m square centred on the
target, headings uniform, speeds uniform in [15, 40] m/s; dt = 0.05 s.

- Dynamics (`Unicycle`): the action is the turn rate u (rad/s, in +-pi/dt, what SwarmEnv
  allows an agent without max_turn_rate); the agent moves at its own constant speed along
  the exact arc of that turn rate over dt, as swarm's engine integrates (the arc's x, y and
  heading increments are handed to VMAS's physics as the force and torque that produce them
  in one step, as VMAS's own DiffDrive does; drag and friction are 0, collisions off).
- Reward: swarm.env's `radial_rate_reward()` (swarm/env/parallel.py), per agent
      -( min(|r_i - R_i| / R_i, 1) + min(|w_i - w| / |w|, 1) )
  with w = d v_L / R_L and R_i = v_i R_L / v_L from the leader L the agent is rooted at, and
  -2 for an agent rooted at no leader. Rooting: a follower's out-neighbour is its nearest
  agent, re-chosen every step (swarm's `selection = "nearest"` with its default hysteresis
  0, the paper's rule; the benchmark runs swarm with it), roots found by pointer jumping
  over the out-neighbours (a follower-only cycle roots at no leader).
- Observation: the 48 floats of swarm.env's observation array for K = 6 contacts
  (swarm/env/observation.py): own (fresh, leader, speed, max_turn_rate, last_u, cos, sin,
  contacts), target (present, range, bearing, R, direction), out (present, range, bearing,
  heading, hops), then the 6 nearest contacts (same five fields).

All agents' geometry, observations and rewards are computed once per step as (B, N, ...)
tensors (`post_step` and `reset_world_at`); `observation` and `reward` hand out columns.
"""

from __future__ import annotations

import math

import torch
from vmas.simulator.core import Agent, World
from vmas.simulator.dynamics.common import Dynamics
from vmas.simulator.scenario import BaseScenario

TAU = 2 * math.pi


def wrap(a: torch.Tensor) -> torch.Tensor:
    """Angles to (-pi, pi]."""
    return a - TAU * torch.ceil((a - math.pi) / TAU)


class Unicycle(Dynamics):
    """Constant speed (the scenario's per-agent speed), turn rate from the action; the exact
    arc over dt, turned into the force and torque VMAS's semi-implicit Euler needs."""

    def __init__(self, world: World, scenario: Circumnav, column: int):
        super().__init__()
        self.world, self.scenario, self.column = world, scenario, column

    @property
    def needed_action_size(self) -> int:
        return 1

    def process_action(self) -> None:
        a, dt = self.agent, self.world.dt
        u = a.action.u[:, 0]
        v = self.scenario.speed[:, self.column]
        h = a.state.rot[:, 0]
        half = 0.5 * u * dt  # swarm/world/kinematics.py's step: the chord of the arc, in sinc form
        chord = v * dt * torch.sinc(half / math.pi)
        dx, dy, turn = chord * torch.cos(h + half), chord * torch.sin(h + half), 2.0 * half
        a.state.force[:, 0] = a.mass * (dx - a.state.vel[:, 0] * dt) / dt**2
        a.state.force[:, 1] = a.mass * (dy - a.state.vel[:, 1] * dt) / dt**2
        a.state.torque = (a.moment_of_inertia * (turn - a.state.ang_vel[:, 0] * dt) / dt**2).unsqueeze(-1)


class Circumnav(BaseScenario):
    def make_world(self, batch_dim: int, device: torch.device, **kwargs) -> World:
        self.n = kwargs.pop("n_agents", 10)
        self.leaders = kwargs.pop("n_leaders", 2)
        self.area = kwargs.pop("area", 120.0)
        self.speed_range = (kwargs.pop("speed_min", 15.0), kwargs.pop("speed_max", 40.0))
        self.omega = kwargs.pop("omega", 1.0)
        self.k = kwargs.pop("k_nearest", 6)
        self.rate_weight = kwargs.pop("rate_weight", 1.0)
        dt = kwargs.pop("dt", 0.05)
        if kwargs:
            raise ValueError(f"Circumnav: unknown options {sorted(kwargs)}")
        world = World(batch_dim, device, dt=dt, drag=0.0, linear_friction=0.0, angular_friction=0.0)
        for i in range(self.n):
            world.add_agent(
                Agent(
                    name=f"agent_{i + 1}",
                    collide=False,
                    rotatable=True,
                    u_range=math.pi / dt,
                    dynamics=Unicycle(world, self, i),
                    action_size=1,
                )
            )
        self.column = {a.name: i for i, a in enumerate(world.agents)}
        self.speed = torch.zeros(batch_dim, self.n, device=device)
        self.is_leader = torch.zeros(self.n, dtype=torch.bool, device=device)
        self.is_leader[: self.leaders] = True
        self.radius = torch.full((batch_dim, self.n), math.nan, device=device)  # leaders' R_L
        self.direction = torch.where(self.is_leader, 1.0, 0.0).expand(batch_dim, self.n)  # ccw leaders
        self.last_u = torch.zeros(batch_dim, self.n, device=device)
        return world

    def reset_world_at(self, env_index: int | None = None) -> None:
        w = self.world
        rows = slice(None) if env_index is None else slice(env_index, env_index + 1)
        b = w.batch_dim if env_index is None else 1
        half = self.area / 2
        xy = torch.empty(b, self.n, 2, device=w.device).uniform_(-half, half)
        heading = torch.empty(b, self.n, device=w.device).uniform_(-math.pi, math.pi)
        speed = torch.empty(b, self.n, device=w.device).uniform_(*self.speed_range)
        self.speed[rows] = speed
        self.radius[rows] = torch.where(self.is_leader, speed / self.omega, math.nan)
        self.last_u[rows] = 0.0
        for i, a in enumerate(w.agents):
            a.set_pos(xy[:, i], batch_index=env_index)
            a.set_rot(heading[:, i : i + 1], batch_index=env_index)
            a.set_vel(torch.zeros(b, 2, device=w.device), batch_index=env_index)
            a.set_ang_vel(torch.zeros(b, 1, device=w.device), batch_index=env_index)
        self._refresh()

    def post_step(self) -> None:
        self.last_u = torch.stack([a.action.u[:, 0] for a in self.world.agents], dim=1)
        self._refresh()

    def _refresh(self) -> None:
        """Geometry, out-neighbours, roots, observations and rewards of every agent."""
        agents, n, k = self.world.agents, self.n, self.k
        pos = torch.stack([a.state.pos for a in agents], dim=1)  # B, N, 2
        h = torch.stack([a.state.rot[:, 0] for a in agents], dim=1)  # B, N
        bsz = pos.shape[0]
        rel = pos.unsqueeze(1) - pos.unsqueeze(2)  # B, i, j, 2: j seen from i
        dist = torch.linalg.vector_norm(rel, dim=-1)
        dist = dist + torch.diag(torch.full((n,), math.inf, device=pos.device))
        bearing = wrap(torch.atan2(rel[..., 1], rel[..., 0]) - h.unsqueeze(2))
        rel_h = wrap(h.unsqueeze(1) - h.unsqueeze(2))
        # out-neighbours: followers their nearest agent, leaders themselves; roots by pointer jumping
        ar = torch.arange(n, device=pos.device).expand(bsz, n)
        out = torch.where(self.is_leader, ar, dist.argmin(dim=2))
        hops = torch.where(self.is_leader, 0, 1).expand(bsz, n).clone()
        root = out
        for _ in range(max(1, math.ceil(math.log2(n)))):
            hops = hops + torch.gather(hops, 1, root)
            root = torch.gather(root, 1, root)
        rooted = self.is_leader[root]
        hops = torch.where(rooted, hops, -1)
        # reward (swarm.env.radial_rate_reward)
        v = self.speed
        v_l, r_l = torch.gather(v, 1, root), torch.gather(self.radius, 1, root)
        d_l = torch.gather(self.direction, 1, root)
        omega = d_l * v_l / r_l
        big_r = v * r_l / v_l
        r2 = (pos * pos).sum(-1)
        rate = torch.where(r2 > 0, (pos[..., 0] * v * torch.sin(h) - pos[..., 1] * v * torch.cos(h)) / r2, 0.0)
        radial = ((r2.sqrt() - big_r).abs() / big_r).clamp(max=1.0)
        rew = -(radial + self.rate_weight * ((rate - omega).abs() / omega.abs()).clamp(max=1.0))
        self.rewards = torch.where(rooted, rew, -(1.0 + self.rate_weight))
        # observation (swarm.env.observation_array, K = k)
        own = torch.stack(
            [
                torch.ones_like(v),
                self.is_leader.expand(bsz, n).float(),
                v,
                torch.zeros_like(v),
                self.last_u,
                torch.cos(h),
                torch.sin(h),
                torch.full_like(v, n - 1),
            ],
            dim=-1,
        )
        lead = self.is_leader.expand(bsz, n).float()
        t_range = r2.sqrt()
        t_bearing = wrap(torch.atan2(-pos[..., 1], -pos[..., 0]) - h)
        target = torch.stack(
            [lead, t_range * lead, t_bearing * lead, torch.nan_to_num(self.radius) * lead, self.direction], dim=-1
        )
        hops_all = hops.unsqueeze(1).expand(bsz, n, n)

        def block(j: torch.Tensor, present: torch.Tensor) -> torch.Tensor:  # j: B, N, m columns
            fields = [torch.gather(x, 2, j) for x in (dist.nan_to_num(posinf=0.0), bearing, rel_h, hops_all.float())]
            return torch.stack([present, *fields], dim=-1) * present.unsqueeze(-1)

        follower = (~self.is_leader).expand(bsz, n).float().unsqueeze(-1)
        out_block = block(out.unsqueeze(-1), follower).flatten(2)
        near = dist.topk(min(k, n - 1), dim=2, largest=False).indices
        contacts = block(near, torch.ones(near.shape, device=pos.device)).flatten(2)
        pad = torch.zeros(bsz, n, 5 * (k - near.shape[2]), device=pos.device)
        self.obs = torch.cat([own, target, out_block, contacts, pad], dim=-1)  # B, N, 18 + 5 k

    def observation(self, agent: Agent) -> torch.Tensor:
        return self.obs[:, self.column[agent.name]]

    def reward(self, agent: Agent) -> torch.Tensor:
        return self.rewards[:, self.column[agent.name]]
