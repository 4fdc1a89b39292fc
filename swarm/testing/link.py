"""A fake world for one agent, ticked by the test: `FakeWorldLink` feeds the agent's brain the
frames a world would send, records the commands it answers with, and moves it (and its
neighbours) as the world would, one dt per `tick()`. No zenoh, no processes, no clock.

    link = FakeWorldLink(my_leader_law, FrameBuilder(role="leader", orbit_radius=10.0, dt=0.1),
                         x=-30.0, heading=0.0, target=(0.0, 0.0))
    link.run(600)                      # 60 s of fake ticks
    link.commands[-1].u, link.pose     # what it sent last, where it is now

The brain is the one an agent process runs (swarm.agents.brain.AgentBrain: out-neighbour
selection, saturation at max_turn_rate, a NaN or inf held as the last turn rate), with the law
under test; frames and commands go through the wire's encoders and decoders
(swarm/contracts/wire.py), so a law sees what it would see off the network, and the commands
are what the world would decode. The agent moves along the exact arcs of
swarm/world/kinematics.py, as in `swarm sim`. See docs/guides/writing-a-law.md#unit-testing.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable
from typing import Any

from swarm.agents.brain import AgentBrain, Decision
from swarm.contracts import wire
from swarm.contracts.brain_config import BrainConf
from swarm.contracts.frames import SensorFrame
from swarm.contracts.laws import FOLLOWER, LEADER, check_law
from swarm.contracts.observation import Observation
from swarm.testing.frames import FrameBuilder, Neighbour, _integer, _number, _point
from swarm.world.kinematics import step_one

Law = Callable[[Observation], float]


def _one_argument(law: Callable[..., Any]) -> bool:
    try:
        inspect.signature(law).bind(None)
    except (TypeError, ValueError):  # ValueError: no signature to check
        return False
    return True


class FakeWorldLink:
    """One agent in a fake world: its law (a function `law(obs) -> u`, or a name as in a
    scenario's [law] table: "module:function", "bearing", "cc"), what it is (`agent`, a
    FrameBuilder), where it starts (x, y, heading), where the target is (leaders) and its
    neighbours (each moving at its own constant speed and turn rate; one given by bearing and
    range is placed where the agent sees it at the start, and moves on from there).

    Each `tick()` sends the agent its frame for the current poses, records the command it
    answers with and moves everybody by one dt. What it records, tick by tick:
    `frames` (SensorFrame), `observations` (what the law was given), `commands`
    (swarm.contracts.wire.Command: tick, u, out, phase, hops, follow) and `track` (the
    agent's (x, y, heading) at each frame)."""

    def __init__(
        self,
        law: Law | str,
        agent: FrameBuilder | None = None,
        *,
        x: float = 0.0,
        y: float = 0.0,
        heading: float = 0.0,
        target: tuple[float, float] | None = None,
        neighbours: Iterable[Neighbour] = (),
        n_agents: int | None = None,
    ) -> None:
        """n_agents: the agents in the (imagined) scenario, which caps the hops the agent
        advertises; by default itself and its neighbours."""
        where = "FakeWorldLink"
        self.agent = FrameBuilder() if agent is None else agent
        if not isinstance(self.agent, FrameBuilder):
            raise TypeError(f"{where}: agent: expected a FrameBuilder, got {self.agent!r}")
        self.x, self.y, self.heading = (
            _number(where, "x", x),
            _number(where, "y", y),
            _number(where, "heading", heading),
        )
        self.target = None if target is None else _point(where, "target", target)
        given = list(neighbours)
        self.agent.contacts(x=self.x, y=self.y, heading=self.heading, neighbours=given)  # checks them
        # placed by their positions now: those given by bearing and range are seen from the start
        self.neighbours: dict[int, Neighbour] = {n.id: n.placed(self.x, self.y) for n in given}
        self.agent.frame(x=self.x, y=self.y, heading=self.heading, target=self.target)  # checks the target
        n = 1 + len(given) if n_agents is None else _integer(where, "n_agents", n_agents, minimum=1)
        self.conf: BrainConf
        self.law: Law
        if isinstance(law, str):
            kind = LEADER if self.agent.role == "leader" else FOLLOWER
            self.law = check_law(law, kind)  # LawError (a ValueError) naming it if it is not one
            names = {"leader_law": law} if kind == LEADER else {"follower_law": law}
            self.conf = self.agent.conf(n_agents=n, **names)
        elif callable(law):
            if not _one_argument(law):
                raise TypeError(f"{where}: law: {law!r} does not take one argument (obs: an Observation)")
            self.law = law
            self.conf = self.agent.conf(n_agents=n)
        else:
            raise TypeError(f"{where}: law: expected a function law(obs) -> u or a name 'module:function', got {law!r}")
        self.brain = AgentBrain(self.conf)
        self.brain.law = self._recorded  # the brain runs as in an agent process, with this law
        self.tick_no = 0
        self.frames: list[SensorFrame] = []
        self.observations: list[Observation] = []
        self.commands: list[wire.Command] = []
        self.track: list[tuple[float, float, float]] = []

    def _recorded(self, obs: Observation) -> float:
        self.observations.append(obs)
        return self.law(obs)

    # -- the world's side ----------------------------------------------------------------------------
    @property
    def pose(self) -> tuple[float, float, float]:
        """The agent's (x, y, heading) now (m, m, rad)."""
        return self.x, self.y, self.heading

    @property
    def state(self) -> dict[str, Any]:
        """The law's own dict (`obs.state`), kept between ticks."""
        return self.brain.state

    @property
    def target_range(self) -> float | None:
        """The agent's distance to the target now (m); None without a target."""
        if self.target is None:
            return None
        return float(((self.target[0] - self.x) ** 2 + (self.target[1] - self.y) ** 2) ** 0.5)

    def move(self, neighbour: Neighbour) -> None:
        """Put a neighbour (a new one, or one already there by its id) where it says, as seen
        from the agent's current pose: e.g. to script a neighbour's path tick by tick."""
        self.agent.contacts(x=self.x, y=self.y, heading=self.heading, neighbours=[neighbour])  # checks it
        self.neighbours[neighbour.id] = neighbour.placed(self.x, self.y)

    def remove(self, neighbour_id: int) -> None:
        """Take a neighbour out of the world (it is no longer sensed)."""
        if neighbour_id not in self.neighbours:
            raise KeyError(f"remove: no neighbour {neighbour_id} (there are {sorted(self.neighbours)})")
        del self.neighbours[neighbour_id]

    def frame(self) -> SensorFrame:
        """The frame the agent gets at this tick, for the current poses."""
        return self.agent.frame(
            x=self.x,
            y=self.y,
            heading=self.heading,
            neighbours=self.neighbours.values(),
            target=self.target,
            tick=self.tick_no,
        )

    def feed(self, frame: SensorFrame) -> wire.Command:
        """Send the agent one frame (through the wire's encoding, as the world does) and record
        the command it answers with (decoded as the world decodes it). Moves nothing: `tick()`
        does, with the frame of the current poses."""
        frame = wire.decode_sense(wire.encode_sense(frame))
        self.frames.append(frame)
        d: Decision = self.brain.decide(frame)
        sent = wire.encode_cmd_fields(self.agent.id, d.tick, d.u, d.out, d.phase, d.hops, 0, d.follow)
        cmd = wire.decode_cmd(sent)
        self.commands.append(cmd)
        return cmd

    def tick(self) -> wire.Command:
        """One tick of the world: the agent's frame in, its command out, then everybody moves
        by dt (the agent at the turn rate it sent). Returns the command."""
        self.track.append(self.pose)
        cmd = self.feed(self.frame())
        dt, speed = self.agent.dt, self.agent.speed
        self.x, self.y, self.heading = step_one(self.x, self.y, self.heading, speed, cmd.u, dt)
        for i, n in self.neighbours.items():
            if n.speed or n.turn_rate:
                assert n.x is not None and n.y is not None  # (placed)
                nx, ny, nh = step_one(n.x, n.y, n.heading, n.speed, n.turn_rate, dt)
                self.neighbours[i] = Neighbour(i, nx, ny, None, None, nh, n.hops, n.speed, n.turn_rate)
        self.tick_no += 1
        return cmd

    def run(self, ticks: int) -> list[wire.Command]:
        """`ticks` ticks; the commands sent over them."""
        _integer("run", "ticks", ticks)
        return [self.tick() for _ in range(ticks)]
