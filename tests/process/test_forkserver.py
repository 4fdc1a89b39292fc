"""The agents' fork server (agents/forkserver.py, swarm/runtime/forks.py).

Fast: the server's protocol (a bad request is an error reply, the end of its stdin ends
it), the launcher's handle of an adopted child (exit codes, signals, two threads polling),
command lines as words. Slow, real processes over real zenoh: under `swarm up` every agent
is forked, titled with the command line it would have had, and the launcher's child; a
fork server killed mid-run does not stop a scripted restart, which execs the agent instead.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import psutil
import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, events_of, start_up

from swarm.agents.forkserver import REPARENT_WAIT, reparented
from swarm.runtime.forks import Forked
from swarm.runtime.procs import agent_id_of, command_words


def _server():
    return subprocess.Popen(
        [sys.executable, "-m", "swarm.agents.forkserver"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


@pytest.mark.slow
def test_a_bad_request_is_an_error_reply_and_the_end_of_stdin_ends_the_server():
    p = _server()
    try:
        out, err = p.communicate(b'{"argv": ["1"]}\nnot json\n', timeout=DEADLINE)
    finally:
        p.kill() if p.poll() is None else None
    replies = [json.loads(line) for line in out.splitlines()]
    assert replies[0] == {"ready": True} and [sorted(r) for r in replies[1:]] == [["error"], ["error"]], (out, err)
    assert "log" in replies[1]["error"] and p.returncode == 0, (replies, err)


def _child(code: int | None, sleep: float = 0.0) -> Forked:
    pid = os.fork()
    if pid == 0:  # pragma: no cover (the child)
        time.sleep(sleep)
        os._exit(code or 0)
    return Forked(pid, ["child"])


@pytest.mark.slow
def test_forked_reads_the_exit_code_once_from_two_threads():
    f = _child(7, sleep=0.2)
    assert f.poll() is None
    seen = []
    threads = [threading.Thread(target=lambda: seen.append(f.wait(DEADLINE))) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert seen == [7, 7] and f.returncode == 7 and f.poll() == 7


def test_forked_kill_is_a_negative_code_and_a_timeout_raises():
    f = _child(0, sleep=30)
    with pytest.raises(subprocess.TimeoutExpired):
        f.wait(0.05)
    f.kill()
    assert f.wait(DEADLINE) == -signal.SIGKILL
    f.kill()  # already reaped: nothing to signal, no error


def test_an_agent_waits_only_while_its_parent_is_the_middle_process():
    assert reparented(os.getppid() + 10**6, timeout=5.0)  # another pid than the parent: at once
    assert not reparented(os.getppid(), timeout=0.05)  # still the middle's: gives up at the timeout


def test_command_words_of_exec_d_and_titled_agents():
    exec_d = [sys.executable, "-m", "swarm.agents.process", "12", "unixsock-stream//x.sock", "run-1", ""]
    titled = [" ".join(exec_d[:-1]), "", "", ""]
    assert command_words(exec_d) == command_words(titled) == exec_d[:-1]
    assert agent_id_of(exec_d) == agent_id_of(titled) == 12
    assert agent_id_of([sys.executable, "-m", "swarm", "world"]) is None
    assert agent_id_of([sys.executable, "-m", "swarm.agents.process"]) is None


FAULTS = """
[[faults]]
at = 1.5
kind = "kill"
agent = 4

[[faults]]
at = 2.0
kind = "restart"
agent = 4
"""


@pytest.mark.slow
def test_agents_are_forked_and_a_dead_fork_server_falls_back_to_exec(rt, tmp_path):
    scenario = tmp_path / "case2-restart.toml"
    scenario.write_text((SCENARIOS / "case2.toml").read_text() + FAULTS)
    # realtime, so that the server is dead well before the scripted restart (t = 2 s of wall time;
    # the world holds the run at the restart's tick until the exec'd agent has joined; the server
    # is killed at t ~ 0.2 s even on a loaded machine, so the kill at 1.5 s leaves a wide margin)
    up = start_up(rt.tracker, scenario, tmp_path / "run", "--clock", "realtime", "--duration", "2.5")
    up.wait_started(DEADLINE)
    pids = rt.tracker.wait_agent_pids(up.launcher, 6)
    for aid, pid in pids.items():
        proc = psutil.Process(pid)
        assert proc.ppid() == up.launcher.pid, f"agent {aid}: parent {proc.ppid()}, not the launcher"
        raw = open(f"/proc/{pid}/cmdline", "rb").read()
        assert b"\0agents.process\0" not in raw and agent_id_of(proc.cmdline()) == aid, raw  # titled, not exec'd
    (server,) = [c for c in psutil.Process(up.launcher.pid).children() if "swarm.agents.forkserver" in c.cmdline()]
    os.kill(server.pid, signal.SIGKILL)  # before the scripted kill (t = 1.5 s)
    assert up.info()["time"] < 1.2

    summ, _ = up.results(120)
    assert summ["completed"] is True
    (start,) = events_of(summ, "start")  # no agent waited out its re-parenting (a bug once did)
    assert start["startup_s"] < REPARENT_WAIT, start
    (rejoin,) = events_of(summ, "rejoin", 4)
    assert rejoin["tick"] == 200, rejoin
    text = up.launcher.text()
    assert "agents are exec'd from now on" in text, text[-2000:]
    assert [s for s in rt.tracker.descendants(up.launcher) if agent_id_of(s.cmdline) == 4 and s.pid != pids[4]]
