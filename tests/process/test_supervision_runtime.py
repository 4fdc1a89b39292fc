"""`swarm up` supervises (real processes over real zenoh; tests/support/runtime_helpers.py):

- an agent whose follower law raises is a `crash` event with the traceback's last line,
  and `swarm up` exits 4; hand-killed agents are `exit` events, and a run left with no
  agent ends (`deserted`, exit 5);
- a SIGKILLed launcher leaves no process of its run behind, and the world writes results;
- a world stopped (SIGSTOP) for 5 s: the run goes on and completes with every agent; past
  the grace an agent exits 5 saying why;
- errors before the first tick (bad endpoint, port in use, a law agents cannot import)
  are one line from `swarm up`.
"""

from __future__ import annotations

import os
import signal
import socket
import time

import pytest
from conftest import to_toml
from deadlines import DEADLINE
from runtime_helpers import (
    SCENARIOS,
    agent_cmd,
    events_of,
    has_started,
    observe_world,
    start_ticking,
    start_up,
    swarm_cmd,
)

from swarm.contracts.vocabulary import EventKind, ExitCode

pytestmark = pytest.mark.slow

# Followers that call their law RAISE_AFTER times, returning NaN on a few calls first.
RAISING_LAW = """
import math
calls = 0
def law(g_i, g_j, lam, c1, c2):
    global calls
    calls += 1
    if calls > {raise_after}:
        raise RuntimeError("the law gave up after {raise_after} calls")
    if 5 <= calls < 8:
        return math.nan
    return c1 * math.atan2(math.sin(g_j - g_i), math.cos(g_j - g_i)) + c2 * math.sin(lam - g_i)
"""
# Importable by `swarm up` (which checks the scenario) but not by agent processes.
UNLOADABLE_LAW = """
import os, sys
if sys.argv and sys.argv[0].endswith(os.path.join("agents", "process.py")):
    raise ImportError("this law cannot be loaded in an agent")
def law(g_i, g_j, lam, c1, c2):
    return 0.0
"""


def _law_scenario(rt, tmp_path, base, module: str, source: str):
    """The law module next to its scenario, in neither the processes' working directory nor
    PYTHONPATH: the world imports it from the scenario's directory, and the agents from
    $SWARM_LAW_PATH, which `swarm up` sets."""
    where = tmp_path / "scenario"
    where.mkdir()
    (where / f"{module}.py").write_text(source)
    assert str(where) not in rt.env.get("PYTHONPATH", "")
    base["gains"]["law"] = f"{module}:law"
    path = where / f"{module}.toml"
    path.write_text(to_toml(base))
    return path


def test_raising_law_is_a_crash_event_and_exit_4(rt, tmp_path, base):
    scen = _law_scenario(rt, tmp_path, base, "raising_law", RAISING_LAW.format(raise_after=40))
    # (the law gives up at 0.4 s: the leader runs the rest of the 5 s alone)
    up = start_up(rt.tracker, scen, tmp_path / "run", "--duration", "5", "--clock", "lockstep")
    rc = up.launcher.wait(120)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    text = up.launcher.text()
    assert rc == ExitCode.AGENT_FAILED, text[-3000:] + up.world_text()[-3000:]
    summ = up.summary()
    crashes = events_of(summ, EventKind.CRASH)
    assert sorted(e["agent"] for e in crashes) == [2, 3], summ["events"]
    for e in crashes:
        assert e["cause"] == "RuntimeError: the law gave up after 40 calls", e
        assert e["log"][-1] == e["cause"] and any('File "' in ln for ln in e["log"]), e["log"]
        assert e["code"] == 1 and e["reason"].endswith(e["cause"]), e
        assert f"agent {e['agent']} (pid {e['pid']}) crashed (exit code 1): {e['cause']}" in text, text
    # The leader lived on: the world finished the run.
    assert summ["completed"] is True and summ["agents"]["1"]["alive"] is True
    assert summ["converged"] is False, "a crashed agent: the run cannot count as converged"
    # Non-finite law outputs (3 per follower) were counted and said.
    for aid in (2, 3):
        log = (up.out / "logs" / f"agent-{aid}.log").read_text()
        assert "returned nan; the last turn rate is held (1 so far)" in log, log


def test_hand_killed_agents_are_exit_events_and_a_deserted_run_ends(rt, tmp_path):
    up, pids, _ = start_ticking(rt.tracker, tmp_path / "run", 150)
    for pid in pids.values():
        os.kill(pid, signal.SIGKILL)
    rc = up.launcher.wait(DEADLINE)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    assert rc == ExitCode.DESERTED, up.launcher.text()[-3000:]
    summ = up.summary()
    assert summ["completed"] is False and summ["ticks"] < 15000
    (end,) = events_of(summ, EventKind.DESERTED)
    assert end["agent"] is None and "no agent process" in end["reason"]
    exits = {e["agent"]: e for e in events_of(summ, EventKind.EXIT)}
    assert sorted(exits) == sorted(pids) and not events_of(summ, EventKind.CRASH), summ["events"]
    assert all(e["code"] == -signal.SIGKILL and "killed by SIGKILL" in e["reason"] for e in exits.values())
    assert "the run ended early: no agent process was left" in up.launcher.text()


def test_sigkilled_launcher_leaves_nothing_behind(rt, tmp_path):
    up, _, _ = start_ticking(rt.tracker, tmp_path / "run", 150)
    assert rt.tracker.world_pid(up.launcher) is not None
    t0 = time.monotonic()
    os.kill(up.launcher.pid, signal.SIGKILL)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    print(f"\n[timing] launcher SIGKILL -> no process of the run left: {time.monotonic() - t0:.2f} s")
    summ = up.summary()  # the world wrote what it had
    assert summ["stopped_by_signal"] == signal.SIGTERM and summ["completed"] is False and summ["ticks"] > 0


def test_world_stopped_for_5_s_the_run_goes_on(rt, tmp_path):
    up, pids, info = start_ticking(rt.tracker, tmp_path / "run", 10)
    world = rt.tracker.world_pid(up.launcher)
    os.kill(world, signal.SIGSTOP)
    try:
        time.sleep(5.0)
    finally:
        os.kill(world, signal.SIGCONT)
    after = up.wait_info(lambda i: i["tick"] > info["tick"] + 100, DEADLINE, "the world to tick again")
    assert all(a["alive"] for a in after["agents"].values()), after["agents"]
    summ, traj = up.results(180)
    assert summ["completed"] is True and summ["ticks"] == 1000
    assert {int(a) for a in summ["agents"]} == set(pids)
    for aid, a in summ["agents"].items():
        assert a["alive"] and a["joins"] == 1 and a["drops"] == 0, (aid, a)
    assert not [
        e for e in summ["events"] if e["kind"] in (EventKind.DROP, EventKind.REJOIN, EventKind.CRASH, EventKind.EXIT)
    ], summ["events"]
    assert traj["alive"][-1].all()
    for aid in pids:
        log = (up.out / "logs" / f"agent-{aid}.log").read_text()
        assert "the world answers again after" in log, log


def test_agent_gives_up_on_a_silent_world_after_its_grace(rt, tmp_path):
    endpoint, run_id = f"unixsock-stream/{rt.dir}/w.sock", "grace"
    w = rt.tracker.spawn(
        swarm_cmd(
            "world",
            SCENARIOS / "turtlebot.toml",
            "--listen",
            endpoint,
            "--run",
            run_id,
            "--out",
            tmp_path / "out",
            "--no-plots",
            "--duration",
            "4000",
            "--join-timeout",
            "120",
        ),
        "world",
    )
    world = observe_world(rt.tracker, w, endpoint, run_id)
    agents = {
        i: rt.tracker.spawn(agent_cmd(i, endpoint, run_id) + ["--world-grace", "1"], f"agent-{i}") for i in (1, 2)
    }
    world.wait(
        lambda i: has_started(i) and i["tick"] > 0,
        DEADLINE,
        "the run to start and tick",
        check=lambda: w.check_running("the run to start"),
    )
    world.close()
    t0 = time.monotonic()
    os.kill(w.pid, signal.SIGSTOP)
    try:
        codes = {i: a.wait(DEADLINE) for i, a in agents.items()}
        waited = time.monotonic() - t0
    finally:
        os.kill(w.pid, signal.SIGCONT)
    print(f"\n[timing] world SIGSTOP -> agents exit (grace 1 s): {waited:.2f} s")
    for i, a in agents.items():
        assert codes[i] == 5, a.text()
        last = a.text().strip().splitlines()[-1]
        assert "has not answered for 1 s (--world-grace); exiting" in last, a.text()
    assert waited >= 1.0  # not before its grace (how soon after it is a benchmark's matter)
    w.group.signal(signal.SIGTERM)
    w.wait(DEADLINE)
    rt.tracker.assert_none_left(timeout=DEADLINE)


def _one_line_failure(rt, tmp_path, *args, timeout: float = DEADLINE) -> tuple[int, str]:
    up = start_up(rt.tracker, SCENARIOS / "case2.toml", tmp_path / "run", *args)
    rc = up.launcher.wait(timeout)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    lines = [ln for ln in up.launcher.text().splitlines() if ln.startswith("swarm up:")]
    assert len(lines) == 1, up.launcher.text()
    return rc, lines[0]


def test_bad_endpoint_is_one_line(rt, tmp_path):
    """An endpoint that is not one is refused before anything starts (swarm/contracts/endpoints.py)."""
    up = start_up(rt.tracker, SCENARIOS / "case2.toml", tmp_path / "run", "--listen", "tcp/127.0.0.1:99999")
    rc = up.launcher.wait(DEADLINE)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    text = up.launcher.text().strip()
    assert (
        rc == ExitCode.USAGE
        and text == "--listen: not an endpoint: 'tcp/127.0.0.1:99999' (port 99999 is not in 0..65535)"
    ), text


def test_port_in_use_is_one_line(rt, tmp_path):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    try:
        port = s.getsockname()[1]
        rc, line = _one_line_failure(rt, tmp_path, "--listen", f"tcp/127.0.0.1:{port}")
    finally:
        s.close()
    assert rc == ExitCode.FAILED and "Address already in use" in line and f"127.0.0.1:{port}" in line, line


def test_law_agents_cannot_import_is_one_line(rt, tmp_path, base):
    scen = _law_scenario(rt, tmp_path, base, "unloadable_law", UNLOADABLE_LAW)
    t0 = time.monotonic()
    up = start_up(rt.tracker, scen, tmp_path / "run", "--duration", "60")
    rc = up.launcher.wait(DEADLINE)
    rt.tracker.assert_none_left(timeout=DEADLINE)
    lines = [ln for ln in up.launcher.text().splitlines() if ln.startswith("swarm up:")]
    assert rc == ExitCode.AGENT_FAILED and len(lines) == 1, up.launcher.text()
    assert "could not start (exit code 3)" in lines[0] and "this law cannot be loaded in an agent" in lines[0], lines
    print(f"\n[timing] unloadable law -> swarm up exit: {time.monotonic() - t0:.2f} s")
