"""The simulated fleet (swarm/robots/fleet.py): the robot's body (unicycle, saturation, the
command watchdog), the latency of its poses, their noise and frames; then the fleet over real
zenoh, as `swarm robots sim` runs it."""

from __future__ import annotations

import math
import statistics

import pytest

from swarm.contracts.orbits import wrap
from swarm.robots.fleet import Delayed, FleetOptions, PoseNoise, Unicycle, odom_pose, saturate, world_pose
from swarm.world.kinematics import step_one

BURGER = (0.22, 2.84)


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
    for bad in ({"rate": 0.0}, {"latency": -1.0}, {"time_scale": math.inf}, {"cmd_timeout": math.nan}):
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
