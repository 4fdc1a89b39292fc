"""The simulated fleet's pure parts (swarm/robots/fleet.py, `swarm robots sim`): a robot's body
(`Unicycle`: the last command, saturated, until it times out), what a TurtleBot3's firmware makes
of a command (`truncated`), the odom frame (`odom_pose`, `world_pose`), the noise on its poses
(`PoseNoise`) and their latency (`Delayed`). Times are arguments (fleet seconds): no clock, no
zenoh.
"""

from __future__ import annotations

import math
import random
from collections import deque
from typing import Generic, TypeVar

from swarm.contracts.orbits import wrap
from swarm.world.kinematics import step_one

DEFAULT_CMD_TIMEOUT = 0.5  # s

T = TypeVar("T")


def saturate(value: float, limit: float) -> float:
    """`value` clipped to [-limit, limit]; 0 for a value that is not a finite number (a robot
    given NaN stops)."""
    if not math.isfinite(value):
        return 0.0
    return max(-limit, min(limit, value))


class Unicycle:
    """One robot's body: a unicycle at (x, y, yaw) in the world frame that follows the last
    command (saturated) until it is older than `cmd_timeout`, and then stands still. Times are
    the fleet's seconds; `advance(t)` integrates up to t, `command(t, ...)` advances to t and
    takes the new command from then on (a command stamped before the body's time takes effect
    at the body's time)."""

    def __init__(
        self,
        x: float,
        y: float,
        yaw: float,
        max_linear: float,
        max_angular: float,
        cmd_timeout: float = DEFAULT_CMD_TIMEOUT,
        t: float = 0.0,
    ):
        self.x, self.y, self.yaw = x, y, yaw
        self.max_linear, self.max_angular, self.cmd_timeout = max_linear, max_angular, cmd_timeout
        self.t = t
        self.v = self.w = 0.0  # the command in effect (saturated)
        self.cmd_until = -math.inf  # when the command in effect times out

    def command(self, t: float, vx: float, wz: float) -> None:
        self.advance(t)
        self.v, self.w = saturate(vx, self.max_linear), saturate(wz, self.max_angular)
        self.cmd_until = self.t + self.cmd_timeout

    def advance(self, t: float) -> None:
        if t <= self.t:
            return
        if self.t < self.cmd_until:
            end = min(t, self.cmd_until)
            self.x, self.y, self.yaw = step_one(self.x, self.y, self.yaw, self.v, self.w, end - self.t)
            self.t = end
        self.t = t  # at rest from the command's timeout on

    def twist(self) -> tuple[float, float]:
        """(linear, angular) velocity now: the command in effect, zero once it timed out."""
        return (self.v, self.w) if self.t < self.cmd_until else (0.0, 0.0)

    def pose(self) -> tuple[float, float, float]:
        return self.x, self.y, self.yaw


def truncated(value: float, quantum: float) -> float:
    """What a TurtleBot3's firmware makes of a command: `value` truncated toward zero to whole
    steps of `quantum` (turtlebot3_node: `static_cast<int32_t>(value * 100)` for 0.01, on
    linear.x and angular.z alike); `value` itself for quantum 0."""
    if quantum <= 0.0 or not math.isfinite(value):
        return value
    return math.trunc(value * (1.0 / quantum)) * quantum


def odom_pose(start: tuple[float, float, float], pose: tuple[float, float, float]) -> tuple[float, float, float]:
    """A world-frame pose in the odom frame of a robot that started at `start` (the odom frame's
    origin and x axis are the robot's start position and heading)."""
    x0, y0, h0 = start
    dx, dy = pose[0] - x0, pose[1] - y0
    c, s = math.cos(h0), math.sin(h0)
    return c * dx + s * dy, -s * dx + c * dy, wrap(pose[2] - h0)


def world_pose(start: tuple[float, float, float], odom: tuple[float, float, float]) -> tuple[float, float, float]:
    """The inverse of `odom_pose`: an odom-frame pose in the world frame."""
    x0, y0, h0 = start
    c, s = math.cos(h0), math.sin(h0)
    return x0 + c * odom[0] - s * odom[1], y0 + s * odom[0] + c * odom[1], wrap(odom[2] + h0)


class PoseNoise:
    """Gaussian measurement noise on poses, from a seeded generator (the same seed, the same
    noise)."""

    def __init__(self, sigma: float, yaw_sigma: float, seed: int = 0):
        self.sigma, self.yaw_sigma = sigma, yaw_sigma
        self.rng = random.Random(seed)

    def apply(self, pose: tuple[float, float, float]) -> tuple[float, float, float]:
        if self.sigma == 0.0 and self.yaw_sigma == 0.0:
            return pose
        g = self.rng.gauss
        return pose[0] + g(0.0, self.sigma), pose[1] + g(0.0, self.sigma), wrap(pose[2] + g(0.0, self.yaw_sigma))


class Delayed(Generic[T]):
    """Items released `delay` s after they were pushed, in the order pushed (the latency of a
    robot's pose on its way to the world)."""

    def __init__(self, delay: float):
        self.delay = delay
        self._queue: deque[tuple[float, T]] = deque()

    def push(self, t: float, item: T) -> None:
        self._queue.append((t + self.delay, item))

    def due(self, t: float) -> list[T]:
        """The items whose time has come by `t` (removed), oldest first."""
        out = []
        while self._queue and self._queue[0][0] <= t:
            out.append(self._queue.popleft()[1])
        return out

    def next_time(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def __len__(self) -> int:
        return len(self._queue)
