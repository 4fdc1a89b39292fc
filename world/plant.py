"""A plant: something other than our kinematics that moves the agents (real robots).

Without a plant `WorldCore.step` integrates the unicycles itself. With one, the plant is
the physics: the world hands it each tick's turn rates and reads the poses back from it.
Its methods, in the order the world process calls them (world/main.py, world/clock.py):

- `prepare()`: before the world listens, so that nothing is started when it fails
  (e.g. reach the robots, learn their command types, wait for their first poses); a
  `Coded` error says what is wrong in one line and gives the world's exit code;
- `start(core, event)`: right before tick 0, once every agent has joined: set
  core.x / core.y / core.heading from the plant's poses; `event(kind, agent, reason,
  **more)` records an event of the run (the engine's `Engine.event`);
- `step(core, u)`: each tick, in place of the integration: `u` is `core.applied()` (the
  turn rates; NaN for an agent not in the world, 0.0 for a coasting one, which goes
  straight on at its speed): send the commands, then set core.x / core.y / core.heading
  from the latest poses;
- `hold()`: the clock holds (a pause, a scripted process fault being carried out): stand
  still until the next `step`;
- `stop()`: on every way out of the world (the end, SIGINT, SIGTERM, an error), as soon
  as the ticks are over, and again (harmlessly) at the very end: every robot stopped;
- `figures()`: what summary.json keeps of it (its `robots` section).

The robots' plant is swarm/robots/plant.py (`RobotPlant`); this package never imports it.
A world with a plant runs the realtime clock only (the robots do not wait for a lockstep).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from swarm.world.core import WorldCore


class EventSink(Protocol):
    def __call__(self, kind: str, agent: int | None, reason: str, **more: Any) -> Any: ...


class Plant(Protocol):
    def prepare(self) -> None: ...

    def start(self, core: WorldCore, event: EventSink) -> None: ...

    def step(self, core: WorldCore, u: np.ndarray) -> None: ...

    def hold(self) -> None: ...

    def stop(self) -> None: ...

    def figures(self) -> dict[str, Any]: ...
