"""The pure parts of the robots' plant (swarm/robots/plant.py): a pose between a robot's odom
frame and the world frame (`odom_to_world`, `rebase`, `mean_pose`), carried forward over its
latency (`predicted`); the twist an agent's turn rate becomes on a robot's motors (`twist_for`,
`quantized`, `planned_speed`); whether a pose can follow the last (`Plausible`); and the ages
of a robot's poses (`PoseAges`, `Spread`). No ROS 2, no zenoh: numbers in, numbers out.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from swarm.contracts.orbits import wrap
from swarm.contracts.vocabulary import EventKind
from swarm.robots.config import RobotSpec
from swarm.world.kinematics import step_one

Pose = tuple[float, float, float]  # x (m), y (m), yaw (rad)
KEPT = 20_000  # the latest pose ages and delays kept per robot for their medians (~0.6 MB each)


def odom_to_world(start: Pose, odom: Pose) -> Pose:
    """A pose in the odom frame of a robot whose odom frame starts at `start` (its start pose in
    the scenario: the frame's origin and x axis) as a pose in the world frame, yaw in (-pi, pi]."""
    x0, y0, h0 = start
    c, s = math.cos(h0), math.sin(h0)
    return x0 + c * odom[0] - s * odom[1], y0 + s * odom[0] + c * odom[1], float(wrap(h0 + odom[2]))


def predicted(pose: Pose, twist: tuple[float, float], age: float, horizon: float) -> Pose:
    """`pose`, measured `age` run seconds ago, carried forward along the unicycle's arc with
    `twist` (linear, angular): latency compensation. The age is clamped to [0, horizon] (a
    stamp from the future or far past, i.e. clocks out of step, is not extrapolated beyond)."""
    dt = min(max(age, 0.0), horizon)
    if dt == 0.0:
        return pose
    return step_one(pose[0], pose[1], pose[2], twist[0], twist[1], dt)


def rebase(origin: Pose, odom: Pose) -> Pose:
    """An odometry pose relative to `origin`, where the robot was before tick 0 (the mean of
    its odometry poses until then, the robot standing still): its odom frame moved to there
    (a robot whose odometry did not start at zero, e.g. its node ran before, or it was driven
    to its start pose)."""
    x0, y0, h0 = origin
    dx, dy = odom[0] - x0, odom[1] - y0
    c, s = math.cos(h0), math.sin(h0)
    return c * dx + s * dy, -s * dx + c * dy, float(wrap(odom[2] - h0))


def mean_pose(poses: Sequence[Pose]) -> Pose:
    """The mean of `poses`: positions averaged, headings by their unit vectors."""
    n = len(poses)
    yaw = math.atan2(sum(math.sin(p[2]) for p in poses), sum(math.cos(p[2]) for p in poses))
    return sum(p[0] for p in poses) / n, sum(p[1] for p in poses) / n, yaw


def saturate(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def motor_steps(value: float, quantum: float) -> int:
    """The whole steps a robot's firmware makes of a commanded `value`: turtlebot3_node
    writes `static_cast<int32_t>(linear.x * 100)` (and angular.z the same) to its board, i.e.
    truncates toward zero, for quantum 0.01."""
    return math.trunc(value * (1.0 / quantum))


def quantized(value: float, quantum: float, limit: float) -> float:
    """`value` as the nearest whole number of `quantum` steps within +-`limit`, written so that
    the firmware's truncation (`motor_steps`) gives exactly that step (0.29 * 100 is
    28.999999999999996 in floating point: sent as is, the robot would drive 0.28). `quantum`
    0: `value` saturated at the limit."""
    if quantum <= 0.0:
        return saturate(value, limit)
    inv = 1.0 / quantum
    top = math.floor(limit * inv + 1e-9)
    n = max(-top, min(top, round(value * inv)))
    sent = n * quantum
    toward = math.inf if n > 0 else -math.inf
    for _ in range(16):  # a few ulps at most
        if motor_steps(sent, quantum) == n:
            break
        sent = math.nextafter(sent, toward)
    return sent


def planned_speed(speed: float, spec: RobotSpec) -> float:
    """The speed an agent's robot really drives at: its scenario speed as whole `quantize`
    steps within max_linear (unchanged for a robot that does not quantize)."""
    if spec.quantize <= 0.0:
        return speed
    return round(quantized(speed, spec.quantize, spec.max_linear) / spec.quantize) * spec.quantize


def twist_for(
    speed: float, u: float, max_linear: float, max_angular: float, quantum: float = 0.0
) -> tuple[float, float]:
    """(linear.x, angular.z) for an agent of constant `speed` turning at `u` (`WorldCore.applied`:
    NaN when the agent is not in the world, which stops its robot), saturated at the robot's limits
    and, with a `quantum`, the nearest whole steps of the robot's firmware (`quantized`)."""
    if not math.isfinite(u):
        return 0.0, 0.0
    return quantized(speed, quantum, max_linear), quantized(u, quantum, max_angular)


YAW_PER_M = 5.0  # rad of pose_slack per m: 0.1 m of slack allows 0.5 rad of yaw


@dataclass(frozen=True)
class Plausible:
    """How far a robot may move between two poses: its limits times (1 + margin), plus slack
    for the noise of the measurement (m; YAW_PER_M times as many rad for the yaw)."""

    max_linear: float
    max_angular: float
    margin: float = 0.5
    slack: float = 0.1

    def why_not(self, last: Pose, pose: Pose, dt: float) -> str | None:
        """None when `pose` can follow `last` after `dt` run seconds; else why not, in words."""
        dt = max(dt, 0.0)
        dist = math.hypot(pose[0] - last[0], pose[1] - last[1])
        turn = abs(float(wrap(pose[2] - last[2])))
        k = 1.0 + self.margin
        reach = self.max_linear * k * dt + self.slack
        swing = self.max_angular * k * dt + self.slack * YAW_PER_M
        if dist <= reach and turn <= swing:
            return None
        return (
            f"{dist:.3f} m and {turn:.2f} rad from the last pose in {dt:.3f} s "
            f"(at most {reach:.3f} m and {swing:.2f} rad: {self.max_linear:g} m/s and {self.max_angular:g} rad/s "
            f"x {k:g}, + {self.slack:g} m)"
        )


class Spread:
    """The maximum of every value noted, and the median of the latest KEPT (a run of hours
    at 20 Hz would otherwise keep every value: memory that grows with the run)."""

    __slots__ = ("latest", "high")

    def __init__(self) -> None:
        self.latest: deque[float] = deque(maxlen=KEPT)
        self.high: float | None = None

    def add(self, v: float) -> None:
        self.latest.append(v)
        if self.high is None or v > self.high:
            self.high = v

    def median(self) -> float | None:
        return float(np.median(self.latest)) if self.latest else None


@dataclass
class PoseAges:
    """The age of a robot's latest pose at each tick (s), and its stale spells."""

    ages: Spread = field(default_factory=Spread)  # the finite ones (a pose had come)
    ticks_without_pose: int = 0
    stale: bool = False
    stale_ticks: int = 0
    stale_spells: int = 0

    def tick(self, age: float, stale_after: float) -> str | None:
        """Note this tick's age; EventKind.STALE when the pose has just gone stale (older than
        `stale_after`), EventKind.FRESH when it has just come back, else None."""
        if math.isfinite(age):
            self.ages.add(age)
        else:
            self.ticks_without_pose += 1
        was, self.stale = self.stale, age > stale_after
        if self.stale:
            self.stale_ticks += 1
        if self.stale and not was:
            self.stale_spells += 1
            return EventKind.STALE
        if was and not self.stale:
            return EventKind.FRESH
        return None

    def figures(self) -> dict[str, Any]:
        """max and median age (s; None before any tick or pose; the median of the latest
        KEPT ticks), ticks without a pose, ticks stale, stale spells."""
        return {
            "pose_age_max": self.ages.high,
            "pose_age_p50": self.ages.median(),
            "ticks_without_pose": self.ticks_without_pose,
            "stale_ticks": self.stale_ticks,
            "stale_spells": self.stale_spells,
        }
