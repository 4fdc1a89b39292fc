"""One robot as the robots' plant (swarm/robots/plant.py) sees it: `Robot`, its spec, start
pose, command type and publisher and its latest pose, which poses it trusts and what it says
about the others; `cmd_type_from`, a robot's command type from the subscription tokens on its
command topic; and what the plant asks of swarm.ros2 (`Node`: `Ros2Node`, or a test's fake).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from swarm.contracts.orbits import wrap
from swarm.contracts.transport import client_config
from swarm.robots.config import RobotsError, RobotsFile, RobotSpec, Ros2Spec
from swarm.robots.pose import Plausible, Pose, PoseAges, Spread, mean_pose, odom_to_world, rebase
from swarm.ros2 import cdr
from swarm.ros2.attachment import parse_attachment
from swarm.ros2.keys import EntityInfo
from swarm.ros2.types import ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED, RosType

NODE_NAME = "swarm_world"  # our node, in the root namespace ("ros2 node list" shows /swarm_world)
NOTICE_EVERY = 5.0  # s between two notices of implausible poses of one robot (the others counted)
ORIGIN_SAMPLES = 200  # odometry poses before tick 0 averaged into the origin (at most)


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
