"""The robot world: the world's plant hook (world/plant.py) and the robots' plant
(swarm/robots/plant.py `RobotPlant`, with swarm/robots/robot.py, discovery.py and pose.py).

- pure: the odom -> world transform, the twists (saturation, a gone agent stops its robot),
  the command type read from a robot's subscription token, the pose ages and stale spells;
- the plant against a fake node (the decisions, no zenoh): prepare, start, step, hold, stop,
  its errors naming the robot and the topic, summary figures;
- the hook in the world process against the fake session (tests/support/fakes.py): a run's ticks go
  through the plant, and the plant is stopped on every way out (end, Stop, an error);
- in process, over real zenoh: the robot world against a tiny robot made with swarm.ros2's
  Ros2Node (publishes odometry, records twists).
"""

from __future__ import annotations

import math
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from fakes import FakeQuery, FakeSession
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner, Result

from swarm.api.launch import Launch
from swarm.cli.main import app
from swarm.contracts import log as logs
from swarm.contracts import wire
from swarm.contracts.errors import UsageError
from swarm.contracts.scenario import parse_scenario
from swarm.contracts.startup import Announcer
from swarm.contracts.stop_signals import StopSignals
from swarm.contracts.vocabulary import EventKind, ExitCode
from swarm.robots import pose
from swarm.robots.config import RobotsError, parse_robots
from swarm.robots.plant import RobotPlant
from swarm.robots.pose import PoseAges, odom_to_world, twist_for
from swarm.robots.robot import cmd_type_from
from swarm.robots.sim_body import odom_pose
from swarm.ros2 import cdr
from swarm.ros2.attachment import attachment, gid_for
from swarm.ros2.keys import EntityInfo
from swarm.ros2.node import Ros2Node
from swarm.ros2.types import ODOMETRY, POSE_STAMPED, TWIST, TWIST_STAMPED
from swarm.runtime.procs import wait_until
from swarm.world import main as world_main
from swarm.world.core import WorldCore
from swarm.world.engine import Engine
from swarm.world.process import World, WorldConfig

ROOT = Path(__file__).resolve().parents[2]
RUN = "robots"
SCENARIO = {
    "run": {"dt": 0.05, "duration": 0.2, "clock": "realtime"},
    "gains": {"c1": 0.15, "c2": 0.075},
    "agents": [
        {
            "id": 1,
            "role": "leader",
            "x": 0.7,
            "y": 0.0,
            "heading": math.pi / 2,
            "speed": 0.105,
            "orbit_radius": 0.7,
            "max_turn_rate": 2.84,
        },
        {"id": 2, "role": "follower", "x": 0.87, "y": 0.16, "heading": 2.426, "speed": 0.3, "max_turn_rate": 5.0},
    ],
}
ROBOTS = {
    "ros2": {"connect": "tcp/127.0.0.1:1", "stale_after": 0.5},
    "robots": [
        {"agent": 1, "namespace": "/tb3_0"},
        {"agent": 2, "namespace": "/tb3_1", "cmd_type": "Twist", "max_linear": 0.22, "max_angular": 2.84},
    ],
}


def token(topic: str, rtype=TWIST_STAMPED, hash_: str | None = None, kind: str = "MS") -> EntityInfo:
    return EntityInfo(
        kind=kind,
        namespace="/" + topic.split("/")[1],
        node="turtlebot3_node",
        topic=topic,
        dds_type=rtype.dds,
        type_hash=hash_ or rtype.rihs01,
        qos_text="::,10:,:,:,,",
    )


# -- pure -------------------------------------------------------------------------------------------
def test_the_odom_frame_starts_at_the_agents_start_pose():
    start = (0.87, 0.16, 2.426)
    x, y, g = odom_to_world(start, (0.0, 0.0, 0.0))
    assert (x, y, g) == pytest.approx(start)
    # 1 m straight ahead in odom is 1 m along the start heading in the world; a quarter turn left
    x, y, g = odom_to_world((1.0, 2.0, math.pi / 2), (1.0, 0.0, math.pi / 2))
    assert (x, y) == pytest.approx((1.0, 3.0))
    assert g == pytest.approx(math.pi)
    x, y, g = odom_to_world((0.0, 0.0, 3.0), (0.0, 0.0, 1.0))  # yaw wrapped into (-pi, pi]
    assert g == pytest.approx(4.0 - 2 * math.pi)


finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(finite, finite, angle, finite, finite, angle)
def test_odom_to_world_inverts_the_fleets_odom_pose(x0, y0, h0, x, y, g):
    """The simulated fleet (swarm/robots/fleet.py) puts a world pose into the odom frame; the
    plant takes it back: the same pose."""
    back = odom_to_world((x0, y0, h0), odom_pose((x0, y0, h0), (x, y, g)))
    assert back[0] == pytest.approx(x, abs=1e-9) and back[1] == pytest.approx(y, abs=1e-9)
    assert math.remainder(back[2] - g, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_twists_are_the_speed_and_the_turn_rate_saturated_at_the_robots_limits():
    assert twist_for(0.105, 0.15, 0.22, 2.84) == (0.105, 0.15)
    assert twist_for(0.3, -5.0, 0.22, 2.84) == (0.22, -2.84)  # both saturated
    assert twist_for(0.3, 5.0, 0.22, 2.84) == (0.22, 2.84)
    assert twist_for(0.105, 0.0, 0.22, 2.84) == (0.105, 0.0)  # coasting: straight on at its speed
    assert twist_for(0.105, math.nan, 0.22, 2.84) == (0.0, 0.0)  # gone: the robot stops


def test_the_command_type_comes_from_the_robots_own_subscription():
    spec = parse_robots(ROBOTS).robots[0]
    assert cmd_type_from(spec, [], "jazzy", "r.toml") is None  # not yet seen
    others = [token("/tb3_1/cmd_vel", TWIST), token("/tb3_0/cmd_vel", TWIST_STAMPED, kind="MP")]
    assert cmd_type_from(spec, others, "jazzy", "r.toml") is None  # another robot's; a publisher
    assert cmd_type_from(spec, [token("/tb3_0/cmd_vel", TWIST_STAMPED)], "jazzy", "r.toml") == TWIST_STAMPED
    assert cmd_type_from(spec, [token("/tb3_0/cmd_vel", TWIST)], "jazzy", "r.toml") == TWIST
    humble = token("/tb3_0/cmd_vel", TWIST, hash_="TypeHashNotSupported")
    assert cmd_type_from(spec, [humble], "humble", "r.toml") == TWIST


def test_a_command_topic_of_another_type_or_distro_is_one_line_naming_the_robot_and_the_topic():
    spec = parse_robots(ROBOTS).robots[0]
    with pytest.raises(
        RobotsError, match=r"^r\.toml: agent 1's robot /tb3_0: /tb3_0/cmd_vel takes .*Odometry_, neither"
    ):
        cmd_type_from(spec, [token("/tb3_0/cmd_vel", ODOMETRY)], "jazzy", "r.toml")
    both = [token("/tb3_0/cmd_vel", TWIST), token("/tb3_0/cmd_vel", TWIST_STAMPED)]
    with pytest.raises(RobotsError, match="both Twist and TwistStamped; set its cmd_type"):
        cmd_type_from(spec, both, "jazzy", "r.toml")
    humble = token("/tb3_0/cmd_vel", TWIST, hash_="TypeHashNotSupported")
    with pytest.raises(
        RobotsError, match=r'/tb3_0/cmd_vel takes Twist with type hash TypeHashNotSupported.*distro = "humble"'
    ):
        cmd_type_from(spec, [humble], "jazzy", "r.toml")
    with pytest.raises(RobotsError, match='distro = "jazzy"$') as e:
        cmd_type_from(spec, [token("/tb3_0/cmd_vel", TWIST)], "humble", "r.toml")
    assert "\n" not in str(e.value)


def test_pose_ages_say_stale_once_and_fresh_once_and_keep_their_figures():
    ages = PoseAges()
    seq = [0.03, 0.04, 0.6, 0.65, math.inf, 0.02, 0.03, 0.7, 0.01]
    changes = [ages.tick(a, 0.5) for a in seq]
    assert changes == [None, None, EventKind.STALE, None, None, EventKind.FRESH, None, EventKind.STALE, EventKind.FRESH]
    f = ages.figures()
    assert f["pose_age_max"] == 0.7
    assert f["pose_age_p50"] == pytest.approx(float(np.median([a for a in seq if math.isfinite(a)])))
    assert (f["stale_ticks"], f["stale_spells"], f["ticks_without_pose"]) == (4, 2, 1)
    assert PoseAges().figures()["pose_age_max"] is None


def test_pose_figures_keep_bounded_memory_and_the_exact_maximum(monkeypatch):
    """A long run keeps the latest KEPT ages for the median, every maximum and count exactly."""
    monkeypatch.setattr(pose, "KEPT", 10)
    ages = PoseAges()
    seq = [5.0] + [0.1] * 30 + [math.inf] * 3 + [0.2] * 5
    for a in seq:
        ages.tick(a, 1.0)
    assert len(ages.ages.latest) == 10
    f = ages.figures()
    assert f["pose_age_max"] == 5.0  # long out of the window, still the maximum
    assert f["pose_age_p50"] == pytest.approx(0.15)  # five of 0.1 and five of 0.2
    assert f["ticks_without_pose"] == 3


# -- the plant against a fake node ------------------------------------------------------------------
class FakePub:
    def __init__(self, topic: str, rtype):
        self.topic, self.rtype = topic, rtype
        self.sent: list[tuple[float, float]] = []

    def put(self, payload: bytes) -> None:
        if self.rtype == TWIST_STAMPED:
            _, _, vx, wz = cdr.decode_twist_stamped(payload)
        else:
            vx, wz = cdr.decode_twist(payload)
        self.sent.append((vx, wz))


class FakeNode:
    """What RobotPlant asks of a Ros2Node; `poses` (topic -> payload) are delivered as soon as the
    topic is subscribed (a robot that publishes)."""

    def __init__(self, entities=(), poses=None):
        self.entities = list(entities)
        self.poses = dict(poses or {})
        self.pubs: dict[str, FakePub] = {}
        self.subs: dict[str, tuple] = {}
        self.closed = False

    def publisher(self, topic, rtype):
        self.pubs[topic] = FakePub(topic, rtype)
        return self.pubs[topic]

    def subscriber(self, topic, rtype, on_sample, *, with_attachment=False):
        self.subs[topic] = (rtype, on_sample)
        if topic in self.poses:
            self.feed(topic, self.poses[topic])

    def remote_entities(self, topic=None, kind=None, timeout=1.0):
        return [e for e in self.entities if (kind is None or e.kind == kind) and (topic is None or e.topic == topic)]

    def close(self):
        self.closed = True

    def feed(self, topic: str, payload: bytes, gid: bytes | None = None) -> None:
        """A pose from the robot's publisher (its GID: gid_for(topic)), or from `gid`'s."""
        self.subs[topic][1](payload, attachment(1, 0, gid_for(topic) if gid is None else gid))


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def odom(x: float, y: float, yaw: float) -> bytes:
    return cdr.encode_odometry(1, "odom", "base_footprint", x, y, yaw)


def fake_plant(robots=ROBOTS, entities=None, poses=None, **kw):
    node = FakeNode(
        [token("/tb3_0/cmd_vel", TWIST_STAMPED)] if entities is None else entities,
        {"/tb3_0/odom": odom(0, 0, 0), "/tb3_1/odom": odom(0, 0, 0)} if poses is None else poses,
    )
    session = FakeSession()
    clock = Clock()
    plant = RobotPlant(
        parse_robots(robots),
        parse_scenario(SCENARIO),
        "r.toml",
        open_session=lambda connect: session,
        make_node=lambda ses: node,
        **{"clock": clock, "watchdog": False, **kw},
    )
    return plant, node, session, clock


def test_the_plant_prepares_stops_every_robot_and_steps_them_from_their_poses():
    plant, node, session, clock = fake_plant()
    plant.prepare()
    assert node.pubs["/tb3_0/cmd_vel"].rtype == TWIST_STAMPED  # auto: from the robot's token
    assert node.pubs["/tb3_1/cmd_vel"].rtype == TWIST  # as the file says
    assert node.subs["/tb3_0/odom"][0] == ODOMETRY
    assert [p.sent for p in node.pubs.values()] == [[(0.0, 0.0)], [(0.0, 0.0)]]  # standing still at first

    core = WorldCore(parse_scenario(SCENARIO), plant=plant)
    events: list[tuple] = []
    node.feed("/tb3_0/odom", odom(0.1, 0.0, 0.0))  # agent 1 moved 0.1 m along its start heading (north)
    plant.start(core, lambda kind, agent, reason, **more: events.append((kind, agent, reason, more)))
    # before tick 0 the odometry origin is the mean of the poses so far (0.05): 0.05 m north of the start
    assert core.pose(1) == pytest.approx((0.7, 0.05, math.pi / 2))
    assert core.pose(2) == pytest.approx((0.87, 0.16, 2.426))

    core.set_command(1, 0.15)
    core.set_command(2, -4.0)  # within the agent's own limit (5), above its robot's (2.84)
    clock.t += 1.0  # 0.2 m and 0.5 rad: plausible in 1 s (not in 0.05 s: tests of Plausible)
    node.feed("/tb3_0/odom", odom(0.1, 0.0, 0.0))
    node.feed("/tb3_1/odom", odom(0.2, 0.0, 0.5))
    core.step()
    assert core.tick == 1
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.15))
    assert node.pubs["/tb3_1/cmd_vel"].sent[-1] == pytest.approx((0.22, -2.84))
    assert core.pose(2) == pytest.approx(odom_to_world((0.87, 0.16, 2.426), (0.2, 0.0, 0.5)))

    core.drop(2)  # on_dropout "leave" (the default): gone, its robot stops
    core.step()
    assert node.pubs["/tb3_1/cmd_vel"].sent[-1] == (0.0, 0.0)
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.15))
    assert not events

    plant.hold()
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == (0.0, 0.0)
    n = len(node.pubs["/tb3_0/cmd_vel"].sent)
    plant.stop()
    assert node.pubs["/tb3_0/cmd_vel"].sent[n:] == [(0.0, 0.0)] * 3
    assert node.closed and session.closed
    plant.stop()  # again: nothing
    assert len(node.pubs["/tb3_0/cmd_vel"].sent) == n + 3


def test_a_coasting_agents_robot_goes_straight_on_at_its_speed():
    coast = {**SCENARIO, "run": {**SCENARIO["run"], "on_dropout": "coast"}}
    plant, node, _, _ = fake_plant()
    plant.prepare()
    core = WorldCore(parse_scenario(coast), plant=plant)
    plant.start(core, lambda *a, **k: None)
    core.set_command(1, 0.3)
    core.drop(1)
    core.step()
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.0))


def test_a_stale_robot_gets_zero_twists_and_one_stale_event_then_one_fresh():
    plant, node, _, clock = fake_plant()
    plant.prepare()
    core = WorldCore(parse_scenario(SCENARIO), plant=plant)
    events: list[tuple] = []
    plant.start(core, lambda kind, agent, reason, **more: events.append((kind, agent, reason, more)))
    core.set_command(1, 0.2)
    core.set_command(2, 0.2)
    for _ in range(3):  # agent 2's robot keeps publishing, agent 1's is silent for 0.6 s
        clock.t += 0.2
        node.feed("/tb3_1/odom", odom(0.0, 0.0, 0.0))
        core.step()
    assert node.pubs["/tb3_0/cmd_vel"].sent[-3:] == [pytest.approx((0.105, 0.2)), (0.105, 0.2), (0.0, 0.0)]
    assert node.pubs["/tb3_1/cmd_vel"].sent[-1] == pytest.approx((0.22, 0.2))
    ((kind, agent, reason, more),) = events
    assert (kind, agent, more["topic"]) == (EventKind.STALE, 1, "/tb3_0/odom")
    assert more["age"] == pytest.approx(0.6)
    assert "no pose on /tb3_0/odom for 0.60 s (stale_after 0.5 s): zero twist" == reason
    clock.t += 0.2
    core.step()  # still stale: zero, no second event
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == (0.0, 0.0) and len(events) == 1
    node.feed("/tb3_0/odom", odom(0.3, 0.0, 0.0))  # 0.3 m in 0.8 s: plausible
    clock.t += 0.05
    core.step()
    assert events[-1][:2] == (EventKind.FRESH, 1)
    assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.2))
    assert core.pose(1) == pytest.approx((0.7, 0.3, math.pi / 2))
    f = plant.figures()
    assert f["stale_after"] == 0.5
    one = f["agents"]["1"]
    assert (one["stale_spells"], one["stale_ticks"], one["cmd_type"]) == (1, 2, "TwistStamped")
    assert one["pose_age_max"] == pytest.approx(0.8)
    assert f["agents"]["2"]["pose_age_max"] == pytest.approx(0.25)
    assert f["agents"]["2"]["cmd_type"] == "Twist" and f["agents"]["2"]["twists"] == 6


@pytest.mark.slow  # waits on real time or zenoh sessions
def test_the_watchdog_stops_the_robots_when_the_world_sends_nothing_for_stale_after():
    """A stalled world (its main thread): zero twists from the watchdog's thread, once, until the
    next step drives the robots again."""
    robots = {**ROBOTS, "ros2": {**ROBOTS["ros2"], "stale_after": 0.2}}
    said: list[str] = []
    plant, node, _, _ = fake_plant(robots, clock=time.monotonic, watchdog=True, say=said.append)
    plant.prepare()
    core = WorldCore(parse_scenario(SCENARIO), plant=plant)
    plant.start(core, lambda *a, **k: None)
    try:
        core.set_command(1, 0.1)
        core.step()
        assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.1))
        assert wait_until(lambda: plant.watchdog_stops == 1, 3.0)
        assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == (0.0, 0.0) == node.pubs["/tb3_1/cmd_vel"].sent[-1]
        assert said[-1] == "robots: no command for 0.2 s (the world stalled): every robot stopped until the next tick"
        time.sleep(0.4)
        assert plant.watchdog_stops == 1  # once per stall
        node.feed("/tb3_0/odom", odom(0, 0, 0))  # (not stale)
        node.feed("/tb3_1/odom", odom(0, 0, 0))
        core.step()
        assert node.pubs["/tb3_0/cmd_vel"].sent[-1] == pytest.approx((0.105, 0.1))
        plant.hold()  # the clock holds: stopped by the hold, nothing for the watchdog
        time.sleep(0.4)
        assert plant.watchdog_stops == 1
    finally:
        plant.stop()
    assert plant._watch is not None and not plant._watch.is_alive()
    assert plant.figures()["watchdog_stops"] == 1


def test_mocap_poses_are_in_the_world_frame_and_malformed_ones_are_counted_not_used():
    robots = {**ROBOTS, "robots": [{**r, "pose": "mocap"} for r in ROBOTS["robots"]]}
    mocap = {
        "/tb3_0/pose": cdr.encode_pose_stamped(1, "world", 3.0, 4.0, 1.0),
        "/tb3_1/pose": cdr.encode_pose_stamped(1, "world", -1.0, 2.0, -3.0),
    }
    plant, node, _, _ = fake_plant(robots, poses=mocap)
    plant.prepare()
    assert node.subs["/tb3_0/pose"][0] == POSE_STAMPED
    node.feed("/tb3_0/pose", b"\x00\x01\x00\x00garbage")
    core = WorldCore(parse_scenario(SCENARIO), plant=plant)
    plant.start(core, lambda *a, **k: None)
    assert core.pose(1) == pytest.approx((3.0, 4.0, 1.0))
    assert core.pose(2) == pytest.approx((-1.0, 2.0, -3.0))
    assert plant.figures()["agents"]["1"]["malformed_poses"] == 1


def test_a_robot_that_does_not_subscribe_or_publish_is_one_line_naming_it_and_its_topic():
    plant, node, session, _ = fake_plant(entities=[], cmd_wait=0.0)
    with pytest.raises(RobotsError) as e:
        plant.prepare()
    assert str(e.value).startswith("r.toml: agent 1's robot /tb3_0: nobody subscribes to /tb3_0/cmd_vel (waited 0 s")
    assert "\n" not in str(e.value) and e.value.exit_code == ExitCode.USAGE
    plant.stop()
    assert node.closed and session.closed

    plant, node, _, _ = fake_plant(poses={"/tb3_0/odom": odom(0, 0, 0)}, pose_wait=0.0)
    with pytest.raises(RobotsError, match=r"^r\.toml: agent 2's robot /tb3_1: no Odometry on /tb3_1/odom within 0 s$"):
        plant.prepare()
    plant.stop()
    assert node.pubs["/tb3_1/cmd_vel"].sent == [(0.0, 0.0)] * 4  # stopped at prepare, and at the end

    def unreachable(connect):
        raise zenoh.ZError("Unable to connect to any of [tcp/127.0.0.1:1]")

    plant = RobotPlant(parse_robots(ROBOTS), parse_scenario(SCENARIO), "r.toml", open_session=unreachable)
    with pytest.raises(RobotsError, match=r"^r\.toml: cannot reach the robots' zenoh router at tcp/127\.0\.0\.1:1 "):
        plant.prepare()
    plant.stop()  # nothing was opened: nothing to close


# -- the hook in the world process (fake session) ---------------------------------------------------
@pytest.fixture
def signals_back():
    """The world's ending ignores SIGINT/SIGTERM (StopSignals.ignore): put this process's back."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


class RecordingPlant:
    """A plant that moves every agent 0.01 m east per step and records what the world asks."""

    def __init__(self, fail: BaseException | None = None):
        self.calls: list[str] = []
        self.u: list[np.ndarray] = []
        self.fail = fail

    def prepare(self) -> None:
        self.calls.append("prepare")
        if self.fail is not None:
            raise self.fail

    def start(self, core, event) -> None:
        self.calls.append("start")
        core.x = core.x + 1.0
        event(EventKind.FRESH, 1, "test")

    def step(self, core, u) -> None:
        self.calls.append("step")
        self.u.append(u.copy())
        core.x = core.x + 0.01

    def hold(self) -> None:
        self.calls.append("hold")

    def stop(self) -> None:
        self.calls.append("stop")

    def figures(self) -> dict:
        return {"agents": {"1": {"pose_age_max": 0.01}}}


def test_without_a_plant_the_engine_integrates_as_before():
    s = parse_scenario(SCENARIO)
    a, b = Engine(s, 4), Engine(s, 4, plant=None)
    for e in (a, b):
        e.start_plant()
        e.hold_plant()
        for _ in range(4):
            e.end_tick()
        e.stop_plant()
    assert a.core.pose(2) == b.core.pose(2) != (0.87, 0.16, 2.426)


def test_with_a_plant_the_engine_records_its_poses_and_hands_it_the_applied_turn_rates():
    s = parse_scenario(SCENARIO)
    plant = RecordingPlant()
    e = Engine(s, 3, plant=plant)
    e.start_plant()
    e.core.set_command(1, 0.25)
    e.core.drop(2)
    for _ in range(3):
        e.end_tick()
    e.close()
    e.stop_plant()
    e.stop_plant()
    assert plant.calls == ["start", "step", "step", "step", "stop"]
    assert plant.u[0][0] == 0.25 and math.isnan(plant.u[0][1])
    x = e.rec.arrays()["x"]
    assert x[:, 0] == pytest.approx(0.7 + 1.0 + 0.01 * np.arange(4))  # the plant's poses, recorded
    assert e.events[0]["kind"] == EventKind.FRESH and e.events[0]["tick"] == 0


def world_with(plant, clock: str = "realtime", duration: float | None = None) -> tuple[World, FakeSession]:
    scenario = SCENARIO if duration is None else {**SCENARIO, "run": {**SCENARIO["run"], "duration": duration}}
    cfg = WorldConfig(
        parse_scenario(scenario), RUN, "unixsock-stream//nonexistent", None, clock=clock, progress=False, plant=plant
    )
    world = World(cfg)
    ses = FakeSession()
    world._open(ses)
    return world, ses


def join(world, aid: int) -> None:
    key = wire.agent_key(RUN, aid, "join")
    world.joins.on_join(FakeQuery(wire.encode_join_request(aid, 100 + aid, "host"), key_expr=key))
    world.inbox.on_alive(wire.agent_key(RUN, aid, "alive"), zenoh.SampleKind.PUT, None)


def test_a_world_with_a_plant_runs_realtime_only():
    with pytest.raises(ValueError, match="realtime clock only"):
        world_with(RecordingPlant(), clock="lockstep")


@pytest.mark.slow
def test_the_worlds_ticks_go_through_the_plant_which_is_stopped_at_the_end(signals_back):
    plant = RecordingPlant()
    world, _ = world_with(plant)
    join(world, 1)
    join(world, 2)
    code = world_main._serve(world, world.cfg, None, StopSignals(world_main.Stop), Announcer(None))
    assert code == ExitCode.OK
    # every tick steps the plant, unless the machine stalled the world past a tick (a loaded
    # machine can): then the plant holds for that step (world/clock.py `hold_robots`)
    calls = plant.calls
    assert calls[0] == "start" and calls[-1] == "stop" and set(calls[1:-1]) <= {"step", "hold", "start"}
    steps, holds = calls.count("step"), calls.count("hold")
    late = [e for e in world.engine.events if e["kind"] == EventKind.LATE]
    assert steps + holds >= world.ticks and (holds == 0 or late), calls
    if not holds:
        assert steps == world.ticks and world.core.x[0] == pytest.approx(0.7 + 1.0 + 0.01 * world.ticks)


def stall_run(where: str) -> tuple[RecordingPlant, World]:
    """A realtime robots world of 30 ticks (50 ms) that stalls 0.5 s in tick 1: in its step
    (`where` = "step": after its commands went out) or right after its frames went out ("wait":
    as a SIGSTOP during the tick's wait does)."""
    plant = RecordingPlant()
    world, _ = world_with(plant, duration=1.5)
    join(world, 1)
    join(world, 2)
    publish, step = world.publish_frames, world.record_and_step

    def stall() -> None:
        if world.core.tick == 1:
            time.sleep(10 * world.core.dt)

    def publish_frames():
        sent = publish()
        if where == "wait":
            stall()
        return sent

    def record_and_step():
        if where == "step":
            stall()
        step()

    world.publish_frames, world.record_and_step = publish_frames, record_and_step  # type: ignore[method-assign]
    code = world_main._serve(world, world.cfg, None, StopSignals(world_main.Stop), Announcer(None))
    assert code == ExitCode.OK and world.core.tick == world.ticks == 30
    assert any(e["kind"] == EventKind.LATE for e in world.engine.events)
    return plant, world


def held_then_driven(calls: list[str], driven_before: int) -> int:
    """After `driven_before` steps: only holds (a zero twist, then the poses read back), at
    least RESUME_HOLD_S of them, then steps again (a loaded machine may stall the world once
    more: holds again, which is the point); the number of holds in the first spell."""
    from swarm.world.clock import RESUME_HOLD_S

    assert calls[: 1 + driven_before] == ["start"] + ["step"] * driven_before
    rest = calls[1 + driven_before : -1]
    holds = 0
    while rest[:2] == ["hold", "start"]:
        rest, holds = rest[2:], holds + 1
    assert holds >= RESUME_HOLD_S / 0.05 and rest[:1] == ["step"] and set(rest) <= {"step", "hold", "start"}, calls
    assert calls[-1] == "stop"
    return holds


@pytest.mark.slow
def test_after_a_stall_the_plant_stands_still_then_starts_from_its_latest_poses(signals_back):
    """The world stalls 0.5 s (ten of its 50 ms periods) in tick 1, before its commands went
    out: no burst of the missed ticks, and tick 1's commands (computed before the stall) are
    never sent. The plant holds (a zero twist to every robot, its latest poses read back) for
    RESUME_HOLD_S of steps while the links to the robots come back, then drives them again.
    Every tick still counts."""
    plant, _ = stall_run("step")
    held_then_driven(plant.calls, driven_before=1)  # tick 0 driven, the stall before tick 1's commands


@pytest.mark.slow
def test_a_stall_within_a_tick_sends_a_zero_twist_instead_of_that_ticks_stale_commands(signals_back):
    """The stall comes right after tick 1's frames went out: tick 1's commands were computed
    from poses the stall made stale, so they are never sent; the plant holds from tick 1 on."""
    plant, _ = stall_run("wait")
    held_then_driven(plant.calls, driven_before=1)  # tick 0 driven; tick 1's commands never sent


@pytest.mark.parametrize(
    ("raised", "code"),
    [
        (world_main.Stop(2), ExitCode.INTERRUPTED),
        (world_main.Stop(15), ExitCode.TERMINATED),
        (RuntimeError("bug"), ExitCode.FAILED),
    ],
)
def test_the_plant_is_stopped_however_the_run_ends(raised, code, monkeypatch, capsys, signals_back):
    plant = RecordingPlant()
    world, _ = world_with(plant)
    world.engine.start_plant()

    def run():
        world.engine.end_tick()
        raise raised

    monkeypatch.setattr(world, "run", run)
    assert world_main._serve(world, world.cfg, None, StopSignals(world_main.Stop), Announcer(None)) == code
    assert plant.calls == ["start", "step", "stop"]


def test_a_plant_that_cannot_be_prepared_ends_the_world_with_its_errors_code_and_is_stopped(capsys, signals_back):
    plant = RecordingPlant(fail=RobotsError("r.toml: agent 1's robot /tb3_0: no Odometry on /tb3_0/odom within 10 s"))
    world, _ = world_with(plant)
    logs.setup("world")  # as run_world does (swarm/contracts/log.py)
    assert world_main._prepare_plant(world, world.cfg, StopSignals(world_main.Stop)) == ExitCode.USAGE
    assert plant.calls == ["prepare", "stop"]
    assert (
        capsys.readouterr().err
        == "swarm world: r.toml: agent 1's robot /tb3_0: no Odometry on /tb3_0/odom within 10 s\n"
    )


@pytest.mark.slow  # waits on real time or zenoh sessions
def test_a_pause_holds_the_plant():
    plant = RecordingPlant()
    world, _ = world_with(plant)
    join(world, 1)
    join(world, 2)
    world.state.paused = True
    threading.Timer(0.3, lambda: setattr(world.state, "paused", False)).start()
    t0 = time.monotonic()
    assert world.run() == ExitCode.OK
    assert time.monotonic() - t0 >= 0.3
    assert plant.calls[:3] == ["start", "hold", "step"]


# -- in process, over zenoh: the robot world against a tiny robot made with Ros2Node ----------------
def _zenoh_config(mode: str, ep: str) -> zenoh.Config:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", f'"{mode}"')
    cfg.insert_json5("listen/endpoints" if mode == "router" else "connect/endpoints", f'["{ep}"]')
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return cfg


class TinyRobot:
    """A robot in `namespace`: its node subscribes to cmd_vel (`cmd` type) and records the
    twists; a thread publishes its odometry (`odom`: x, y, yaw in its odom frame) at 50 Hz."""

    def __init__(self, session, namespace: str, cmd, odom: tuple[float, float, float]):
        self.node = Ros2Node(session, "turtlebot3_node", namespace=namespace)
        self.cmd = cmd
        self.odom = odom
        self.twists: list[tuple[float, float]] = []
        self.node.subscriber("cmd_vel", cmd, self._on_cmd)
        self.pub = self.node.publisher("odom", ODOMETRY)
        self.quit = threading.Event()
        self.thread = threading.Thread(target=self._publish, daemon=True)
        self.thread.start()

    def _on_cmd(self, payload: bytes) -> None:
        if self.cmd == TWIST_STAMPED:
            _, _, vx, wz = cdr.decode_twist_stamped(payload)
        else:
            vx, wz = cdr.decode_twist(payload)
        self.twists.append((vx, wz))

    def _publish(self) -> None:
        while not self.quit.wait(0.02):
            self.pub.put(cdr.encode_odometry(time.time_ns(), "odom", "base_footprint", *self.odom))

    def close(self) -> None:
        self.quit.set()
        self.thread.join(2.0)
        self.node.close()


@pytest.fixture
def robots_router(tmp_path):
    """(endpoint, a client session on it) of a router standing in for rmw_zenohd."""
    ep = f"unixsock-stream/{tmp_path / 'robots.sock'}"
    router = zenoh.open(_zenoh_config("router", ep))
    robot_side = zenoh.open(_zenoh_config("client", ep))
    try:
        yield ep, robot_side
    finally:
        robot_side.close()
        router.close()


@pytest.mark.slow  # waits on real time or zenoh sessions
def test_the_robot_world_builds_frames_from_the_robots_poses_and_sends_them_the_agents_commands(
    robots_router, signals_back
):
    ep, robot_side = robots_router
    tb0 = TinyRobot(robot_side, "/tb3_0", TWIST_STAMPED, (0.3, 0.1, 0.2))  # cmd_type auto: read from its token
    tb1 = TinyRobot(robot_side, "/tb3_1", TWIST, (0.0, 0.0, 0.0))  # cmd_type Twist in the file
    try:
        s = parse_scenario(SCENARIO)
        plant = RobotPlant(parse_robots({**ROBOTS, "ros2": {**ROBOTS["ros2"], "connect": ep}}), s, "r.toml")
        world, ses = world_with(plant)
        assert world_main._prepare_plant(world, world.cfg, StopSignals(world_main.Stop)) is None
        # our node is in the robots' graph
        graph = tb0.node.remote_entities()
        assert {(e.kind, e.topic) for e in graph if e.node == "swarm_world"} >= {
            ("NN", ""),
            ("MP", "/tb3_0/cmd_vel"),
            ("MS", "/tb3_0/odom"),
            ("MP", "/tb3_1/cmd_vel"),
        }
        assert tb0.twists == [(0.0, 0.0)] and tb1.twists == [(0.0, 0.0)]  # standing still before tick 0
        join(world, 1)
        join(world, 2)
        world.engine.start_plant()

        # tick 0's frames come from the robots' poses: the odom frame starts at each agent's start pose
        # (odometry rebased to the robot's first pose: a robot that has not moved is at its start pose)
        p1 = (0.7, 0.0, math.pi / 2)
        p2 = (0.87, 0.16, 2.426)
        assert world.core.pose(1) == pytest.approx(p1) and world.core.pose(2) == pytest.approx(p2)
        world.publish_frames()
        f1 = wire.decode_sense(ses.on(wire.agent_key(RUN, 1, "sense"))[-1])
        f2 = wire.decode_sense(ses.on(wire.agent_key(RUN, 2, "sense"))[-1])
        assert f1.heading == pytest.approx(p1[2]) and f1.target == pytest.approx((-p1[0], -p1[1]))
        assert f2.heading == pytest.approx(p2[2])
        (seen,) = [c for c in f2.contacts if c.id == 1]
        assert seen.range == pytest.approx(math.dist(p1[:2], p2[:2]))

        # the agents' commands go to the robots: linear.x = speed, angular.z = u (saturated)
        world.engine.command(1, 0, 0.15, None, 0)
        world.engine.command(2, 0, -4.0, 1, 1)
        world.record_and_step()
        assert wait_until(lambda: len(tb0.twists) >= 2 and len(tb1.twists) >= 2, 5.0)
        assert tb0.twists[1] == pytest.approx((0.105, 0.15))
        assert tb1.twists[1] == pytest.approx((0.22, -2.84))

        # the end: zero twists to every robot, our node gone from their graph
        world_main._stop_plant(world)
        assert wait_until(lambda: tb0.twists[-1] == (0.0, 0.0) and tb1.twists[-1] == (0.0, 0.0), 5.0)
        assert wait_until(lambda: not [e for e in tb0.node.remote_entities() if e.node == "swarm_world"], 5.0)
        figures = plant.figures()["agents"]
        assert figures["1"]["cmd_type"] == "TwistStamped" and figures["2"]["cmd_type"] == "Twist"
        assert figures["1"]["poses"] > 0 and figures["1"]["pose_age_max"] < 0.5
        assert 0.0 <= figures["2"]["pose_delay_p50"] < 0.5  # stamped now, received within ms
    finally:
        tb0.close()
        tb1.close()


# -- the command line and the API: what is refused before anything starts -------------------------
TURTLEBOT = ROOT / "scenarios" / "turtlebot.toml"
TURTLEBOT_ROBOTS = ROOT / "scenarios" / "robots" / "turtlebot.toml"


def invoke(*args) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.mark.parametrize("command", ["world", "up"])
def test_robots_with_the_lockstep_clock_is_a_usage_error(command, tmp_path):
    res = invoke(command, TURTLEBOT, "--robots", TURTLEBOT_ROBOTS, "--clock", "lockstep", "--out", tmp_path / "o")
    assert res.exit_code == ExitCode.USAGE
    assert f"swarm {command}: --robots runs the realtime clock only" in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.parametrize("command", ["world", "up"])
def test_a_robots_file_that_does_not_fit_the_scenario_is_one_line_and_exit_2(command, tmp_path):
    bad = tmp_path / "robots.toml"
    bad.write_text('[[robots]]\nagent = 1\nnamespace = "/tb3_0"\n')
    res = invoke(command, TURTLEBOT, "--robots", bad, "--out", tmp_path / "o")
    assert res.exit_code == ExitCode.USAGE
    assert f"swarm {command}: {bad}: no robot for agent 2 (every agent of the scenario needs one)" in res.output
    assert not (tmp_path / "o").exists()
    res = invoke(command, TURTLEBOT, "--robots", tmp_path / "none.toml")
    assert res.exit_code == ExitCode.USAGE and "none.toml: no such file" in res.output


def test_launch_with_robots_runs_realtime_passes_the_file_to_its_world_and_says_its_warnings_once(tmp_path):
    fast = tmp_path / "fast.toml"
    fast.write_text(TURTLEBOT_ROBOTS.read_text().replace("max_linear = 0.22", "max_linear = 0.05", 1))
    said: list[str] = []
    run = Launch(TURTLEBOT, tmp_path / "o", robots=fast, say=said.append)
    cfg = run.launcher.cfg
    assert cfg.clock == "realtime" and cfg.robots == fast
    assert said == [
        "warning: robots: agent 1: speed 0.1 m/s is above its robot's max_linear 0.05 m/s (the robot will be "
        "saturated and the law's constant speed will not hold)"
    ]
    with pytest.raises(UsageError, match="realtime clock only"):
        Launch(TURTLEBOT, tmp_path / "p", robots=fast, clock="lockstep")
    with pytest.raises(RobotsError):
        Launch(TURTLEBOT, tmp_path / "q", robots=tmp_path / "none.toml")


def test_a_pose_is_carried_forward_from_its_stamp_along_the_last_twist():
    """Latency compensation ([ros2] predict): the pose measured `age` s ago moves on with the
    twist the robot was given; a clock out of step is not extrapolated past the horizon."""
    from swarm.robots.pose import predicted
    from swarm.world.kinematics import step_one

    assert predicted((0.0, 0.0, 0.0), (1.0, 0.0), 0.5, 1.0) == pytest.approx((0.5, 0.0, 0.0))
    assert predicted((1.0, 2.0, 0.3), (0.4, 0.8), 0.2, 1.0) == step_one(1.0, 2.0, 0.3, 0.4, 0.8, 0.2)
    assert predicted((1.0, 2.0, 0.3), (0.4, 0.8), 5.0, 1.0) == step_one(1.0, 2.0, 0.3, 0.4, 0.8, 1.0)
    assert predicted((1.0, 2.0, 0.3), (0.4, 0.8), -3.0, 1.0) == (1.0, 2.0, 0.3)


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (lambda d: d["robots"][1].update(max_linear=math.inf), r"robots\[1\]\.max_linear: Input should be a finite"),
        (lambda d: d["robots"][0].update(max_angular=math.nan), r"robots\[0\]\.max_angular: Input should be a finite"),
        (lambda d: d["robots"][1].update(namespace="/tb3_0/"), "agents 1 and 2 share the topic /tb3_0/cmd_vel"),
        (lambda d: d["robots"][1].update(pose_topic="/tb3_0/odom"), "agents 1 and 2 share the topic /tb3_0/odom"),
        (lambda d: d["ros2"].update(connect="nonsense"), r"ros2.*connect: not an endpoint: 'nonsense'"),
        (lambda d: d["ros2"].update(connect="tcp/host:99999"), r"ros2.*connect: not an endpoint"),
    ],
    ids=["inf-speed", "nan-turn", "one-namespace", "one-pose-topic", "nonsense-connect", "bad-port"],
)
def test_robots_files_that_would_fail_later_are_refused_at_once_naming_the_field(change, says, tmp_path):
    """Gaps that used to pass the check and fail at run time (a zenoh Json5Err, exit 1; or two
    agents driving one robot): one message naming the file and the field, exit 2 from the CLI."""
    import copy

    from conftest import to_toml

    data = copy.deepcopy(ROBOTS)
    change(data)
    with pytest.raises(RobotsError, match=says) as e:
        parse_robots(data, "r.toml")
    assert str(e.value).startswith("r.toml: invalid robots file") and e.value.exit_code == ExitCode.USAGE
    path = tmp_path / "r.toml"
    path.write_text(to_toml(data))
    res = invoke("robots", "sim", str(TURTLEBOT), "--robots", str(path))
    assert res.exit_code == ExitCode.USAGE and "Traceback" not in res.output, res.output
    assert f"{path}: invalid robots file" in res.output
