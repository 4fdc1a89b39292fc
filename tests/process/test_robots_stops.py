"""Stops that do not depend on the world (docs/guides/robots.md#stops), with real processes on
real zenoh: `swarm up --robots` zero-twists every robot when its world exits (SIGKILL here),
`swarm estop` from a second terminal (world running, stalled with SIGSTOP, killed), and
`swarm robots guard` next to the fleet's router when the world's commands stop. The fleet
(`swarm robots sim`, one for the module: `fleet`) is the robots; the wire (a client of its
router, test_robots_e2e.Wire) sees each twist as it arrives. The tests assert outcomes (the last
twist each robot got is zero, and came after the fault; the run ended; nothing left); the delays
are benchmarks/robots_stops.py's.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
from deadlines import DEADLINE
from runtime_helpers import Runtime, start_up, swarm_cmd, wait_for
from test_robots_e2e import ROBOT, TURTLEBOT, start_fleet, stop_fleet, wait_moving

import swarm
from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow


def last_is_zero_after(wire, ns: str, event: float) -> bool:
    """Whether the last twist `ns` received is zero and arrived after `event`."""
    twists = wire.twists_of(ns)
    return bool(twists) and twists[-1][0] > event and twists[-1][1:] == (0.0, 0.0)


def world_pid_of(rt, up) -> int:
    return wait_for(lambda: rt.tracker.world_pid(up.launcher), DEADLINE, "the world's pid")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """One `swarm robots sim` (no watchdog on the robots: --cmd-timeout 3600) for the module's
    tests, each with runs of its own on it (a run takes its robots' poses as they stand before its
    tick 0: a run after another starts where the robots were left): (its robots file, the wire).
    Each test sees its robots' zero twists on the wire; the fleet's own report, when it is
    stopped after the last test, says it left every robot stopped by a zero twist. (A fleet per
    test was five starts and stops of `swarm robots sim`.)"""
    base = tmp_path_factory.mktemp("fleet")
    with Runtime(base) as frt:
        tracked, robots, wire = start_fleet(frt, base, "--cmd-timeout", "3600")
        yield robots, wire
        report = stop_fleet(frt, tracked)
    assert report.count("stopped by a zero twist") == 2, report


def run_on(rt, tmp_path, robots, wire):
    """`swarm up` of the turtlebot scenario on the fleet, once both robots move under it."""
    since = time.monotonic()  # (the wire holds the twists of the module's earlier runs too)
    up = start_up(rt.tracker, TURTLEBOT, tmp_path / "run", "--robots", robots, "--duration", 120)
    wait_moving(up, wire, since)
    return up


def test_a_killed_world_leaves_every_robot_zero_twisted_by_swarm_up(rt, tmp_path, fleet):
    robots, wire = fleet
    up = run_on(rt, tmp_path, robots, wire)
    world = world_pid_of(rt, up)
    event = time.monotonic()
    os.kill(world, signal.SIGKILL)
    code = up.launcher.wait(DEADLINE)
    assert code != ExitCode.OK, up.launcher.text()[-3000:]
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"a zero twist for {ns}")
        wire.report("SIGKILL of the world", ns, event)
    text = up.launcher.text()
    assert "robots: zero twist sent to 2 robots (the world exited: killed by SIGKILL)" in text, text[-3000:]
    # `swarm estop` from another terminal, its world killed (the estop test's third case, on this
    # run: one fleet and one run less): it zero-twists every robot again and says the run is over
    event = time.monotonic()
    estop = rt.tracker.spawn(swarm_cmd("estop"), "estop")  # the run's robots file: from its record
    assert estop.wait(DEADLINE) == ExitCode.OK, estop.text()[-3000:]
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"a zero twist for {ns}")
        wire.report("swarm estop, world killed", ns, event)
    out = estop.text()
    assert "estop: zero twist sent to 2 robots" in out, out
    assert "its world was gone" in out or "had ended" in out, out
    ended = time.monotonic()
    for ns in ROBOT.values():
        assert last_is_zero_after(wire, ns, event) and not wire.moving_since(ns, ended)


@pytest.mark.parametrize("world_state", ["running", "stalled"])  # (killed: the test above)
def test_estop_from_another_terminal_zero_twists_every_robot_and_ends_the_run(rt, tmp_path, world_state, fleet):
    robots, wire = fleet
    up = run_on(rt, tmp_path, robots, wire)
    world = world_pid_of(rt, up)
    if world_state == "stalled":
        os.kill(world, signal.SIGSTOP)
    elif world_state == "killed":
        os.kill(world, signal.SIGKILL)
    event = time.monotonic()
    estop = rt.tracker.spawn(swarm_cmd("estop"), "estop")  # the run's robots file: from its record
    assert estop.wait(DEADLINE) == ExitCode.OK, estop.text()[-3000:]
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"a zero twist for {ns}")
        wire.report(f"swarm estop, world {world_state}", ns, event)
    out = estop.text()
    assert "estop: zero twist sent to 2 robots" in out, out
    code = up.launcher.wait(DEADLINE)  # the run has ended
    if world_state == "running":  # through the world, as `swarm stop` ends it
        assert code == ExitCode.INTERRUPTED and "stopped at tick" in out, out + up.launcher.text()[-3000:]
    elif world_state == "stalled":
        assert "killed with SIGKILL" in out and "has ended the run" in out, out
    else:
        assert "its world was gone" in out or "had ended" in out, out
    # and no robot moved again after the run ended
    ended = time.monotonic()
    for ns in ROBOT.values():
        assert last_is_zero_after(wire, ns, event) and not wire.moving_since(ns, ended)


def test_estop_with_a_robots_file_and_no_run(rt, fleet):
    robots, wire = fleet
    event = time.monotonic()
    estop = rt.tracker.spawn(swarm_cmd("estop", "--robots", robots), "estop")
    assert estop.wait(DEADLINE) == ExitCode.OK, estop.text()[-3000:]
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"a zero twist for {ns}")
    assert estop.text().count("\n") == 1, estop.text()  # the robots only: no run to end
    nothing = rt.tracker.spawn(swarm_cmd("estop"), "estop-none")
    assert nothing.wait(DEADLINE) == ExitCode.USAGE
    assert "give --robots FILE" in nothing.text() and nothing.text().count("\n") == 1, nothing.text()


def test_the_guard_zero_twists_a_robot_whose_commands_stopped_and_lets_it_go_again(rt, tmp_path, fleet):
    robots, wire = fleet
    guard = rt.tracker.spawn(swarm_cmd("robots", "guard", "--robots", robots, "--cmd-timeout", "0.3"), "guard")
    wait_for(lambda: guard.check_running("the guard") or "Ctrl-C stops it" in guard.text(), DEADLINE, "the guard")
    up = run_on(rt, tmp_path, robots, wire)
    assert "zero twist sent" not in guard.text(), guard.text()  # while commands flow: nothing
    world = world_pid_of(rt, up)
    os.kill(world, signal.SIGSTOP)  # its commands stop (its own watchdog with it)
    event = time.monotonic()
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"the guard's zero twist for {ns}")
        wire.report("the world's commands stopped (SIGSTOP), the guard", ns, event)
    wait_for(lambda: guard.text().count("zero twist sent") == 2, DEADLINE, "the guard's lines")
    os.kill(world, signal.SIGCONT)  # commands again: the guard lets them through
    wait_moving(up, wire, since=time.monotonic())
    wait_for(lambda: guard.text().count("commands again") == 2, DEADLINE, "the guard to see commands again")
    event = time.monotonic()
    up.launcher.popen.send_signal(signal.SIGINT)
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    for ns in ROBOT.values():  # the run's own zero twists at its end
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"the run's zero twist for {ns}")
    guard.popen.send_signal(signal.SIGINT)
    assert guard.wait(DEADLINE) == ExitCode.INTERRUPTED, guard.text()
    assert guard.text().count("zero twist sent") == 2, guard.text()  # the run's own end stopped the robots


@pytest.mark.parametrize(
    ("guard", "field"),
    [
        ({"cmd_timeout": 0}, "guard.cmd_timeout"),
        ({"cmd_timeout": 61}, "guard.cmd_timeout"),
        ({"connect": "nowhere"}, "guard"),
        ({"cmd_timeout": 0.5, "extra": 1}, "guard.extra"),
    ],
)
def test_a_bad_guard_table_is_refused_naming_its_field(guard, field):
    from fleet_support import robots_file

    from swarm.robots.config import RobotsError, parse_robots

    assert parse_robots({**robots_file(), "guard": {"cmd_timeout": 0.25}}).guard.cmd_timeout == 0.25
    assert parse_robots(robots_file()).guard.cmd_timeout == 0.5
    with pytest.raises(RobotsError, match=field.replace(".", r"\.")):
        parse_robots({**robots_file(), "guard": guard}, "robots.toml")


def test_estop_ready_stops_every_robot_on_enter_and_the_api_stops_them_too(rt, tmp_path, monkeypatch, fleet):
    robots, wire = fleet
    up = run_on(rt, tmp_path, robots, wire)
    ready = subprocess.Popen(
        swarm_cmd("estop", "--ready"), env=rt.tracker.env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert ready.stdout is not None and ready.stdin is not None
        assert "estop ready: run " in ready.stdout.readline()
        wait_moving(up, wire, since=time.monotonic())  # connected, nothing sent: the robots drive on
        event = time.monotonic()
        ready.stdin.write("\n")
        ready.stdin.close()
        assert ready.wait(DEADLINE) == ExitCode.OK
        out = ready.stdout.read()
    finally:
        if ready.poll() is None:
            ready.kill()
            ready.wait()
    assert "estop: zero twist sent to 2 robots" in out and "stopped at tick" in out, out
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"a zero twist for {ns}")
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    # the Python API, with the robots file and no run: the robots only
    monkeypatch.setenv("SWARM_RUNTIME_DIR", rt.tracker.env["SWARM_RUNTIME_DIR"])
    event = time.monotonic()
    done = swarm.estop(robots=robots, end=False)
    assert done.robots == 2 and done.run is None and done.ended is None
    for ns in ROBOT.values():
        wait_for(lambda ns=ns: last_is_zero_after(wire, ns, event), DEADLINE, f"the API's zero twist for {ns}")


def test_the_stops_open_the_same_zenoh_client_as_the_rest_of_the_project(tmp_path):
    """swarm/robots/halt.py writes swarm.contracts.transport's client settings out (its start-up)."""
    from swarm.contracts import tls, transport
    from swarm.robots import halt

    password = tmp_path / "pw"
    password.write_text("secret\n")
    plan = halt.HaltPlan(
        "tls/127.0.0.1:7447",
        0,
        "jazzy",
        (halt.Target(1, "", "/cmd_vel", ("Twist",)),),
        "swarm",
        str(password),
        "/ca.pem",
        "/me.pem",
        "/me.key",
    )
    ours = plan.zenoh_config()
    theirs = transport.client_config(
        plan.connect,
        timeout_ms=halt.OPEN_TIMEOUT_MS,
        identity=("swarm", "secret"),
        tls={
            f"{tls.TLS}/root_ca_certificate": "/ca.pem",
            f"{tls.TLS}/connect_certificate": "/me.pem",
            f"{tls.TLS}/connect_private_key": "/me.key",
            f"{tls.TLS}/enable_mtls": True,
        },
    )
    assert (halt.TLS, halt.LEASE_MS) == (tls.TLS, transport.LEASE_MS)
    for key in ("mode", "connect", "scouting", "transport"):
        assert ours.get_json(key) == theirs.get_json(key), key
