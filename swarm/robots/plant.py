"""The robots' plant (world/plant.py `Plant`): a world whose physics is ROS 2 robots reached
through rmw_zenoh, `swarm up SCENARIO --robots FILE` / `swarm world SCENARIO --robots FILE`
(docs/guides/robots.md).

The agent processes are unchanged: the world builds their frames from the robots' poses and
sends each agent's turn rate to its robot. Per robot of the robots file (swarm/robots/config.py):

- poses: nav_msgs/Odometry (`pose = "odom"`: the odom frame starts where the agent starts in
  the scenario, so world pose = start pose composed with the odometry pose) or
  geometry_msgs/PoseStamped (`pose = "mocap"`: already in the world frame);
- commands: Twist or TwistStamped (`cmd_type`; "auto": the type the robot's own subscription
  token announces) with linear.x = the agent's constant speed saturated at max_linear and
  angular.z = its turn rate saturated at max_angular.

Safety: a robot gets a zero twist when its agent is gone (not when it coasts: that is straight
on at its speed, as on_dropout = "coast" says), when its latest pose is older than
`[ros2] stale_after` (a `stale` event, `fresh` when poses come again), while the world's clock
holds (a pause, a scripted fault) and at the end, however the world ends (`stop`); and a
watchdog thread stops every robot when the world's main thread has sent no command for
stale_after (a stalled or starved world) until the next tick. A world killed with SIGKILL
(or stopped with SIGSTOP) sends nothing: the robot side must stop a robot whose commands
stop (docs/guides/robots.md). Pose ages (since each pose was received, in the run's seconds: wall
seconds times the time scale) are measured at every tick: their maximum and median per agent
are in summary.json's `robots` section, with the delays from the poses' stamps to their
reception (which include any offset between the robot's clock and ours).

Everything that talks to the robots goes through swarm.ros2's `Ros2Node`; the decisions
(`odom_to_world`, `twist_for`, `cmd_type_from`, `PoseAges`) are pure functions and classes.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from swarm.contracts.orbits import wrap
from swarm.contracts.scenario import Scenario
from swarm.contracts.transport import client_config
from swarm.contracts.vocabulary import EventKind
from swarm.robots.config import RobotsError, RobotsFile, RobotSpec, Ros2Spec
from swarm.ros2 import cdr
from swarm.ros2.attachment import gid_for, parse_attachment
from swarm.ros2.keys import EntityInfo
from swarm.ros2.types import ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED, RosType
from swarm.world.core import WorldCore
from swarm.world.kinematics import step_one
from swarm.world.plant import EventSink

NODE_NAME = "swarm_world"  # our node, in the root namespace ("ros2 node list" shows /swarm_world)
CMD_WAIT = 5.0  # s to wait for a robot's subscription token (cmd_type = "auto")
POSE_WAIT = 10.0  # s to wait for every robot's first pose
DISCOVERY_POLL = 0.25  # s between looks at the robots' tokens
STOP_REPEAT = 3  # zero twists sent to each robot at the end (reliable, but a robot must not miss it)
STOP_GAP = 0.02  # s between them
WATCHDOG_PERIOD = 0.05  # s between the watchdog's looks
Pose = tuple[float, float, float]  # x (m), y (m), yaw (rad)


ROBOTS_CLOCK = "realtime"


def robot_scenario(scenario: Scenario, robots: RobotsFile | None = None) -> Scenario:
    """`scenario` as the robot world runs it: the realtime clock, and no agent added while it
    runs (`swarm spawn`: every agent needs a robot of the robots file); with `robots`, each
    agent's speed the one its robot's motors get (`planned_speed`: a whole number of the
    robot's `quantize` steps, within its max_linear), which the world plans with (its
    expected radii) and sends, and its [safety] table, if it has one, in place of the
    scenario's (docs/design/safety.md)."""
    run = scenario.run.model_copy(update={"clock": ROBOTS_CLOCK, "max_added_agents": 0})
    update: dict[str, Any] = {"run": run}
    if robots is not None:
        agents = []
        for a in scenario.agents:
            spec = robots.robot(a.id)
            speed = a.speed if spec is None else planned_speed(a.speed, spec)
            agents.append(a if speed == a.speed else a.model_copy(update={"speed": speed}))
        update["agents"] = agents
        if robots.safety is not None:  # the robots file's [safety] table: the filter for these robots
            update["safety"] = robots.safety
    return scenario.model_copy(update=update)


# -- the pure parts -------------------------------------------------------------------------------
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


def label(spec: RobotSpec) -> str:
    """How errors and events name a robot: "agent 1's robot /tb3_0"."""
    return f"agent {spec.agent}'s robot {spec.namespace or '/'}"


def cmd_type_from(spec: RobotSpec, entities: Sequence[EntityInfo], distro: str, source: str) -> RosType | None:
    """The command type of `spec`'s robot from the subscription tokens seen on its command topic
    (`entities`: anyone's; only subscriptions on that topic count): None while there is none;
    RobotsError (one line naming the robot and the topic) when the robot takes neither Twist nor
    TwistStamped, both, or the type hash of another ROS distribution than [ros2] distro."""
    topic = spec.topic(spec.cmd_topic)
    subs = [e for e in entities if e.kind == "MS" and e.topic == topic]
    if not subs:
        return None
    fits = {e.dds_type for e in subs} & {TWIST.dds, TWIST_STAMPED.dds}
    if not fits:
        other = ", ".join(sorted({e.dds_type for e in subs}))
        raise RobotsError(f"{source}: {label(spec)}: {topic} takes {other}, neither Twist nor TwistStamped")
    if len(fits) > 1:
        raise RobotsError(
            f"{source}: {label(spec)}: {topic} has subscriptions of both Twist and TwistStamped; "
            'set its cmd_type ("Twist" or "TwistStamped")'
        )
    rtype = TWIST if fits == {TWIST.dds} else TWIST_STAMPED
    ours = rtype.hash_for(distro)
    theirs = {e.type_hash for e in subs if e.dds_type == rtype.dds}
    if ours not in theirs:
        other_distro = "humble" if distro != "humble" else "jazzy"
        hint = (
            f'; set [ros2] distro = "{other_distro}"'
            if rtype.hash_for(other_distro) in theirs
            else " (another version of the type)"
        )
        raise RobotsError(
            f"{source}: {label(spec)}: {topic} takes {rtype.short} with type hash {sorted(theirs)[0]}, "
            f'not {ours} as [ros2] distro = "{distro}" writes it{hint}'
        )
    return rtype


NOTICE_EVERY = 5.0  # s between two notices of implausible poses of one robot (the others counted)
ORIGIN_SAMPLES = 200  # odometry poses before tick 0 averaged into the origin (at most)
MAX_SAID = 100  # notices kept for summary.json (its latest 20)
KEPT = 20_000  # the latest pose ages and delays kept per robot for their medians (~0.6 MB each)


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


# -- what the plant asks of swarm.ros2 (Ros2Node; tests give it a fake) ---------------------------
class Publisher(Protocol):
    def put(self, payload: bytes) -> None: ...


class Node(Protocol):
    def publisher(self, topic: str, rtype: RosType) -> Any: ...

    def subscriber(
        self, topic: str, rtype: RosType, on_sample: Callable[..., None], *, with_attachment: bool = False
    ) -> Any: ...

    def remote_entities(
        self, topic: str | None = None, kind: str | None = None, timeout: float = 1.0
    ) -> list[EntityInfo]: ...

    def close(self) -> None: ...


def open_robots_session(connect: str, ros2: Ros2Spec | None = None) -> Any:
    """A zenoh session in client mode on the robots' router (rmw_zenohd forwards only to clients),
    with the robots file's credentials (usrpwd user and password, TLS) for a closed router."""
    import zenoh  # lazy: zenoh's native library, for a world that drives robots only

    identity, tls = ros2.zenoh_settings() if ros2 is not None else (None, {})
    return zenoh.open(client_config(connect, identity=identity, tls=tls))


def ros2_node(session: Any, robots: RobotsFile) -> Node:
    from swarm.ros2.node import Ros2Node  # lazy: node.py imports zenoh; the pure parts above do not need it

    return Ros2Node(session, NODE_NAME, domain=robots.ros2.domain, distro=robots.ros2.distro)


def gid_text(gid: bytes | None) -> str:
    return "no rmw_zenoh attachment" if gid is None else f"GID {gid.hex()[:12]}"


class Robot:
    """One robot as the plant sees it: its spec, start pose, command type and publisher, and its
    latest pose (written by the subscription's callback, in zenoh's thread).

    Trust: the poses of one publisher only, the one whose GID the first pose carried (checked
    against the graph by the plant: rmw_zenoh's GID is the XXH3 of its token); a pose from any
    other GID, or without an attachment, is refused (`foreign`). A pose that implies motion beyond
    the robot's limits since the last accepted one (`Plausible`) is refused (`implausible`): the
    robot then goes stale, and stops, until its poses are plausible again. What the plant must
    say about it goes to `notices` (zenoh's thread appends, the plant's threads say it)."""

    def __init__(
        self,
        spec: RobotSpec,
        start: Pose,
        source: str,
        *,
        time_scale: float = 1.0,
        margin: float = 0.5,
        slack: float = 0.1,
        grace: float = 1.0,
    ):
        self.spec = spec
        self.grace = grace  # run s that stamps may add to the time between two poses' receptions
        self.start = start
        self.source = source
        self.time_scale = time_scale
        self.cmd_type: RosType | None = (
            None if spec.cmd_type == "auto" else (TWIST if spec.cmd_type == "Twist" else TWIST_STAMPED)
        )
        self.pose_type = ODOMETRY if spec.pose == "odom" else POSE_STAMPED
        self.cmd_topic = spec.topic(spec.cmd_topic)
        self.pose_topic = spec.topic(spec.pose_topic_name)
        self.plausible = Plausible(spec.max_linear, spec.max_angular, margin, slack)
        self.publisher: Any = None
        self.latest: tuple[float, Pose] | None = None  # (monotonic s received, world pose)
        self.stamp_ns = 0  # the latest pose's stamp (the robot's wall clock; 0: none)
        self.last_twist = (0.0, 0.0)  # (linear, angular) sent last: what the robot does meanwhile
        self.poses = 0  # received
        self.malformed = 0  # payloads that were no pose of the type
        self.twists = 0  # sent
        self.delays = Spread()  # s from each pose's stamp to its reception (wall clocks)
        self.ages = PoseAges()
        self.odom_origin: Pose | None = None  # the mean odometry pose before tick 0: the odom frame's origin
        self.gid: bytes | None = None  # the robot's pose publisher's (its first pose's)
        self.gid_checked: str | None = None  # how the graph vouched for it (the plant's words)
        self.foreign = 0  # poses refused: another publisher's GID, or no attachment
        self.implausible = 0  # poses refused: beyond the robot's limits
        self.foreign_commands = 0  # samples on its command topic from anyone but us
        self.strangers: dict[bytes | None, int] = {}  # GID -> poses refused of it
        self.cmd_strangers: dict[bytes | None, int] = {}  # GID -> commands of it seen
        self.other_publishers: list[str] = []  # named in the log (their nodes or GIDs)
        self.notices: deque[str] = deque()
        self._origin_samples: list[Pose] = []  # odometry before tick 0: its mean is the origin
        self._origin_frozen = False
        self._our_seq = 0  # the last sequence number of ours seen on the command topic
        self._said_implausible: float | None = None  # when an implausible pose was last said (clock s)
        self._implausible_said = 0  # how many had been refused then
        self._lock = threading.Lock()

    @property
    def limits(self) -> tuple[float, float]:
        return self.spec.max_linear, self.spec.max_angular

    def world_pose(self, pose: cdr.Pose2D, origin: Pose | None = None) -> Pose:
        """The world pose of a pose message: odometry rebased to `origin` (default: the robot's
        odom_origin) and put at the agent's start pose; a mocap pose as it is."""
        if self.spec.pose == "odom":
            odom = (pose.x, pose.y, pose.yaw)
            origin = origin or self.odom_origin or odom
            return odom_to_world(self.start, rebase(origin, odom))
        return pose.x, pose.y, float(wrap(pose.yaw))

    def freeze_origin(self) -> None:
        """Tick 0: the odometry origin is the mean of the poses received so far (the robot
        standing still before the run), and stays so."""
        with self._lock:
            self._origin_frozen = True

    def on_pose(self, payload: bytes, now: float, att: bytes | None = None) -> None:
        try:
            gid: bytes | None = parse_attachment(att)[2] if att is not None else None
        except ValueError:
            gid = None
        decode = cdr.decode_odometry if self.spec.pose == "odom" else cdr.decode_pose_stamped
        with self._lock:
            if gid is None or (self.gid is not None and gid != self.gid):
                self.foreign += 1
                seen = self.strangers.get(gid, 0)
                self.strangers[gid] = seen + 1
                if seen == 0:
                    self.notices.append(
                        f"{self.label()}: a pose on {self.pose_topic} from another publisher than the robot's "
                        f"({gid_text(gid)}): refused, as every one from it will be"
                    )
                return
            try:
                msg = decode(payload)
            except cdr.CdrError:
                self.malformed += 1
                return
            if not all(math.isfinite(v) for v in (msg.x, msg.y, msg.yaw)):
                self.malformed += 1
                return
            odom = (msg.x, msg.y, msg.yaw)
            settling = self.spec.pose == "odom" and not self._origin_frozen
            origin = mean_pose([*self._origin_samples, odom]) if settling else None
            pose = self.world_pose(msg, origin)
            if self.latest is not None:
                why = self.plausible.why_not(self.latest[1], pose, self.elapsed(now, msg.stamp_ns))
                if why is not None:
                    self.implausible += 1
                    if self._said_implausible is None or now - self._said_implausible >= NOTICE_EVERY:
                        more = self.implausible - self._implausible_said - 1
                        since = f" ({more} more since the last said)" if more > 0 else ""
                        self._said_implausible, self._implausible_said = now, self.implausible
                        self.notices.append(f"{self.label()}: a pose on {self.pose_topic} refused: {why}{since}")
                    return
            self.gid = gid
            if settling and origin is not None and len(self._origin_samples) < ORIGIN_SAMPLES:
                self._origin_samples.append(odom)
                self.odom_origin = origin
            self.latest = (now, pose)
            self.stamp_ns = msg.stamp_ns
            self.poses += 1
            if msg.stamp_ns > 0:
                self.delays.add((time.time_ns() - msg.stamp_ns) / 1e9)

    def elapsed(self, now: float, stamp_ns: int) -> float:
        """Run seconds since the last accepted pose, for the plausibility of the next: the time
        between their receptions, or between their stamps when that is longer (poses that
        arrive bunched after a stall of the network or of this process), but never more than
        `grace` s longer (a forged stamp buys no more)."""
        assert self.latest is not None
        received = (now - self.latest[0]) * self.time_scale
        if stamp_ns <= 0 or self.stamp_ns <= 0:
            return received
        stamped = (stamp_ns - self.stamp_ns) / 1e9 * self.time_scale
        return max(received, min(stamped, received + self.grace))

    def on_command_seen(
        self, gid: bytes | None, ours: bytes | None, seq: int | None = None, sent: int | None = None
    ) -> None:
        """A sample on the robot's command topic (any type) with `gid` and `seq` in its
        attachment: not ours (`ours`, of which we have sent `sent` samples), the robot obeys
        someone else too. One that carries our GID with a sequence number we did not send next
        (repeated, or beyond ours) is a copy of our GID."""
        with self._lock:
            if gid is not None and gid == ours:
                if seq is None or sent is None or self._our_seq < seq <= sent:
                    self._our_seq = max(self._our_seq, seq or 0)
                    return
                gid_shown: bytes | None = gid
            else:
                gid_shown = gid
            self.foreign_commands += 1
            seen = self.cmd_strangers.get(gid_shown, 0)
            self.cmd_strangers[gid_shown] = seen + 1
            if seen == 0:
                copy = ", a copy of ours (its sequence numbers are not ours)" if gid == ours else ""
                self.notices.append(
                    f"{self.label()}: commands on {self.cmd_topic} from another publisher ({gid_text(gid)}{copy}): "
                    "the robot obeys them as well as ours"
                )

    def label(self) -> str:
        return f"robot {self.spec.agent} ({self.spec.namespace or '/'})"

    def send(self, vx: float, wz: float) -> None:
        if self.publisher is None or self.cmd_type is None:
            return
        if self.cmd_type == TWIST_STAMPED:
            payload = cdr.encode_twist_stamped(time.time_ns(), "", vx, wz)
        else:
            payload = cdr.encode_twist(vx, wz)
        self.publisher.put(payload)
        self.last_twist = (vx, wz)
        self.twists += 1

    @property
    def refused(self) -> int:
        return self.foreign + self.implausible

    def figures(self) -> dict[str, Any]:
        return {
            "namespace": self.spec.namespace,
            "pose": self.spec.pose,
            "pose_topic": self.pose_topic,
            "cmd_topic": self.cmd_topic,
            "cmd_type": self.cmd_type.short if self.cmd_type is not None else None,
            "quantize": self.spec.quantize,
            "poses": self.poses,
            "malformed_poses": self.malformed,
            # poses refused: from another publisher than the robot's (foreign), or implying motion
            # beyond the robot's limits (implausible)
            "refused_poses": {"foreign": self.foreign, "implausible": self.implausible},
            "foreign_commands": self.foreign_commands,
            "other_publishers": list(self.other_publishers),
            "pose_gid": self.gid.hex() if self.gid is not None else None,
            "pose_gid_checked": self.gid_checked,
            "odom_origin": list(self.odom_origin) if self.odom_origin is not None else None,
            "twists": self.twists,
            **self.ages.figures(),
            # from the poses' stamps to their reception: the transport's latency, plus any offset
            # between the robot's clock and this machine's
            "pose_delay_max": self.delays.high,
            "pose_delay_p50": self.delays.median(),
        }


class RobotPlant:
    """The robots of `robots` as the world's plant for `scenario` (whose agents each have a robot:
    swarm/robots/config.py `check_against`). `source` names the robots file in errors.
    `open_session(connect)` and `make_node(session)` reach the robots (tests pass their own);
    `clock` is monotonic seconds; `time_scale` the run's (ages are in the run's seconds)."""

    def __init__(
        self,
        robots: RobotsFile,
        scenario: Scenario,
        source: str = "<robots>",
        *,
        time_scale: float = 1.0,
        open_session: Callable[[str], Any] | None = None,
        make_node: Callable[[Any], Node] | None = None,
        clock: Callable[[], float] = time.monotonic,
        cmd_wait: float = CMD_WAIT,
        pose_wait: float = POSE_WAIT,
        say: Callable[[str], None] | None = None,
        watchdog: bool = True,
    ):
        self.file = robots
        self.source = source
        self.stale_after = robots.ros2.stale_after
        self.predict = robots.ros2.predict
        self.time_scale = time_scale
        self.open_session = open_session or (lambda connect: open_robots_session(connect, robots.ros2))
        self.make_node = make_node or (lambda session: ros2_node(session, robots))
        self.clock = clock
        self.cmd_wait, self.pose_wait = cmd_wait, pose_wait
        self.say = say or (lambda line: None)
        self.robots: dict[int, Robot] = {}
        for a in scenario.agents:
            spec = robots.robot(a.id)
            if spec is not None:
                self.robots[a.id] = Robot(
                    spec,
                    (a.x, a.y, a.heading),
                    source,
                    time_scale=time_scale,
                    margin=robots.ros2.pose_margin,
                    slack=robots.ros2.pose_slack,
                    grace=2.0 * robots.ros2.stale_after,
                )
        self.session: Any = None
        self.node: Node | None = None
        self.event: EventSink | None = None
        self.stopped = False
        self.watchdog = watchdog
        self.watchdog_stops = 0  # times the watchdog stopped the robots (the world sent nothing for stale_after)
        self._send_lock = threading.Lock()  # the main thread's commands and the watchdog's zeros
        self._moving_since: float | None = None  # clock() of the last commands, None once all were zero
        self._quit = threading.Event()
        self._watch: threading.Thread | None = None
        self._robot_keys: set[str] = set()  # the robots' own pose publishers' tokens
        self._names: dict[bytes, str] = {}  # GID -> node, for the publishers the graph showed
        self.notices: deque[str] = deque()  # the graph watcher's (zenoh's thread), said by ours
        self.said: list[str] = []  # every notice said (the latest MAX_SAID)

    # -- prepare: before the world listens ---------------------------------------------------------
    def prepare(self) -> None:
        """Reach the robots' router, learn each robot's command type, declare our publishers and
        subscriptions, stop every robot, wait for every robot's first pose; RobotsError (one line:
        the robot, the topic) when something is missing."""
        connect = self.file.ros2.connect
        try:
            self.session = self.open_session(connect)
        except RobotsError:
            raise
        except Exception as e:  # zenoh.ZError: nothing answers there (its text ends with a source path)
            why = str(e).split(" at /", 1)[0]
            closed = " (a router closed with usrpwd refuses a wrong or missing [ros2] user and password_file)"
            raise RobotsError(
                f"{self.source}: cannot reach the robots' zenoh router at {connect} ([ros2] connect): {why}"
                + (closed if self.file.ros2.user is not None else "")
            ) from None
        self.node = self.make_node(self.session)
        self._learn_cmd_types()
        node = self.node
        for r in self.robots.values():
            assert r.cmd_type is not None
            r.publisher = node.publisher(r.cmd_topic, r.cmd_type)
            node.subscriber(r.pose_topic, r.pose_type, self._receiver(r), with_attachment=True)
        for r in self.robots.values():
            r.send(0.0, 0.0)  # standing still until the first tick
        self._wait_for_poses()
        self._check_pose_publishers()
        self._watch_the_graph()
        for aid, r in self.robots.items():
            assert r.cmd_type is not None
            self.say(
                f"robot {aid}: {r.spec.namespace or '/'} {r.spec.pose} on {r.pose_topic} -> "
                f"{r.cmd_topic} {r.cmd_type.short}"
            )

    def _receiver(self, r: Robot) -> Callable[..., None]:
        """The subscription's callback for robot `r` (zenoh's thread): its pose, stamped now."""
        return lambda payload, att=None: r.on_pose(payload, self.clock(), att)

    def _check_pose_publishers(self) -> None:
        """The publisher of each robot's poses in the ROS graph: one at most (RobotsError naming
        them when there are more: whose poses would the robot be?), whose GID, the XXH3 of its
        token as rmw_zenoh makes it, the robot's first pose should carry."""
        assert self.node is not None
        pubs = self.node.remote_entities(kind="MP", timeout=1.0)
        for r in self.robots.values():
            mine = [e for e in pubs if e.topic == r.pose_topic]
            if len(mine) > 1:
                names = ", ".join(sorted(self._name(e) for e in mine))
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: {len(mine)} publishers on {r.pose_topic} ({names}): "
                    "one robot's poses come from one publisher (stop the others, or set its pose_topic)"
                )
            if not mine:
                r.gid_checked = "first pose (no publisher token on the topic)"
                self._notice(
                    f"{r.label()}: no publisher of {r.pose_topic} in the ROS graph: trusting the GID of its first pose"
                )
                continue
            e = mine[0]
            self._robot_keys.add(e.key)
            self._names[gid_for(e.key)] = self._name(e)
            if r.gid is not None and r.gid == gid_for(e.key):
                r.gid_checked = f"token of {self._name(e)}"
            else:
                r.gid_checked = f"first pose (not the XXH3 of {self._name(e)}'s token)"
                self._notice(
                    f"{r.label()}: the poses on {r.pose_topic} do not carry the GID of {self._name(e)}'s token "
                    "(XXH3-128, as rmw_zenoh on Jazzy makes it): trusting the GID of its first pose"
                )

    def _watch_the_graph(self) -> None:
        """From now on, name at once every other publisher on a robot's pose or command topic
        (the ROS graph's tokens), and every sample on a command topic that is not ours."""
        node = self.node
        watch, listen = getattr(node, "watch", None), getattr(node, "listen", None)
        if watch is not None:
            watch(self._on_token)
        if listen is not None:
            for r in self.robots.values():
                listen(r.cmd_topic, self._command_watcher(r))

    def _command_watcher(self, r: Robot) -> Callable[[str, bytes, bytes | None], None]:
        def seen(_key: str, _payload: bytes, att: bytes | None) -> None:
            try:
                seq, _, gid = parse_attachment(att) if att is not None else (None, 0, None)
            except ValueError:
                seq, gid = None, None
            r.on_command_seen(gid, getattr(r.publisher, "gid", None), seq, getattr(r.publisher, "seq", None))

        return seen

    @staticmethod
    def _name(e: EntityInfo) -> str:
        ns = e.namespace.rstrip("/")
        return f"{ns}/{e.node} (zid {e.zid})"

    def _on_token(self, key: str, e: EntityInfo, alive: bool) -> None:
        """The graph watcher (zenoh's thread): a publisher on a robot's topic that is not the robot's."""
        if not alive or e.kind != "MP" or key in self._robot_keys:
            return
        name = self._name(e)
        self._names[gid_for(key)] = name
        for r in self.robots.values():
            if e.topic == r.pose_topic:
                what = "its poses are refused"
            elif e.topic == r.cmd_topic:
                what = "the robot obeys it as well as us"
            else:
                continue
            with r._lock:
                if name not in r.other_publishers:
                    r.other_publishers.append(name)
            self._notice(f"{r.label()}: another publisher on {e.topic}: {name}, {e.dds_type}: {what}")

    def _notice(self, line: str) -> None:
        self.notices.append(line)

    def flush_notices(self) -> None:
        """Say what the robots' callbacks and the graph watcher noticed (main or watchdog thread)."""
        for queue in (self.notices, *(r.notices for r in self.robots.values())):
            while True:
                try:
                    line = queue.popleft()
                except IndexError:
                    break
                line = self._named(line)
                self.said.append(line)
                del self.said[:-MAX_SAID]
                self.say(line)

    def _named(self, line: str) -> str:
        """A notice's "GID 0123456789ab" with the name of its node when the graph told us."""
        for gid, name in list(self._names.items()):
            text = f"GID {gid.hex()[:12]}"
            if text in line:
                return line.replace(text, f"{text}, {name}")
        return line

    def _learn_cmd_types(self) -> None:
        """cmd_type = "auto": the type of the robot's own subscription on its command topic."""
        assert self.node is not None
        waiting = [r for r in self.robots.values() if r.cmd_type is None]
        t_end = self.clock() + self.cmd_wait
        while waiting:
            seen = self.node.remote_entities(kind="MS", timeout=min(1.0, max(self.cmd_wait, 0.05)))
            for r in waiting:
                r.cmd_type = cmd_type_from(r.spec, seen, self.file.ros2.distro, self.source)
            waiting = [r for r in waiting if r.cmd_type is None]
            if waiting and self.clock() >= t_end:
                r = waiting[0]
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: nobody subscribes to {r.cmd_topic} (waited {self.cmd_wait:g} s "
                    f"for its token to learn its command type): is the robot up, in namespace "
                    f"{r.spec.namespace or '/'}, on ROS_DOMAIN_ID {self.file.ros2.domain}, behind "
                    f"{self.file.ros2.connect}? (or set its cmd_type)"
                )
            if waiting:
                time.sleep(DISCOVERY_POLL)

    def _wait_for_poses(self) -> None:
        t_end = self.clock() + self.pose_wait
        while True:
            missing = [r for r in self.robots.values() if r.latest is None]
            if not missing:
                return
            if self.clock() >= t_end:
                r = missing[0]
                raise RobotsError(
                    f"{self.source}: {label(r.spec)}: no {r.pose_type.short} on {r.pose_topic} within "
                    f"{self.pose_wait:g} s" + (f" ({r.malformed} malformed)" if r.malformed else "")
                )
            time.sleep(0.02)

    # -- the run ------------------------------------------------------------------------------------
    def start(self, core: WorldCore, event: EventSink) -> None:
        """Before tick 0: the poses of tick 0 are the robots' latest; the watchdog starts."""
        self.event = event
        for r in self.robots.values():
            r.freeze_origin()
        self._read_poses(core)
        if self.watchdog and self._watch is None:
            self._watch = threading.Thread(target=self._watchdog, name="robots-watchdog", daemon=True)
            self._watch.start()

    def step(self, core: WorldCore, u: np.ndarray) -> None:
        """This tick's commands out (zero for an agent gone or a stale robot), then the latest
        poses in."""
        now = self.clock()
        twists: dict[int, tuple[float, float]] = {}
        for aid, r in self.robots.items():
            k = core.index.get(aid)
            if k is None:
                continue
            latest = r.latest
            age = (now - latest[0]) * self.time_scale if latest is not None else math.inf
            change = r.ages.tick(age, self.stale_after)
            if change is not None and self.event is not None:
                self._announce(change, aid, r, age)
            stale = r.ages.stale
            twists[aid] = (
                (0.0, 0.0) if stale else twist_for(float(core.speed[k]), float(u[k]), *r.limits, r.spec.quantize)
            )
        with self._send_lock:
            for aid, (vx, wz) in twists.items():
                self.robots[aid].send(vx, wz)
            moving = any(t != (0.0, 0.0) for t in twists.values())
            self._moving_since = self.clock() if moving else None
        self._read_poses(core)
        self.flush_notices()

    def _watchdog(self) -> None:
        """Every robot stopped when the world has sent no command for stale_after (wall s: the
        run's over the time scale) while they were moving; the next step drives them again."""
        limit = self.stale_after / self.time_scale
        while not self._quit.wait(WATCHDOG_PERIOD):
            self.flush_notices()
            with self._send_lock:
                since = self._moving_since
                if since is None or self.clock() - since <= limit:
                    continue
                for r in self.robots.values():
                    self._quietly(r.send, 0.0, 0.0)
                self._moving_since = None
                self.watchdog_stops += 1
            self.say(f"robots: no command for {limit:g} s (the world stalled): every robot stopped until the next tick")

    def _announce(self, change: str, aid: int, r: Robot, age: float) -> None:
        assert self.event is not None
        if change == EventKind.STALE:
            self.event(
                EventKind.STALE,
                aid,
                f"no pose on {r.pose_topic} for {age:.2f} s (stale_after {self.stale_after:g} s): zero twist",
                age=age if math.isfinite(age) else None,
                topic=r.pose_topic,
            )
        else:
            self.event(
                EventKind.FRESH, aid, f"poses on {r.pose_topic} again ({age:.2f} s old)", age=age, topic=r.pose_topic
            )

    def _read_poses(self, core: WorldCore) -> None:
        x, y, g = core.x.copy(), core.y.copy(), core.heading.copy()
        now_ns = time.time_ns()
        for aid, r in self.robots.items():
            k = core.index.get(aid)
            latest = r.latest
            if k is not None and latest is not None:
                pose = latest[1]
                if self.predict and r.stamp_ns > 0:
                    age = (now_ns - r.stamp_ns) / 1e9 * self.time_scale
                    pose = predicted(pose, r.last_twist, age, self.stale_after)
                x[k], y[k], g[k] = pose
        core.x, core.y, core.heading = x, y, g

    def hold(self) -> None:
        """The clock holds: every robot stands still until the next step."""
        with self._send_lock:
            for r in self.robots.values():
                self._quietly(r.send, 0.0, 0.0)
            self._moving_since = None
        self.flush_notices()

    def stop(self) -> None:
        """Every robot stopped (zero twists, STOP_REPEAT times), then our node and session closed;
        whatever state prepare() got to. A second call does nothing."""
        if self.stopped:
            return
        self.stopped = True
        self._quit.set()
        if self._watch is not None:
            self._watch.join(1.0)
        for i in range(STOP_REPEAT):
            for r in self.robots.values():
                self._quietly(r.send, 0.0, 0.0)
            if i < STOP_REPEAT - 1 and any(r.publisher is not None for r in self.robots.values()):
                time.sleep(STOP_GAP)
        self._quietly(self.flush_notices)
        if self.node is not None:
            self._quietly(self.node.close)
        if self.session is not None:
            self._quietly(self.session.close)

    @staticmethod
    def _quietly(fn: Callable[..., Any], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:  # one robot's (or a closed session's) error must not keep the others going
            pass

    def figures(self) -> dict[str, Any]:
        """summary.json's `robots`: the router, stale_after, and per agent its robot's figures."""
        return {
            "connect": self.file.ros2.connect,
            "domain": self.file.ros2.domain,
            "distro": self.file.ros2.distro,
            "stale_after": self.stale_after,
            "watchdog_stops": self.watchdog_stops,
            # poses refused (another publisher's, or beyond a robot's limits), commands of another
            # publisher seen on a robot's topic, and other publishers named: 0, 0, [] in a clean run
            "refusals": sum(r.refused for r in self.robots.values()),
            "foreign_commands": sum(r.foreign_commands for r in self.robots.values()),
            "other_publishers": sorted({n for r in self.robots.values() for n in r.other_publishers}),
            "notices": list(self.said[-20:]),
            "agents": {str(aid): r.figures() for aid, r in self.robots.items()},
        }
