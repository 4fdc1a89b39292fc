"""Trust on the robots' network and the robots' hardware details (docs/guides/robots.md#trust,
#quantize): issue 34, items 4 and 5.

- pure: a pose beyond the robot's limits is refused (`Plausible`); a pose of another publisher's
  GID, or without an attachment, is refused and counted, and said once; odometry rebased to the
  robot's first pose; the firmware's steps (`motor_steps`, `quantized`, the fleet's `truncated`),
  the speeds the world plans with and its warning;
- over real zenoh in this process: a second publisher on a robot's pose and command topics is
  named by the plant (its node), its poses refused, its commands counted; a router closed with
  usrpwd and an ACL (the fleet's `--router-config`) refuses a client without credentials and lets
  the world in with the robots file's user and password_file.
"""

from __future__ import annotations

import functools
import json
import math
import threading
import time

import pytest
import zenoh

from swarm.contracts.scenario import parse_scenario
from swarm.contracts.transport import client_config
from swarm.robots import robot as robot_module
from swarm.robots.config import RobotsError, check_against, load_robots, parse_robots
from swarm.robots.fleet import router_config
from swarm.robots.plant import RobotPlant, robot_scenario
from swarm.robots.pose import Plausible, motor_steps, planned_speed, quantized, rebase, twist_for
from swarm.robots.robot import Robot
from swarm.robots.sim_body import truncated
from swarm.ros2 import cdr
from swarm.ros2.attachment import attachment, gid_for
from swarm.ros2.node import Ros2Node
from swarm.ros2.types import ODOMETRY, TWIST
from swarm.runtime.procs import wait_until

SCENARIO = {
    "run": {"dt": 0.05, "duration": 0.2, "clock": "realtime"},
    "gains": {"c1": 0.15, "c2": 0.075},
    "agents": [
        {"id": 1, "role": "leader", "x": 0.7, "y": 0.0, "heading": math.pi / 2, "speed": 0.105, "orbit_radius": 0.7},
        {"id": 2, "role": "follower", "x": 0.87, "y": 0.16, "heading": 2.426, "speed": 0.15},
    ],
}
ROBOTS = {
    "ros2": {"connect": "tcp/127.0.0.1:1", "stale_after": 0.5},
    "robots": [
        {"agent": 1, "namespace": "/tb3_0", "cmd_type": "Twist", "quantize": 0.01},
        {"agent": 2, "namespace": "/tb3_1", "cmd_type": "Twist", "quantize": 0.01},
    ],
}


def odom(x: float, y: float, yaw: float) -> bytes:
    return cdr.encode_odometry(1, "odom", "base_footprint", x, y, yaw)


def robot(**spec) -> Robot:
    file = parse_robots({**ROBOTS, "robots": [{"agent": 1, "namespace": "/tb3_0", **spec}]})
    return Robot(file.robots[0], (0.0, 0.0, 0.0), "r.toml")


OWN, OTHER = gid_for("the robot's token"), gid_for("a stranger's token")


# -- pure: plausibility, foreign GIDs, rebasing ---------------------------------------------------------
def test_a_pose_beyond_the_robots_limits_is_implausible():
    p = Plausible(0.22, 2.84, margin=0.5, slack=0.1)
    assert p.why_not((0, 0, 0), (0.05, 0.0, 0.05), 0.033) is None  # noise-sized
    assert p.why_not((0, 0, 0), (0.3, 0.0, 0.0), 1.0) is None  # 0.3 m in 1 s: 0.33 m/s + 0.1 m allowed
    why = p.why_not((0.7, 0.0, 0.0), (4.0, 5.0, 0.0), 0.05)  # the spoofing run's jump
    assert why is not None and why.startswith("5.991 m and 0.00 rad from the last pose in 0.050 s")
    assert p.why_not((0, 0, 0), (0.0, 0.0, 1.0), 0.05) is not None  # 1 rad in a tick: above 2.84 x 1.5
    assert p.why_not((0, 0, 0), (0.0, 0.0, 1.0), 0.2) is None
    assert p.why_not((0, 0, 3.1), (0, 0, -3.1), 0.01) is None  # across +-pi: a small turn
    assert p.why_not((0, 0, 0), (0.2, 0.0, 0.0), -1.0) is not None  # time backwards: no reach but the slack


def test_the_robot_refuses_poses_of_another_publisher_and_beyond_its_limits_and_counts_them():
    r = robot()
    r.on_pose(odom(0.0, 0.0, 0.0), 10.0, attachment(1, 0, OWN))
    r.freeze_origin()  # tick 0
    assert r.gid == OWN and r.poses == 1
    r.on_pose(odom(0.01, 0.0, 0.0), 10.05, attachment(2, 0, OWN))
    assert r.poses == 2 and r.latest is not None and r.latest[1][0] == pytest.approx(0.01)
    for k in range(5):  # a stranger's poses: refused whatever they say, one notice
        r.on_pose(odom(0.02, 0.0, 0.0), 10.06 + k / 100, attachment(k, 0, OTHER))
    r.on_pose(odom(0.02, 0.0, 0.0), 10.07, None)  # no rmw_zenoh attachment: refused
    r.on_pose(odom(0.02, 0.0, 0.0), 10.07, b"short")  # not one: refused
    assert (r.foreign, r.poses, r.strangers[OTHER], r.strangers[None]) == (7, 2, 5, 2)
    assert r.latest[1][0] == pytest.approx(0.01)
    for k in range(3):  # the robot's GID, 6 m away in a tick: refused, said once in 5 s
        r.on_pose(odom(4.0, 5.0, 0.0), 10.1 + k / 20, attachment(3 + k, 0, OWN))
    assert (r.implausible, r.poses) == (3, 2)
    r.on_pose(odom(0.03, 0.0, 0.0), 10.3, attachment(6, 0, OWN))
    r.on_pose(odom(4.0, 5.0, 0.0), 10.35, attachment(7, 0, OWN))  # within 5 s: counted, not said
    assert (r.implausible, r.poses, r.refused, len(r.notices)) == (4, 3, 11, 3)
    r.on_pose(odom(4.0, 5.0, 0.0), 15.2, attachment(8, 0, OWN))  # 5 s on: said, with the count
    assert r.implausible == 5 and r.notices[-1].endswith("(3 more since the last said)")
    notices = list(r.notices)
    assert len(notices) == 4
    assert notices[0] == (
        f"robot 1 (/tb3_0): a pose on /tb3_0/odom from another publisher than the robot's (GID {OTHER.hex()[:12]}): "
        "refused, as every one from it will be"
    )
    assert "no rmw_zenoh attachment" in notices[1]
    assert notices[2].startswith("robot 1 (/tb3_0): a pose on /tb3_0/odom refused: 6.397 m and 0.00 rad")
    f = r.figures()
    assert f["refused_poses"] == {"foreign": 7, "implausible": 5} and f["pose_gid"] == OWN.hex()


def test_the_origin_is_the_mean_of_the_odometry_before_tick_0():
    """Noisy odometry of a robot standing still: the origin is the mean of the poses before
    tick 0 (its noise averaged out), fixed from tick 0 on."""
    r = Robot(parse_robots(ROBOTS).robots[0], (0.0, 0.0, 0.0), "r.toml")
    for k, (x, yaw) in enumerate([(0.01, 0.1), (-0.01, -0.1), (0.03, 0.3), (-0.03, -0.3)]):
        r.on_pose(odom(x, 0.0, yaw), 10.0 + k / 30, attachment(k + 1, 0, OWN))
    assert r.odom_origin == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    assert r.latest is not None and r.latest[1] == pytest.approx((-0.03, 0.0, -0.3))
    r.freeze_origin()
    r.on_pose(odom(0.05, 0.0, 0.0), 11.0, attachment(9, 0, OWN))
    assert r.odom_origin == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)  # unchanged from tick 0 on
    assert r.latest[1] == pytest.approx((0.05, 0.0, 0.0))


def test_poses_that_arrive_bunched_are_judged_by_their_stamps_within_a_grace():
    """After a stall, poses measured 1 s apart can arrive 2 ms apart: their stamps say how far
    the robot could go; a forged stamp buys at most `grace` s."""
    r = Robot(parse_robots(ROBOTS).robots[0], (0.0, 0.0, 0.0), "r.toml", grace=1.0)

    def at(stamp_s: float, x: float) -> bytes:
        return cdr.encode_odometry(round(stamp_s * 1e9), "odom", "base_footprint", x, 0.0, 0.0)

    r.on_pose(at(100.0, 0.0), 10.0, attachment(1, 0, OWN))
    r.freeze_origin()
    r.on_pose(at(101.0, 0.2), 10.002, attachment(2, 0, OWN))  # 0.2 m in 1 s of stamps: plausible
    assert (r.poses, r.implausible) == (2, 0)
    r.on_pose(at(1000.0, 1.0), 10.004, attachment(3, 0, OWN))  # 900 s of stamps: only 1 s of grace
    assert (r.poses, r.implausible) == (2, 1)
    r.on_pose(at(102.0, 0.35), 11.0, attachment(4, 0, OWN))  # stamps say 1 s, reception 1 s: plausible
    assert r.poses == 3


def test_commands_of_another_publisher_are_counted_and_said_once_per_publisher():
    r = robot()
    for _ in range(3):
        r.on_command_seen(OWN, OWN)  # ours: nothing
    for _ in range(4):
        r.on_command_seen(OTHER, OWN)
    r.on_command_seen(None, OWN)
    assert r.foreign_commands == 5 and len(r.notices) == 2
    assert r.notices[0].endswith("the robot obeys them as well as ours")
    # ours carry our GID and our sequence numbers, in order; a copy of our GID does not
    for seq in (1, 2, 3):
        r.on_command_seen(OWN, OWN, seq, 3)
    assert r.foreign_commands == 5
    r.on_command_seen(OWN, OWN, 2, 3)  # a sequence number already seen
    r.on_command_seen(OWN, OWN, 99, 4)  # one we never sent
    r.on_command_seen(OWN, OWN, 4, 4)  # ours, the next
    assert r.foreign_commands == 7 and len(r.notices) == 3
    assert "a copy of ours (its sequence numbers are not ours)" in r.notices[2]


def test_odometry_is_rebased_to_the_robots_first_pose():
    assert rebase((1.0, 2.0, 0.5), (1.0, 2.0, 0.5)) == pytest.approx((0.0, 0.0, 0.0))
    # 1 m ahead of the first pose, along its heading: 1 m ahead in the rebased frame
    ahead = (1.0 + math.cos(0.5), 2.0 + math.sin(0.5), 0.7)
    assert rebase((1.0, 2.0, 0.5), ahead) == pytest.approx((1.0, 0.0, 0.2))
    r = Robot(parse_robots(ROBOTS).robots[0], (0.7, 0.0, math.pi / 2), "r.toml")
    r.on_pose(odom(1.0, 2.0, 0.5), 10.0, attachment(1, 0, OWN))  # a robot whose odometry did not start at 0
    assert r.latest is not None and r.latest[1] == pytest.approx((0.7, 0.0, math.pi / 2))  # at its start pose
    r.freeze_origin()  # tick 0
    r.on_pose(odom(*ahead), 20.0, attachment(2, 0, OWN))
    assert r.latest[1] == pytest.approx((0.7, 1.0, math.pi / 2 + 0.2))  # 1 m north of the start
    assert r.figures()["odom_origin"] == [1.0, 2.0, 0.5]
    mocap = robot(pose="mocap")
    mocap.on_pose(cdr.encode_pose_stamped(1, "world", 1.0, 2.0, 0.5), 10.0, attachment(1, 0, OWN))
    assert mocap.latest is not None and mocap.latest[1] == pytest.approx((1.0, 2.0, 0.5))  # not rebased


# -- pure: the firmware's steps --------------------------------------------------------------------------
def test_the_firmware_truncates_and_the_world_sends_whole_steps_it_keeps():
    # turtlebot3_node: static_cast<int32_t>(v * 100)
    assert [motor_steps(v, 0.01) for v in (0.105, 0.29, -0.29, 0.15, 0.009, -0.009)] == [10, 28, -28, 15, 0, 0]
    assert truncated(0.105, 0.01) == pytest.approx(0.10) and truncated(0.29, 0.01) == pytest.approx(0.28)
    assert truncated(0.123, 0.0) == 0.123
    # the world's value: the nearest step, written so that the truncation keeps it
    for v in (0.29, -0.29, 0.57, 0.15, 0.1, 1.13, -2.84, 0.004, 0.006, -0.006):
        sent = quantized(v, 0.01, 3.0)
        assert motor_steps(sent, 0.01) == round(v * 100), v
        assert abs(sent - round(v * 100) / 100) < 1e-12
    assert quantized(3.5, 0.01, 2.84) == pytest.approx(2.84) and motor_steps(quantized(3.5, 0.01, 2.84), 0.01) == 284
    assert quantized(0.123, 0.0, 0.22) == 0.123 and quantized(0.3, 0.0, 0.22) == 0.22  # no quantum: saturated
    vx, wz = twist_for(0.105, 0.1549, 0.22, 2.84, 0.01)
    assert (motor_steps(vx, 0.01), motor_steps(wz, 0.01)) == (10, 15)
    assert twist_for(0.105, math.nan, 0.22, 2.84, 0.01) == (0.0, 0.0)


def test_the_world_plans_with_the_speeds_the_motors_get_and_warns():
    file = parse_robots(ROBOTS)
    s = parse_scenario(SCENARIO)
    assert planned_speed(0.105, file.robots[0]) == pytest.approx(0.10)
    assert planned_speed(0.105, parse_robots({**ROBOTS, "robots": [{"agent": 1}]}).robots[0]) == 0.105
    planned = robot_scenario(s, file)
    assert [a.speed for a in planned.agents] == [pytest.approx(0.10), 0.15]
    assert planned.run.clock == "realtime" and [a.speed for a in robot_scenario(s).agents] == [0.105, 0.15]
    warnings = check_against(file, s, "r.toml")
    assert warnings[0] == (
        "agent 1: speed 0.105 m/s is not a whole number of its robot's steps (quantize 0.01): its motors get "
        "0.1 m/s, which the world sends and plans with (expected radii)"
    )
    assert not any("agent 2: speed" in w for w in warnings)


def test_the_credentials_of_a_closed_router_come_from_the_robots_file(tmp_path):
    (tmp_path / "pw").write_text("s3cret\nignored\n")
    path = tmp_path / "robots.toml"
    path.write_text(
        '[ros2]\nconnect = "tcp/127.0.0.1:1"\nuser = "swarm"\npassword_file = "pw"\n\n[[robots]]\nagent = 1\n'
    )
    file = load_robots(path)
    assert file.ros2.password_file == tmp_path / "pw"  # relative to the robots file
    assert file.ros2.zenoh_settings() == (("swarm", "s3cret"), {})
    with pytest.raises(RobotsError, match="user and password_file: give both"):
        parse_robots({**ROBOTS, "ros2": {"user": "swarm"}})
    with pytest.raises(RobotsError, match="TLS needs a tls/HOST:PORT connect"):
        parse_robots({**ROBOTS, "ros2": {"root_ca": "ca.pem"}})
    tls = parse_robots({**ROBOTS, "ros2": {"connect": "tls/h:7447", "root_ca": "/ca.pem"}}).ros2.zenoh_settings()[1]
    assert tls == {"transport/link/tls/root_ca_certificate": "/ca.pem"}
    (tmp_path / "pw").write_text("")
    with pytest.raises(RobotsError, match="no password on its first line"):
        file.ros2.password()


# -- over zenoh, in this process --------------------------------------------------------------------------
class Publishing:
    """A node publishing a pose and twists on robot 1's topics at `rate` Hz until closed."""

    def __init__(self, session, name: str, pose: tuple[float, float, float], rate: float = 50.0, cmd: bool = False):
        self.node = Ros2Node(session, name)
        self.pose_pub = self.node.publisher("/tb3_0/odom", ODOMETRY)
        self.cmd_pub = self.node.publisher("/tb3_0/cmd_vel", TWIST) if cmd else None
        self.pose, self.rate = pose, rate
        self.quit = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.quit.wait(1.0 / self.rate):
            self.pose_pub.put(cdr.encode_odometry(time.time_ns(), "odom", "base_footprint", *self.pose))
            if self.cmd_pub is not None:
                self.cmd_pub.put(cdr.encode_twist(0.22, 2.84))

    def close(self) -> None:
        self.quit.set()
        self.thread.join(2.0)
        self.node.close()


class Robots:
    """A robot per agent (subscribing to its Twist cmd_vel, publishing its odometry)."""

    def __init__(self, session):
        self.nodes = []
        self.pubs = []
        for ns in ("/tb3_0", "/tb3_1"):
            node = Ros2Node(session, "turtlebot3_node", namespace=ns)
            node.subscriber("cmd_vel", TWIST, lambda payload: None)
            self.nodes.append(node)
            self.pubs.append(node.publisher("odom", ODOMETRY))
        self.quit = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.quit.wait(0.02):
            for pub in self.pubs:
                pub.put(cdr.encode_odometry(time.time_ns(), "odom", "base_footprint", 0.0, 0.0, 0.0))

    def close(self) -> None:
        self.quit.set()
        self.thread.join(2.0)
        for node in self.nodes:
            node.close()


@pytest.mark.slow  # zenoh sessions and real time
def test_a_second_publisher_on_a_robots_topics_is_named_its_poses_refused_its_commands_counted(tmp_path):
    ep = f"unixsock-stream/{tmp_path / 'robots.sock'}"
    router = zenoh.open(router_config(ep))
    robot_side = zenoh.open(client_config(ep))
    stranger_side = zenoh.open(client_config(ep))
    robots = Robots(robot_side)
    said: list[str] = []
    plant = RobotPlant(
        parse_robots({**ROBOTS, "ros2": {**ROBOTS["ros2"], "connect": ep}}),
        parse_scenario(SCENARIO),
        "r.toml",
        say=said.append,
    )
    stranger = None
    try:
        plant.prepare()
        one = plant.robots[1]
        assert one.gid == gid_for(robots.pubs[0].token_key)  # rmw_zenoh's GID: the XXH3 of its token
        assert one.gid_checked is not None and one.gid_checked.startswith("token of /tb3_0/turtlebot3_node")
        assert not [line for line in said if "another" in line]
        stranger = Publishing(stranger_side, "intruder", (4.0, 5.0, 0.0), cmd=True)
        named = lambda: [line for line in said if "/intruder" in line]  # noqa: E731
        assert wait_until(lambda: plant.flush_notices() or len(named()) >= 4, 10.0), said
        assert wait_until(lambda: one.foreign >= 10 and one.foreign_commands >= 10, 10.0)
        text = "\n".join(named())
        assert "robot 1 (/tb3_0): another publisher on /tb3_0/odom: /intruder (zid " in text
        assert "its poses are refused" in text
        assert "another publisher on /tb3_0/cmd_vel: /intruder" in text and "the robot obeys it" in text
        assert f"GID {stranger.pose_pub.gid.hex()[:12]}, /intruder" in text  # its samples, named by their GID
        assert one.latest is not None and one.latest[1] == pytest.approx((0.7, 0.0, math.pi / 2))  # never moved
        assert plant.robots[2].refused == 0 and plant.robots[2].foreign_commands == 0
        f = plant.figures()
        assert f["refusals"] == one.foreign and f["other_publishers"] == [n for n in one.other_publishers]
        assert f["agents"]["1"]["refused_poses"]["foreign"] >= 10 and f["agents"]["1"]["foreign_commands"] >= 10
    finally:
        if stranger is not None:
            stranger.close()
        plant.stop()
        robots.close()
        stranger_side.close()
        robot_side.close()
        router.close()


@pytest.mark.slow  # zenoh sessions and real time
def test_two_publishers_of_a_robots_poses_at_start_are_refused_naming_them(tmp_path):
    ep = f"unixsock-stream/{tmp_path / 'robots.sock'}"
    router = zenoh.open(router_config(ep))
    side = zenoh.open(client_config(ep))
    robots = Robots(side)
    other = Publishing(side, "second_odom", (0.0, 0.0, 0.0))
    plant = RobotPlant(
        parse_robots({**ROBOTS, "ros2": {**ROBOTS["ros2"], "connect": ep}}), parse_scenario(SCENARIO), "r.toml"
    )
    try:
        with pytest.raises(RobotsError, match=r"2 publishers on /tb3_0/odom \(/second_odom .*/tb3_0/turtlebot3_node"):
            plant.prepare()
    finally:
        plant.stop()
        other.close()
        robots.close()
        side.close()
        router.close()


@pytest.mark.slow  # zenoh sessions
def test_a_router_closed_with_usrpwd_and_an_acl_refuses_a_stranger_and_lets_the_world_in(tmp_path, monkeypatch):
    users = tmp_path / "users.txt"
    users.write_text("swarm:pw-of-swarm\n")
    acl_rule = {
        "id": "ros",
        "permission": "allow",
        "flows": ["ingress", "egress"],
        "messages": ["put", "delete", "declare_subscriber", "query", "reply", "liveliness_token"]
        + ["declare_liveliness_subscriber", "liveliness_query", "declare_queryable"],
        "key_exprs": ["0/**", "@ros2_lv/0/**"],
    }
    config = {
        "transport": {"auth": {"usrpwd": {"dictionary_file": str(users)}}},
        "access_control": {
            "enabled": True,
            "default_permission": "deny",
            "rules": [acl_rule],
            "subjects": [{"id": "fleet", "usernames": ["swarm"]}],
            "policies": [{"rules": ["ros"], "subjects": ["fleet"]}],
        },
    }
    (tmp_path / "router.json5").write_text(json.dumps(config))
    ep = f"unixsock-stream/{tmp_path / 'robots.sock'}"
    router = zenoh.open(router_config(ep, str(tmp_path / "router.json5")))
    robots = Robots(router)  # the robots on the router's own session (the fleet's way)
    (tmp_path / "pw").write_text("pw-of-swarm\n")
    path = tmp_path / "robots.toml"
    path.write_text(
        f'[ros2]\nconnect = "{ep}"\nuser = "swarm"\npassword_file = "pw"\n\n'
        '[[robots]]\nagent = 1\nnamespace = "/tb3_0"\ncmd_type = "Twist"\n\n'
        '[[robots]]\nagent = 2\nnamespace = "/tb3_1"\ncmd_type = "Twist"\n'
    )
    plant = RobotPlant(load_robots(path), parse_scenario(SCENARIO), str(path))
    try:
        with pytest.raises(zenoh.ZError):
            zenoh.open(client_config(ep, timeout_ms=1500)).close()  # no credentials: refused at connect
        plant.prepare()  # the world with the robots file's user and password_file: in
        assert plant.robots[1].poses > 0 and plant.robots[2].poses > 0
        wrong = path.with_name("wrong.toml")
        (tmp_path / "bad").write_text("not-the-password\n")
        wrong.write_text(path.read_text().replace('password_file = "pw"', 'password_file = "bad"'))
        other = RobotPlant(load_robots(wrong), parse_scenario(SCENARIO), str(wrong))
        # the refused session waits out its connect timeout: 1.5 s as the stranger's, not the 10 s
        # default (the product's own open_robots_session, credentials and all, with a shorter wait)
        monkeypatch.setattr(robot_module, "client_config", functools.partial(client_config, timeout_ms=1500))
        with pytest.raises(RobotsError, match="cannot reach the robots' zenoh router .* refuses a wrong or missing"):
            other.prepare()
        other.stop()
    finally:
        plant.stop()
        robots.close()
        router.close()
