"""Interop with ROBOTIS' zenoh-ros2-sdk (an independent Python implementation of rmw_zenoh's
protocol, rosbags for CDR) playing the robots: TurtleBots whose node `turtlebot3_node` in their
namespace subscribes to cmd_vel (Twist or TwistStamped) and publishes Odometry, driven by our
robot world. The SDK robots hear our twists and see our node in their graph; our world reads
their odometry. tests/zenoh/test_ros2_node.py has the other way round (the SDK as the world, our
node as the robot).

Offline: the SDK looks for its message definitions in its registry's directory before it would
git-clone ros2/common_interfaces; the fixture writes them there from rosbags' Jazzy store.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
import zenoh
import zenoh_ros2_sdk
import zenoh_ros2_sdk.message_registry
from deadlines import DEADLINE
from fleet_support import free_port, robots_file, write_robots
from ros2_sdk_offline import sdk_offline
from runtime_helpers import SCENARIOS, start_up, wait_for

from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.robots.config import parse_robots
from swarm.robots.fleet import router_config
from swarm.robots.plant import RobotPlant
from swarm.robots.robot import NODE_NAME
from swarm.robots.sim_body import Unicycle, world_pose
from swarm.ros2.types import ODOMETRY, TWIST, TWIST_STAMPED
from swarm.world.core import WorldCore

pytestmark = pytest.mark.slow  # zenoh sessions and zenoh-ros2-sdk's own

TURTLEBOT = SCENARIOS / "turtlebot.toml"
BURGER = (0.22, 2.84)
NS = 1_000_000_000


@pytest.fixture
def robots_router(tmp_path, monkeypatch):
    """A zenoh router on a free TCP port standing in for rmw_zenohd (its endpoint); the SDK's
    process-wide session will connect to it as a client, with message definitions from rosbags
    and its git cache in the tmp dir (which must stay unused)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(router_config(endpoint))
    sdk_offline(monkeypatch, tmp_path, endpoint, [TWIST.name, TWIST_STAMPED.name, ODOMETRY.name])
    try:
        yield endpoint
    finally:
        if zenoh_ros2_sdk.ZenohSession._instance is not None:
            zenoh_ros2_sdk.ZenohSession._instance.close()
        router.close()
        assert not (tmp_path / "cache").exists(), "the SDK tried to fetch message definitions"


class SdkRobot:
    """A TurtleBot3 Burger played by the SDK: `turtlebot3_node` in `namespace` takes `cmd_type`
    on cmd_vel and publishes Odometry on odom ("odom" -> "base_footprint") at `rate` Hz from a
    unicycle in its odom frame (the fleet's body: saturated, stopped by a 0.5 s watchdog)."""

    def __init__(self, namespace: str, cmd_type: str, rate: float = 30.0):
        self.namespace, self.stamped = namespace, cmd_type == TWIST_STAMPED.name
        self.body = Unicycle(0.0, 0.0, 0.0, *BURGER, t=time.monotonic())
        self.lock = threading.Lock()
        self.twists: list[tuple[float, float]] = []  # as received
        self.published: list[tuple[float, float, float]] = []  # odom-frame poses sent
        self.sub = zenoh_ros2_sdk.ROS2Subscriber(
            topic=f"{namespace}/cmd_vel",
            msg_type=cmd_type,
            callback=self._on_twist,
            node_name="turtlebot3_node",
            namespace=namespace,
        )
        self.pub = zenoh_ros2_sdk.ROS2Publisher(
            topic=f"{namespace}/odom", msg_type=ODOMETRY.name, node_name="turtlebot3_node", namespace=namespace
        )
        self.T = self.pub.session_mgr.store.types
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(1.0 / rate,), daemon=True)
        self.thread.start()

    def _on_twist(self, msg) -> None:
        twist = msg.twist if self.stamped else msg
        vx, wz = float(twist.linear.x), float(twist.angular.z)
        with self.lock:
            self.body.command(time.monotonic(), vx, wz)
            self.twists.append((vx, wz))

    def _odometry(self, x: float, y: float, yaw: float, vx: float, wz: float) -> dict:
        T, now = self.T, time.time_ns()
        vec = T["geometry_msgs/msg/Vector3"]
        return {
            "header": T["std_msgs/msg/Header"](
                stamp=T["builtin_interfaces/msg/Time"](sec=now // NS, nanosec=now % NS), frame_id="odom"
            ),
            "child_frame_id": "base_footprint",
            "pose": T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                    ),
                ),
                covariance=np.zeros(36),
            ),
            "twist": T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=vec(x=vx, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=wz)),
                covariance=np.zeros(36),
            ),
        }

    def _run(self, period: float) -> None:
        while not self.stop.is_set():
            with self.lock:
                self.body.advance(time.monotonic())
                pose, twist = self.body.pose(), self.body.twist()
                self.published.append(pose)
            self.pub.publish(**self._odometry(*pose, *twist))
            self.stop.wait(period)

    def received(self) -> list[tuple[float, float]]:
        with self.lock:
            return list(self.twists)

    def poses(self) -> list[tuple[float, float, float]]:
        with self.lock:
            return list(self.published)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.pub.close()
        self.sub.close()


@pytest.fixture
def sdk_robots(robots_router):
    """(the router's endpoint, {agent: SdkRobot}): agent 1's robot takes TwistStamped (Jazzy's
    TurtleBot3 bringup), agent 2's Twist (Humble's)."""
    robots = {1: SdkRobot("/tb3_0", TWIST_STAMPED.name), 2: SdkRobot("/tb3_1", TWIST.name)}
    try:
        yield robots_router, robots
    finally:
        for r in robots.values():
            r.close()


def publishers_of(topic: str) -> list[tuple[str, str]]:
    """(node, namespace) of every publisher of `topic` in the SDK's graph."""
    info = zenoh_ros2_sdk.get_topic_info(topic, timeout=0.5, verbose=True)
    return [] if info is None else [(e.node_name, e.node_namespace) for e in info.publishers]


def test_our_robot_plant_drives_sdk_robots(sdk_robots):
    endpoint, sdk = sdk_robots
    scenario = load_scenario(TURTLEBOT)
    starts = {a.id: (a.x, a.y, a.heading) for a in scenario.agents}
    plant = RobotPlant(parse_robots(robots_file(endpoint)), scenario, "robots.toml")
    try:
        plant.prepare()  # cmd types from the SDK robots' own subscription tokens; their first odometry
        figures = plant.figures()["agents"]
        assert (figures["1"]["cmd_type"], figures["2"]["cmd_type"]) == ("TwistStamped", "Twist")
        # our node in the SDK's graph: the publisher of each robot's cmd_vel
        for ns in ("/tb3_0", "/tb3_1"):
            assert wait_for(lambda ns=ns: (NODE_NAME, "/") in publishers_of(f"{ns}/cmd_vel"), DEADLINE, "our node")
        topics = dict(zenoh_ros2_sdk.get_topic_names_and_types(timeout=0.5))
        assert topics["/tb3_0/cmd_vel"] == [TWIST_STAMPED.name] and topics["/tb3_1/cmd_vel"] == [TWIST.name]
        wait_for(lambda: sdk[1].received() and sdk[2].received(), DEADLINE, "the zero twists before tick 0")
        assert sdk[1].received()[0] == sdk[2].received()[0] == (0.0, 0.0)

        core = WorldCore(scenario, plant=plant)
        plant.start(core, lambda *a, **k: None)
        assert core.pose(1) == pytest.approx(starts[1]) and core.pose(2) == pytest.approx(starts[2])
        core.set_command(1, 0.15)
        core.set_command(2, -4.0)  # above the Burger's 2.84 rad/s

        def moved() -> bool:
            core.step()  # the commands out, the SDK robots' latest poses in
            return math.dist(core.pose(1)[:2], starts[1][:2]) > 0.02 and sdk[2].received()[-1] != (0.0, 0.0)

        wait_for(moved, DEADLINE, "the SDK robots to move", interval=0.05)
        assert sdk[1].received()[-1] == pytest.approx((0.10, 0.15))
        assert sdk[2].received()[-1] == pytest.approx((0.15, -2.84))
        for aid in (1, 2):  # our world's pose is one the SDK robot published, from the agent's start pose
            seen = [world_pose(starts[aid], p) for p in sdk[aid].poses()]
            assert min(math.dist(core.pose(aid)[:2], p[:2]) for p in seen) < 1e-9
        assert plant.figures()["agents"]["1"]["poses"] > 0 and plant.figures()["agents"]["1"]["malformed_poses"] == 0
    finally:
        plant.stop()
    for aid in (1, 2):
        wait_for(
            lambda aid=aid: sdk[aid].received()[-1] == (0.0, 0.0), DEADLINE, f"robot {aid}'s zero twist at the end"
        )
    assert wait_for(
        lambda: NODE_NAME not in dict(publishers_of("/tb3_0/cmd_vel")), DEADLINE, "our node to leave the graph"
    )


@pytest.mark.slow
def test_swarm_up_drives_sdk_robots(sdk_robots, rt, tmp_path):
    """The turtlebot scenario run by `swarm up --robots` with the SDK playing both robots."""
    endpoint, sdk = sdk_robots
    robots = write_robots(tmp_path / "robots.toml", robots_file(endpoint))
    # 8 s (was 10 s): 160 commands a robot at 20 Hz; `swarm sim`'s leader ends 0.75 m and its
    # follower 1.20 m from where they started (0.91 m and 1.50 m at 10 s)
    up = start_up(rt.tracker, TURTLEBOT, tmp_path / "run", "--robots", robots, "--duration", 8)
    assert up.launcher.wait(120) == ExitCode.OK, up.launcher.text()[-3000:] + up.world_text()[-3000:]
    rt.tracker.assert_none_left()
    for aid in (1, 2):
        wait_for(
            lambda aid=aid: sdk[aid].received()[-1] == (0.0, 0.0), DEADLINE, f"robot {aid}'s zero twist at the end"
        )
        moving = [t for t in sdk[aid].received() if t != (0.0, 0.0)]
        assert len(moving) > 100, f"robot {aid}: {len(moving)} motion commands"
    summary, traj = up.summary(), up.trajectory()
    figures = summary["robots"]["agents"]
    assert (figures["1"]["cmd_type"], figures["2"]["cmd_type"]) == ("TwistStamped", "Twist")
    assert figures["1"]["poses"] > 0 and figures["2"]["poses"] > 0
    # the recording holds the SDK robots' poses (their odometry from each agent's start pose)
    scenario = load_scenario(TURTLEBOT)
    for k, aid in enumerate(int(i) for i in traj["ids"]):
        a = next(a for a in scenario.agents if a.id == aid)
        published = np.array([world_pose((a.x, a.y, a.heading), p)[:2] for p in sdk[aid].poses()])
        recorded = np.stack([traj["x"][:, k], traj["y"][:, k]], axis=1)
        gap = np.min(np.hypot(*(recorded[:, None, :] - published[None, :, :]).transpose(2, 0, 1)), axis=1)
        assert gap.max() < 1e-6, f"agent {aid}: a recorded pose the SDK robot never published ({gap.max():g} m)"
        assert math.dist(recorded[0], recorded[-1]) > 0.5  # 8 s at 0.10 / 0.15 m/s
