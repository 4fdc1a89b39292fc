"""The simulated fleet (swarm/robots/fleet.py): the robot's body (unicycle, saturation, the
command watchdog), the latency of its poses, their noise and frames; then the fleet over real
zenoh, as `swarm robots sim` runs it."""

from __future__ import annotations

import math
import signal
import socket
import statistics
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
import zenoh
from deadlines import DEADLINE
from fleet_support import client, free_port, robots_file, write_robots
from runtime_helpers import SCENARIOS, swarm_cmd, wait_for

from swarm.contracts.orbits import wrap
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.robots.config import parse_robots
from swarm.robots.fleet import Fleet, FleetError, FleetOptions, router_config
from swarm.robots.sim_body import Delayed, PoseNoise, Unicycle, odom_pose, saturate, world_pose
from swarm.ros2 import cdr
from swarm.ros2.attachment import parse_attachment
from swarm.ros2.node import Ros2Node
from swarm.ros2.types import ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED
from swarm.world.kinematics import step_one

pytestmark = pytest.mark.slow  # zenoh sessions and `swarm robots sim` processes

BURGER = (0.22, 2.84)
TURTLEBOT = SCENARIOS / "turtlebot.toml"


def close(a, b, tol=1e-12):
    return all(abs(p - q) <= tol for p, q in zip(a, b, strict=True))


# -- the body ----------------------------------------------------------------------------------------
def test_saturation_clips_at_the_limits_and_stops_on_nan():
    assert saturate(0.5, 0.22) == 0.22
    assert saturate(-3.0, 2.84) == -2.84
    assert saturate(0.1, 0.22) == 0.1
    assert saturate(math.nan, 0.22) == 0.0 and saturate(math.inf, 1.0) == 0.0
    body = Unicycle(0.0, 0.0, 0.0, *BURGER, cmd_timeout=10.0)
    body.command(0.0, 1.0, -5.0)
    assert body.twist() == (0.22, -2.84)
    body.command(0.1, math.nan, 0.5)
    assert body.twist() == (0.0, 0.5)


def test_a_body_without_a_command_stands_still():
    body = Unicycle(1.0, 2.0, 0.3, *BURGER)
    body.advance(100.0)
    assert body.pose() == (1.0, 2.0, 0.3) and body.twist() == (0.0, 0.0) and body.t == 100.0


def test_a_held_command_is_the_worlds_exact_arc():
    body = Unicycle(0.5, -0.2, 1.0, *BURGER, cmd_timeout=100.0)
    body.command(0.0, 0.15, 0.3)
    for k in range(1, 31):
        body.advance(k / 30)
    expected = (0.5, -0.2, 1.0)
    for _ in range(30):
        expected = step_one(*expected, 0.15, 0.3, 1 / 30)
    assert close(body.pose(), expected, 1e-12)
    # a full circle brings it back: radius v / w
    ring = Unicycle(0.0, 0.0, 0.0, *BURGER, cmd_timeout=100.0)
    ring.command(0.0, 0.2, 0.5)
    ring.advance(2 * math.pi / 0.5)
    assert close(ring.pose(), (0.0, 0.0, 0.0), 1e-9)
    half = Unicycle(0.0, 0.0, 0.0, *BURGER, cmd_timeout=100.0)
    half.command(0.0, 0.2, 0.5)
    half.advance(math.pi / 0.5)  # half way round: the far side of a circle of radius 0.4
    assert close(half.pose(), (0.0, 0.8, math.pi), 1e-9)


def test_commands_take_effect_piecewise_at_their_times():
    body = Unicycle(0.0, 0.0, 0.0, *BURGER, cmd_timeout=100.0)
    body.command(0.0, 0.1, 0.0)
    body.command(2.0, 0.1, 1.0)  # straight for 2 s, then turning
    body.advance(3.0)
    expected = step_one(0.2, 0.0, 0.0, 0.1, 1.0, 1.0)
    assert close(body.pose(), expected, 1e-12)
    # a command from before the body's time counts from the body's time
    body.command(1.0, 0.0, 0.0)
    assert body.t == 3.0 and close(body.pose(), expected, 1e-12)


def test_the_watchdog_stops_a_robot_whose_command_is_too_old():
    body = Unicycle(0.0, 0.0, 0.0, *BURGER, cmd_timeout=0.5)
    body.command(1.0, 0.2, 0.0)
    body.advance(1.25)
    assert body.twist() == (0.2, 0.0) and close(body.pose(), (0.05, 0.0, 0.0))
    body.advance(10.0)  # moved for 0.5 s only
    assert body.twist() == (0.0, 0.0) and close(body.pose(), (0.1, 0.0, 0.0))
    body.command(10.0, 0.2, 0.0)  # a fresh command moves it again
    body.advance(10.1)
    assert close(body.pose(), (0.12, 0.0, 0.0))
    body.command(10.1, 0.0, 0.0)  # a zero twist stops it at once
    body.advance(10.4)
    assert close(body.pose(), (0.12, 0.0, 0.0))


# -- frames, noise, latency -------------------------------------------------------------------------
def test_the_odom_frame_starts_at_the_start_pose():
    start = (0.87, 0.16, 2.426)
    assert close(odom_pose(start, start), (0.0, 0.0, 0.0))
    ahead = (start[0] + math.cos(start[2]), start[1] + math.sin(start[2]), start[2] + 0.5)
    assert close(odom_pose(start, ahead), (1.0, 0.0, 0.5), 1e-12)
    left = (start[0] - math.sin(start[2]), start[1] + math.cos(start[2]), start[2])
    assert close(odom_pose(start, left), (0.0, 1.0, 0.0), 1e-12)
    for pose in [(3.0, -1.0, 3.1), (-0.4, 0.2, -2.9), start]:
        assert close(world_pose(start, odom_pose(start, pose)), (pose[0], pose[1], wrap(pose[2])), 1e-12)


def test_pose_noise_is_seeded_and_of_its_size():
    assert PoseNoise(0.0, 0.0, seed=1).apply((1.0, 2.0, 0.5)) == (1.0, 2.0, 0.5)
    a, b = PoseNoise(0.01, 0.05, seed=7), PoseNoise(0.01, 0.05, seed=7)
    samples = [a.apply((1.0, 2.0, 0.5)) for _ in range(4000)]
    assert samples == [b.apply((1.0, 2.0, 0.5)) for _ in range(4000)]
    assert samples[:3] != [PoseNoise(0.01, 0.05, seed=8).apply((1.0, 2.0, 0.5)) for _ in range(3)]
    xs, ys, yaws = zip(*samples, strict=True)
    assert statistics.pstdev(xs) == pytest.approx(0.01, rel=0.1)
    assert statistics.pstdev(ys) == pytest.approx(0.01, rel=0.1)
    assert statistics.pstdev(yaws) == pytest.approx(0.05, rel=0.1)
    assert statistics.fmean(xs) == pytest.approx(1.0, abs=0.001)


def test_yaw_noise_defaults_to_the_pose_noise_over_its_baseline():
    assert FleetOptions(pose_noise=0.01).yaw_sigma == pytest.approx(0.05)
    assert FleetOptions(pose_noise=0.01, yaw_noise=0.2).yaw_sigma == 0.2
    bad_ones = (
        {"rate": 0.0},
        {"latency": -1.0},
        {"time_scale": math.inf},
        {"cmd_timeout": math.nan},
        {"stop_poses": {2: -1}},
    )
    for bad in bad_ones:
        with pytest.raises(ValueError, match=next(iter(bad))):
            FleetOptions(**bad)


def test_delayed_items_come_out_in_order_at_their_time():
    q: Delayed[str] = Delayed(0.03)
    assert q.due(100.0) == [] and q.next_time() is None
    q.push(1.0, "a")
    q.push(1.02, "b")
    q.push(1.04, "c")
    assert q.next_time() == pytest.approx(1.03)
    assert q.due(1.029) == []
    assert q.due(1.05) == ["a", "b"] and len(q) == 1
    assert q.due(2.0) == ["c"] and len(q) == 0
    none: Delayed[int] = Delayed(0.0)
    none.push(5.0, 1)
    assert none.due(5.0) == [1]


# -- the fleet's loop, stepped by hand (no session) ---------------------------------------------------------


def test_poses_are_published_their_latency_after_they_were_measured():
    lines: list[str] = []
    fleet = Fleet(
        parse_robots(robots_file()), load_scenario(TURTLEBOT), FleetOptions(latency=0.03, rate=10), lines.append
    )
    r = fleet.robots[0]
    assert fleet.step(0.0) == pytest.approx(0.03)  # measured now, out at 0.03
    assert r.published == 0 and len(r.poses) == 1
    fleet.step(0.029)
    assert r.published == 0
    assert fleet.step(0.03) == pytest.approx(0.1)  # out; the next measurement at 0.1
    assert r.published == 1 and len(r.poses) == 0
    fleet.step(0.25)  # late: one measurement (no burst), the next one at the next multiple of the period
    assert len(r.poses) == 1 and r.next_pose == pytest.approx(0.3)
    assert lines == []


def test_a_robot_told_to_stop_its_poses_stops_them_and_says_so():
    lines: list[str] = []
    options = FleetOptions(rate=10, stop_poses={2: 0.5})
    fleet = Fleet(parse_robots(robots_file()), load_scenario(TURTLEBOT), options, lines.append)
    one, two = fleet.robots
    for k in range(11):
        fleet.step(k * fleet.period)
    assert one.published == two.published == 11  # no motion yet: the run has not started
    two.inbox.append((1.0, 0.0, 0.0))  # a zero twist (the world stopping every robot before its start)
    one.inbox.append((1.05, 0.1, 0.0))  # the run's first motion command: 0.5 s from then
    for k in range(11, 21):
        fleet.step(k * fleet.period)
    assert one.published == 21 and two.published == 16
    assert lines == ["robot 2: poses stopped at t=1.600 s (--stop-poses)"]
    with pytest.raises(FleetError, match="agent 7"):
        Fleet(parse_robots(robots_file()), load_scenario(TURTLEBOT), FleetOptions(stop_poses={7: 1.0}))


def test_commands_move_the_body_and_the_report_says_how_it_was_left():
    fleet = Fleet(parse_robots(robots_file()), load_scenario(TURTLEBOT), FleetOptions(rate=10, cmd_timeout=5.0))
    one, two = fleet.robots
    assert one.describe() == "robot 1: /tb3_0 odom -> cmd_vel Twist"
    one.inbox.append((0.0, 1.0, 0.0))  # saturated at 0.22
    fleet.step(0.0)
    fleet.step(1.0)
    assert close(odom_pose(one.start, one.body.pose()), (0.22, 0.0, 0.0), 1e-12)
    one.inbox.append((1.0, 0.0, 0.0))
    fleet.step(2.0)
    assert close(odom_pose(one.start, one.body.pose()), (0.22, 0.0, 0.0), 1e-12)
    assert one.report().endswith("last command linear 0, angular 0; stopped by a zero twist at t=1.000 s")
    two.inbox.append((2.0, 0.1, 0.0))
    fleet.step(2.1)
    assert two.report().endswith("NO zero twist after its last motion command")


# -- the fleet over zenoh -----------------------------------------------------------------------------------


@contextmanager
def running_fleet(data: dict, options: FleetOptions) -> Iterator[tuple[Fleet, zenoh.Session]]:
    """A fleet in a thread of this process, on its own router; (the fleet, a client session to it)."""
    router = zenoh.open(router_config(data["ros2"]["connect"]))
    fleet = Fleet(parse_robots(data), load_scenario(TURTLEBOT), options, out=lambda _line: None)
    fleet.open(router)
    stop = threading.Event()
    loop = threading.Thread(target=fleet.run, args=(stop,), daemon=True)
    loop.start()
    session = client(data["ros2"]["connect"])
    try:
        yield fleet, session
    finally:
        session.close()
        stop.set()
        loop.join(10)
        fleet.close()
        router.close()


class Samples:
    """What a subscriber received, kept for waits and checks."""

    def __init__(self, decode):
        self.decode, self.items, self.lock = decode, [], threading.Lock()

    def __call__(self, payload: bytes) -> None:
        with self.lock:
            self.items.append(self.decode(payload))

    def __len__(self) -> int:
        with self.lock:
            return len(self.items)

    def last(self):
        with self.lock:
            return self.items[-1]

    def since(self, k: int) -> list:
        with self.lock:
            return self.items[k:]


def test_the_fleet_speaks_ros2_and_its_robots_follow_their_twists():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    data = robots_file(endpoint, cmd_type="TwistStamped", pose="mocap")
    with running_fleet(data, FleetOptions(rate=50)) as (fleet, session), Ros2Node(session, "tester") as node:
        # the graph: each robot's subscription and publisher, in its namespace, of its types
        ents = wait_for(
            lambda: len(node.remote_entities(kind="MS")) == 2 and node.remote_entities(), DEADLINE, "the tokens"
        )
        seen = {(e.kind, e.namespace, e.node, e.topic, e.dds_type) for e in ents if e.kind in ("MP", "MS")}
        assert seen == {
            ("MS", "/tb3_0", "sim_robot", "/tb3_0/cmd_vel", TWIST.dds),
            ("MP", "/tb3_0", "sim_robot", "/tb3_0/odom", ODOMETRY.dds),
            ("MS", "/tb3_1", "sim_robot", "/tb3_1/cmd_vel", TWIST_STAMPED.dds),
            ("MP", "/tb3_1", "sim_robot", "/tb3_1/pose", POSE_STAMPED.dds),
        }
        assert all(e.qos_text == "::,10:,:,:,," for e in ents if e.kind in ("MP", "MS"))
        # poses: odometry from the start pose's origin; mocap in the world frame
        odom, mocap = Samples(cdr.decode_odometry), Samples(cdr.decode_pose_stamped)
        node.subscriber("/tb3_0/odom", ODOMETRY, odom)
        node.subscriber("/tb3_1/pose", POSE_STAMPED, mocap)
        wait_for(lambda: len(odom) and len(mocap), DEADLINE, "the first poses")
        first = odom.last()
        assert (first.frame_id, first.x, first.y, first.yaw) == ("odom", 0.0, 0.0, 0.0)
        agent2 = load_scenario(TURTLEBOT).agents[1]
        p = mocap.last()
        assert p.frame_id == "world" and close((p.x, p.y, p.yaw), (agent2.x, agent2.y, agent2.heading), 1e-9)
        # commands: robot 1 drives straight on at its limit, robot 2 stays (a Twist on its
        # TwistStamped topic is not for it); then a zero twist stops robot 1 where it is
        cmd1 = node.publisher("/tb3_0/cmd_vel", TWIST)
        wrong = node.publisher("/tb3_1/cmd_vel", TWIST)
        cmd2 = node.publisher("/tb3_1/cmd_vel", TWIST_STAMPED)

        def drive_until_moved() -> bool:
            cmd1.put(cdr.encode_twist(0.5, 0.0))
            wrong.put(cdr.encode_twist(0.5, 0.0))
            return odom.last().x > 0.05

        wait_for(drive_until_moved, DEADLINE, "robot 1 to move", interval=0.05)
        p = mocap.last()
        assert close((p.x, p.y), (agent2.x, agent2.y), 1e-9)
        cmd1.put(cdr.encode_twist(0.0, 0.0))
        wait_for(lambda: fleet.robots[0].stopped_at is not None, DEADLINE, "robot 1 to take its zero twist")
        k = len(odom)
        wait_for(lambda: len(odom) > k + 8, DEADLINE, "more poses")
        # (a pose published before the stop may still arrive after it on a loaded machine: the
        # robot stands still from some pose on, and the last five are all that one)
        after = odom.since(k)[-5:]
        assert all(q.x == after[0].x for q in after) and after[0].x > 0.05
        cmd2.put(cdr.encode_twist_stamped(1, "", 0.1, 0.0))
        wait_for(lambda: fleet.robots[1].commands == 1, DEADLINE, "robot 2's command")
    one, two = fleet.robots
    assert one.body.v == 0.0 and one.malformed == 0 and two.commands == 1
    assert two.last_command == (0.1, 0.0)


def test_the_fleet_saturates_what_it_is_told():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with running_fleet(robots_file(endpoint), FleetOptions(rate=50, cmd_timeout=5.0)) as (fleet, session):
        with Ros2Node(session, "tester") as node:
            odom = Samples(cdr.decode_odometry)
            node.subscriber("/tb3_0/odom", ODOMETRY, odom)
            cmd = node.publisher("/tb3_0/cmd_vel", TWIST)
            wait_for(lambda: cmd.has_subscribers and len(odom), DEADLINE, "the robot's subscription and odometry")
            cmd.put(cdr.encode_twist(3.0, -9.0))
            cmd.put(b"\x00\x01\x00\x00 not a twist")
            wait_for(lambda: fleet.robots[0].commands == 1 and fleet.robots[0].malformed == 1, DEADLINE, "both samples")
            wait_for(lambda: odom.last().x != 0.0, DEADLINE, "robot 1 to move")
    assert fleet.robots[0].body.twist() == (0.22, -2.84)


def test_the_odometry_carries_rmw_zenohs_attachment():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with running_fleet(robots_file(endpoint), FleetOptions(rate=50)) as (_fleet, session):
        attachments = Samples(parse_attachment)
        key = "0/tb3_0/odom/" + ODOMETRY.dds + "/" + ODOMETRY.hash_for("jazzy")
        sub = session.declare_subscriber(key, lambda s: attachments(s.attachment.to_bytes()))
        wait_for(lambda: len(attachments) >= 3, DEADLINE, "three odometry samples")
        sub.undeclare()
        seqs = [a[0] for a in attachments.since(0)]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs))) and len({a[2] for a in attachments.since(0)}) == 1


# -- `swarm robots sim` ---------------------------------------------------------------------------------------


def test_swarm_robots_sim_runs_until_ctrl_c(rt, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robots = write_robots(tmp_path / "robots.toml", robots_file(endpoint, cmd_type="TwistStamped"))
    fleet = rt.tracker.spawn(
        swarm_cmd("robots", "sim", TURTLEBOT, "--robots", robots, "--latency", "0.03", "--pose-noise", "0.01"), "fleet"
    )
    wait_for(
        lambda: fleet.check_running("its banner") or "fleet ready" in fleet.text(), DEADLINE, "the fleet to be ready"
    )
    text = fleet.text()
    assert "robot 1: /tb3_0 odom -> cmd_vel Twist\n" in text
    assert "robot 2: /tb3_1 odom -> cmd_vel TwistStamped\n" in text
    assert f"router on {endpoint}" in text and "latency 0.03 s, noise 0.01 m / 0.05 rad" in text
    session = client(endpoint)
    try:
        with Ros2Node(session, "tester") as node:
            odom = Samples(cdr.decode_odometry)
            node.subscriber("/tb3_1/odom", ODOMETRY, odom)
            wait_for(lambda: len(odom) >= 3, DEADLINE, "odometry")
            assert all(p.frame_id == "odom" for p in odom.since(0))
            assert any(p.x != 0.0 for p in odom.since(0))  # the noise
    finally:
        session.close()
    fleet.popen.send_signal(signal.SIGINT)
    assert fleet.wait(DEADLINE) == ExitCode.INTERRUPTED
    assert "robot 1: 0 commands (0 malformed)" in fleet.text()


def test_swarm_robots_sim_ends_after_its_duration_and_refuses_what_it_cannot_do(rt, tmp_path):
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        taken = f"tcp/127.0.0.1:{busy.getsockname()[1]}"
        robots = write_robots(tmp_path / "robots.toml", robots_file(taken))
        refused = rt.tracker.spawn(swarm_cmd("robots", "sim", TURTLEBOT, "--robots", robots), "taken")
        assert refused.wait(DEADLINE) == ExitCode.USAGE
        assert f"cannot listen on {taken}" in refused.text()
    finally:
        busy.close()
    bad = write_robots(tmp_path / "bad.toml", robots_file(cmd_type="Twisty"))
    wrong = rt.tracker.spawn(swarm_cmd("robots", "sim", TURTLEBOT, "--robots", bad), "bad")
    assert wrong.wait(DEADLINE) == ExitCode.USAGE and "cmd_type" in wrong.text()
    stops = rt.tracker.spawn(swarm_cmd("robots", "sim", TURTLEBOT, "--robots", robots, "--stop-poses", "2"), "stops")
    assert stops.wait(DEADLINE) == ExitCode.USAGE and "--stop-poses 2: give AGENT:SECONDS" in stops.text()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    timed = rt.tracker.spawn(
        swarm_cmd(
            "robots", "sim", TURTLEBOT, "--robots", robots, "--listen", endpoint, "--duration", "2", "--time-scale", "4"
        ),
        "timed",
    )
    assert timed.wait(DEADLINE) == ExitCode.OK
    assert f"router on {endpoint}" in timed.text() and "robot 2: 0 commands" in timed.text()
