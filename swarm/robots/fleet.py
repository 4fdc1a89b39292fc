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
stamp is the wall-clock time of measurement, as a robot's is). `time_scale` runs the fleet's
clock that many times faster than the wall's (for `swarm up --time-scale`): the rate, the
latency and the command timeout are in the fleet's time, the stamps stay wall-clock.

The pure parts (`Unicycle`, `Delayed`, `PoseNoise`, `odom_pose`: swarm/robots/sim_body.py) take
times as arguments; `Fleet` adds the clock and the protocol.
"""

from __future__ import annotations

import json
import math
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import zenoh

from swarm.contracts.scenario import Scenario
from swarm.contracts.transport import ROUTER_QUEUE
from swarm.contracts.vocabulary import Coded, ExitCode, signal_exit
from swarm.robots.config import RobotsFile, RobotSpec
from swarm.robots.sim_body import DEFAULT_CMD_TIMEOUT, Delayed, PoseNoise, Unicycle, odom_pose, truncated
from swarm.ros2 import cdr
from swarm.ros2.node import Ros2Node, Ros2Publisher, Ros2Subscriber
from swarm.ros2.types import ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED

DEFAULT_RATE = 30.0  # Hz: a little above a TurtleBot3 (turtlebot3_node reads its sensors every 50 ms: 20 Hz)
YAW_NOISE_BASELINE = 0.2  # m: yaw noise = pose noise / this (a marker spread the size of a TurtleBot)
ODOM_FRAME, BASE_FRAME, WORLD_FRAME = "odom", "base_footprint", "world"
ROBOT_NODE = "sim_robot"  # each robot's node name, in its namespace


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
    # the firmware's step (m/s and rad/s; 0: none): each command truncated toward zero to a whole
    # number of steps, as turtlebot3_node does (static_cast<int32_t>(linear.x * 100) for 0.01)
    quantize: float = 0.0
    # agent -> fleet s after the fleet's first motion command (the run's start) when that robot
    # stops publishing its poses (to rehearse stale poses)
    stop_poses: Mapping[int, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("latency", "pose_noise", "cmd_timeout", "quantize"):
            if not (getattr(self, name) >= 0.0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number >= 0")
        for name in ("rate", "time_scale"):
            if not (getattr(self, name) > 0.0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a finite number > 0")
        if self.yaw_noise is not None and not (self.yaw_noise >= 0.0 and math.isfinite(self.yaw_noise)):
            raise ValueError("yaw_noise must be a finite number >= 0")
        for agent, after in self.stop_poses.items():
            if not (after >= 0.0 and math.isfinite(after)):
                raise ValueError(f"stop_poses: agent {agent}'s seconds must be a finite number >= 0")

    @property
    def yaw_sigma(self) -> float:
        return self.pose_noise / YAW_NOISE_BASELINE if self.yaw_noise is None else self.yaw_noise


# -- the fleet over zenoh ------------------------------------------------------------------------------
class FleetError(Coded):
    """The fleet cannot start (its router cannot listen, a bad option); exit 2."""

    exit_code = ExitCode.USAGE


def router_config(listen: str, config_file: str | None = None) -> zenoh.Config:
    """A zenoh router listening on `listen`, the stand-in for the robots' rmw_zenohd; with
    `config_file`, a zenoh config (JSON5) as rmw_zenohd takes it (ZENOH_ROUTER_CONFIG_URI) under
    ours: e.g. its transport/auth/usrpwd and access_control close the router."""
    settings: dict[str, object] = {
        "mode": "router",
        "listen/endpoints": [listen],
        "scouting/multicast/enabled": False,
        "transport/shared_memory/enabled": False,
        **ROUTER_QUEUE,
    }
    cfg = zenoh.Config.from_file(config_file) if config_file is not None else zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


@dataclass
class SimRobot:
    """One robot of the fleet: its body, its node, and what it saw."""

    spec: RobotSpec
    start: tuple[float, float, float]  # the agent's start pose in the scenario (world frame)
    body: Unicycle
    poses: Delayed[bytes]
    stop_poses_after: float = math.inf  # fleet s after the first motion command
    node: Ros2Node | None = None
    pose_pub: Ros2Publisher | None = None
    cmd_sub: Ros2Subscriber | None = None
    inbox: deque[tuple[float, float, float]] = field(default_factory=deque)  # (t, vx, wz) from zenoh's thread
    next_pose: float = 0.0  # fleet time of the next measurement: ticks * period
    ticks: int = 0
    commands: int = 0
    malformed: int = 0
    published: int = 0
    poses_stopped: bool = False
    last_command: tuple[float, float] | None = None
    last_moving_at: float | None = None  # fleet time of the last nonzero command
    stopped_at: float | None = None  # fleet time of the first zero command after it

    @property
    def cmd_type(self) -> str:
        return "TwistStamped" if self.spec.cmd_type == "TwistStamped" else "Twist"

    def describe(self) -> str:
        """ "robot 1: /tb3_0 odom -> cmd_vel TwistStamped" """
        ns = self.spec.namespace or "/"
        return f"robot {self.spec.agent}: {ns} {self.spec.pose_topic_name} -> {self.spec.cmd_topic} {self.cmd_type}"

    def take(self, t: float, vx: float, wz: float) -> None:
        """A command that arrived at fleet time `t` (in the main loop, in arrival order)."""
        self.body.command(t, vx, wz)
        self.commands += 1
        self.last_command = (vx, wz)
        if vx != 0.0 or wz != 0.0:
            self.last_moving_at, self.stopped_at = t, None
        elif self.stopped_at is None:
            self.stopped_at = t

    def report(self) -> str:
        """One line at the end: what the robot received and sent, and how it was left."""
        last = "none" if self.last_command is None else "linear {:g}, angular {:g}".format(*self.last_command)
        line = (
            f"robot {self.spec.agent}: {self.commands} commands ({self.malformed} malformed), "
            f"{self.published} poses; last command {last}"
        )
        if self.last_moving_at is not None and self.stopped_at is not None:
            line += f"; stopped by a zero twist at t={self.stopped_at:.3f} s"
        elif self.last_moving_at is not None:
            line += "; NO zero twist after its last motion command"
        return line


class Fleet:
    """The robots of a robots file, at their agents' start poses in `scenario`, driven by
    `step(now)` (fleet seconds); `open(session)` declares their nodes, `close()` undeclares
    them. `run` is the loop of `swarm robots sim`."""

    def __init__(
        self,
        robots: RobotsFile,
        scenario: Scenario,
        options: FleetOptions | None = None,
        out: Callable[[str], None] = print,
    ):
        self.file, self.options, self.out = robots, options or FleetOptions(), out
        self.noise = PoseNoise(self.options.pose_noise, self.options.yaw_sigma, self.options.seed)
        starts = {a.id: (a.x, a.y, a.heading) for a in scenario.agents}
        unknown = sorted(set(self.options.stop_poses) - {r.agent for r in robots.robots})
        if unknown:
            raise FleetError(f"--stop-poses: no robot for agent {unknown[0]} in the robots file")
        self.robots = []
        for spec in robots.robots:
            if spec.agent not in starts:
                raise FleetError(f"robots.agent {spec.agent}: the scenario has no agent {spec.agent}")
            start = starts[spec.agent]
            body = Unicycle(*start, spec.max_linear, spec.max_angular, self.options.cmd_timeout)
            self.robots.append(
                SimRobot(
                    spec,
                    start,
                    body,
                    Delayed(self.options.latency),
                    stop_poses_after=self.options.stop_poses.get(spec.agent, math.inf),
                )
            )
        self.period = 1.0 / self.options.rate
        self.first_motion_at: float | None = None  # fleet time of the first nonzero command to any robot
        self.epoch_ns = time.time_ns()  # the stamps: this + the wall time since then
        self._t0 = time.monotonic()

    # the fleet's clock: seconds since it was made, time_scale times faster than the wall's
    def now(self) -> float:
        return (time.monotonic() - self._t0) * self.options.time_scale

    def open(self, session: zenoh.Session) -> None:
        ros2 = self.file.ros2
        for r in self.robots:
            r.node = Ros2Node(session, ROBOT_NODE, r.spec.namespace, ros2.domain, ros2.distro)
            pose_type = ODOMETRY if r.spec.pose == "odom" else POSE_STAMPED
            r.pose_pub = r.node.publisher(r.spec.topic(r.spec.pose_topic_name), pose_type)
            cmd_type = TWIST_STAMPED if r.cmd_type == "TwistStamped" else TWIST
            r.cmd_sub = r.node.subscriber(r.spec.topic(r.spec.cmd_topic), cmd_type, self._on_command(r))

    def _on_command(self, r: SimRobot) -> Callable[[bytes], None]:
        stamped = r.cmd_type == "TwistStamped"

        def on_sample(payload: bytes) -> None:  # zenoh's thread: decode and queue
            t = self.now()
            try:
                vx, wz = cdr.decode_twist_stamped(payload)[2:] if stamped else cdr.decode_twist(payload)
            except cdr.CdrError:
                r.malformed += 1
                return
            r.inbox.append((t, vx, wz))

        return on_sample

    def measure(self, r: SimRobot, t: float) -> bytes:
        """The robot's pose message at fleet time `t` (noise added; the odom frame for odom)."""
        stamp = self.epoch_ns + round(t / self.options.time_scale * 1e9)  # the wall clock then
        if r.spec.pose == "odom":
            x, y, yaw = self.noise.apply(odom_pose(r.start, r.body.pose()))
            vx, wz = r.body.twist()
            return cdr.encode_odometry(stamp, ODOM_FRAME, BASE_FRAME, x, y, yaw, vx, wz)
        x, y, yaw = self.noise.apply(r.body.pose())
        return cdr.encode_pose_stamped(stamp, WORLD_FRAME, x, y, yaw)

    def step(self, now: float) -> float:
        """Take the commands that arrived, move every robot to `now`, measure the poses that are
        due and publish those whose latency has passed; the fleet time of the next thing to do."""
        wake = math.inf
        for r in self.robots:
            while r.inbox:
                t, vx, wz = r.inbox.popleft()
                q = self.options.quantize
                r.take(min(t, now), truncated(vx, q), truncated(wz, q))
                if self.first_motion_at is None and r.last_moving_at is not None:
                    self.first_motion_at = r.last_moving_at
            r.body.advance(now)
            if r.next_pose <= now:
                if self.first_motion_at is None or now < self.first_motion_at + r.stop_poses_after:
                    r.poses.push(now, self.measure(r, now))
                elif not r.poses_stopped:
                    r.poses_stopped = True
                    self.out(f"robot {r.spec.agent}: poses stopped at t={now:.3f} s (--stop-poses)")
                r.ticks = max(r.ticks + 1, math.floor(now / self.period) + 1)  # late: no burst to catch up
                r.next_pose = r.ticks * self.period
            for payload in r.poses.due(now):
                if r.pose_pub is not None:
                    r.pose_pub.put(payload)
                r.published += 1
            wake = min(wake, r.next_pose, r.poses.next_time() or math.inf)
        return wake

    def run(self, stop: threading.Event, duration: float | None = None) -> None:
        """Step until `stop` is set (or `duration` fleet seconds have passed)."""
        end = math.inf if duration is None else duration
        while not stop.is_set():
            now = self.now()
            if now >= end:
                break
            wake = min(self.step(now), end)
            wait = (wake - self.now()) / self.options.time_scale
            if wait > 0:
                stop.wait(wait)

    def close(self) -> None:
        for r in self.robots:
            if r.node is not None:
                r.node.close()
                r.node = None


def say(line: str) -> None:
    print(line, flush=True)


def run_fleet(
    robots: RobotsFile,
    scenario: Scenario,
    options: FleetOptions,
    listen: str | None = None,
    duration: float | None = None,
    out: Callable[[str], None] = say,
    config_file: str | None = None,
) -> int:
    """`swarm robots sim`: open the router, declare the robots, step them until Ctrl-C /
    SIGTERM (exit 130 / 143) or `duration` fleet seconds (exit 0); one line per robot at start
    and at the end."""
    fleet = Fleet(robots, scenario, options, out)
    endpoint = listen or robots.ros2.connect
    try:
        session = zenoh.open(router_config(endpoint, config_file))
    except zenoh.ZError as e:
        raise FleetError(f"cannot listen on {endpoint} (give another with --listen): {e}") from None
    stop, caught = threading.Event(), []

    def on_signal(signum: int, _frame: object) -> None:
        caught.append(signum)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        fleet.open(session)
        o = fleet.options
        out(
            f"fleet: {len(fleet.robots)} robots, router on {endpoint} (domain {robots.ros2.domain}, "
            f"{robots.ros2.distro}); poses at {o.rate:g} Hz, latency {o.latency:g} s, noise {o.pose_noise:g} m / "
            f"{o.yaw_sigma:g} rad, command timeout {o.cmd_timeout:g} s, time scale {o.time_scale:g}"
            + (f", commands truncated to steps of {o.quantize:g}" if o.quantize > 0 else "")
            + (f"; router config {config_file}" if config_file is not None else "")
        )
        for r in fleet.robots:
            out(r.describe())
        out("fleet ready (Ctrl-C stops it)")
        fleet.run(stop, duration)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        fleet.close()
        session.close()
    for r in fleet.robots:
        out(r.report())
    return signal_exit(caught[0]) if caught else ExitCode.OK
