"""The simulated fleet (`swarm robots sim SCENARIO --robots FILE`): unicycle robots that speak
rmw_zenoh like TurtleBots do, so a hardware run can be rehearsed on one machine and the
robot world tested end to end (docs/guides/robots.md).

One process, one zenoh session in router mode standing in for the robots' `rmw_zenohd`
(listening on the robots file's `[ros2] connect`, or `--listen`). Per robot of the robots
file, a ROS node in the robot's namespace with

- a subscription on its command topic: TwistStamped when the robots file says
  `cmd_type = "TwistStamped"`, Twist for "Twist" and "auto" (the world reads the type from
  this subscription's token);
- a publisher of its pose at `rate` Hz: nav_msgs/Odometry for `pose = "odom"` (frames
  "odom" / "base_footprint", relative to where the robot starts: the odom frame starts at
  the agent's start pose in the scenario), geometry_msgs/PoseStamped for `pose = "mocap"`
  (the world frame, "world").

The body is a unicycle integrated exactly over each piece of constant command (the world's
kinematics, world/kinematics.py), the command saturated at the robot's max_linear and
max_angular. A command older than `cmd_timeout` stops the robot: what a robot-side watchdog
does. Poses are measured at `rate` Hz, get Gaussian noise (`pose_noise` m on x and y,
`yaw_noise` rad on the yaw) and are published `latency` s after they were measured (their
stamp is the time of measurement). `time_scale` runs the fleet's clock that many times
faster than the wall's (for `swarm up --time-scale`): every duration here (rate, latency,
command timeout, stamps) is in the fleet's time.

The pure parts (`Unicycle`, `Delayed`, `PoseNoise`, `odom_pose`) take times as arguments;
`Fleet` adds the clock and the protocol.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from swarm.contracts.orbits import wrap
from swarm.world.kinematics import step_one

DEFAULT_RATE = 30.0  # Hz: the TurtleBot3's odometry rate is about that
DEFAULT_CMD_TIMEOUT = 0.5  # s
YAW_NOISE_BASELINE = 0.2  # m: yaw noise = pose noise / this (a marker spread the size of a TurtleBot)
ODOM_FRAME, BASE_FRAME, WORLD_FRAME = "odom", "base_footprint", "world"
ROBOT_NODE = "sim_robot"  # each robot's node name, in its namespace

T = TypeVar("T")


@dataclass(frozen=True)
class FleetOptions:
    """How the fleet behaves (the options of `swarm robots sim`)."""

    latency: float = 0.0  # s from a pose's measurement to its publication
    pose_noise: float = 0.0  # m: standard deviation of the noise on x and y
    yaw_noise: float | None = None  # rad: of the yaw (None: pose_noise / YAW_NOISE_BASELINE)
    rate: float = DEFAULT_RATE  # Hz: poses per second
    cmd_timeout: float = DEFAULT_CMD_TIMEOUT  # s: an older command stops the robot
    time_scale: float = 1.0  # fleet seconds per wall second
    seed: int = 0
    stop_poses: Mapping[int, float] = field(default_factory=dict)  # agent -> fleet s it stops publishing poses

    def __post_init__(self) -> None:
        for name in ("latency", "pose_noise", "cmd_timeout"):
            if not (getattr(self, name) >= 0.0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number >= 0")
        for name in ("rate", "time_scale"):
            if not (getattr(self, name) > 0.0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number > 0")
        if self.yaw_noise is not None and not (self.yaw_noise >= 0.0 and math.isfinite(self.yaw_noise)):
            raise ValueError("yaw_noise must be a finite number >= 0")

    @property
    def yaw_sigma(self) -> float:
        return self.pose_noise / YAW_NOISE_BASELINE if self.yaw_noise is None else self.yaw_noise


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
