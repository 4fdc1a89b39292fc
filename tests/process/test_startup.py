"""Start-up and its files: a world or an agent stopped in its first
second exits and leaves nothing behind; `swarm up` waits for the world's own word that it
listens (swarm/contracts/startup.py), not a fixed time; the files of a killed world are
swept by the next `swarm runs`. (A spawned agent logs into the run's `logs/`:
test_live_cli.py, on its shared run.)

Real processes, real zenoh on Unix sockets in private runtime dirs; outcomes only, with
generous deadlines (a loaded 2-core machine must pass), never elapsed times.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, Runtime, agent_cmd, short_runtime_dir, swarm_cmd, wait_for
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts.runtime_sweep import sweep_stale
from swarm.contracts.startup import ENV_READY_FD, READY, Announcer, ReadyWait
from swarm.contracts.stop_signals import StopSignals
from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import wait_until

REPO = Path(__file__).resolve().parents[2]
EXIT_DEADLINE = DEADLINE  # s for a stopped process to exit: an outcome, not a timing


# --- the parts, in this process -----------------------------------------------------------------
class Stopped(BaseException):
    pass


def test_held_signal_is_raised_when_the_block_ends():
    stops = StopSignals(lambda signum: Stopped(signum)).install()
    try:
        reached = False
        with pytest.raises(Stopped):
            with stops.held():
                os.kill(os.getpid(), signal.SIGTERM)
                wait_until(lambda: stops.pending, DEADLINE)
                reached = True  # the signal did not interrupt the block
        assert reached and stops.fired
        os.kill(os.getpid(), signal.SIGTERM)  # `once`: a second signal is ignored
    finally:
        stops.restore()


def test_ready_pipe_steps_and_end():
    r, w = os.pipe()
    wait = ReadyWait(r)
    tell = Announcer(w)
    tell.say("credentials")
    tell.say("listening")
    assert not wait.poll(1.0) and wait.doing() == "opening its hub (zenoh.open)"
    tell.ready()  # closes its end
    assert wait.wait(DEADLINE) and wait.step == READY
    wait.close()
    r, w = os.pipe()
    wait = ReadyWait(r)
    os.close(w)  # a world that exits before it is ready
    assert not wait.wait(DEADLINE) and wait.ended and wait.doing().startswith("starting")
    wait.close()


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_sweep_removes_only_files_whose_owner_is_gone(tmp_path):
    d = tmp_path
    dead, alive = _dead_pid(), os.getpid()
    for run, pid in (("dead", dead), ("live", alive)):
        (d / f"{run}.cred").write_text(json.dumps({"v": 1, "run": run, "endpoint": "x", "pid": pid}))
        os.chmod(d / f"{run}.cred", 0o600)
        (d / f"{run}.sock").write_text("")
        (d / f"{run}.sock.lock").write_text("")
    (d / "dead.tls").mkdir()
    (d / "orphan.sock.lock").write_text("")  # a lock nobody holds, of no run
    (d / "held.sock").write_text("")  # a socket whose lock is held (something listens): kept
    (d / "held.sock.lock").write_text("")
    (d / "other.txt").write_text("")
    fd = os.open(d / "held.sock.lock", os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        removed = {p.name for p in sweep_stale(d)}
    finally:
        os.close(fd)
    assert removed == {"dead.cred", "dead.sock", "dead.sock.lock", "dead.tls", "orphan.sock.lock"}
    assert sorted(p.name for p in d.iterdir()) == [
        "held.sock",
        "held.sock.lock",
        "live.cred",
        "live.sock",
        "live.sock.lock",
        "other.txt",
    ]


# --- a world process stopped while it starts ---------------------------------------------------------
@contextmanager
def world_process(rt_dir: str, run: str = "st", *extra):
    """`swarm world` (case2, no agents: it waits for them) with its start-up pipe: (Popen, ReadyWait).
    Killed (its own group) if a test leaves it running."""
    r, w = os.pipe()
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt_dir, ENV_READY_FD: str(w)}
    p = subprocess.Popen(
        swarm_cmd("world", SCENARIOS / "case2.toml", "--run", run, *extra),
        env=env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        pass_fds=(w,),
        start_new_session=True,
        cwd=REPO,
    )
    os.close(w)
    wait = ReadyWait(r)
    try:
        yield p, wait
    finally:
        wait.close()
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()


def _exit_of(p: subprocess.Popen) -> int | None:
    try:
        return p.wait(EXIT_DEADLINE)
    except subprocess.TimeoutExpired:
        return None


@pytest.mark.slow
@pytest.mark.parametrize("when", ["0", "0.05", "0.15", "0.3", "0.6", "step", "ready"])
def test_world_stopped_in_its_first_second_exits_and_leaves_no_files(when):
    """SIGTERM at a point of a world's start (s after it started; at its first start-up word;
    once it said it listens): it exits, and its runtime dir is empty."""
    rt = short_runtime_dir()
    try:
        with world_process(rt) as (p, wait):
            if when == "step":
                wait_for(lambda: wait.poll(0.05) or wait.step or wait.ended, DEADLINE, "the world's first word")
            elif when == "ready":
                assert wait.wait(DEADLINE), f"the world did not get ready (last word {wait.step!r})"
            else:
                time.sleep(float(when))
            p.send_signal(signal.SIGTERM)
            code = _exit_of(p)
            assert code is not None, f"the world did not exit within {EXIT_DEADLINE} s of SIGTERM ({when})"
            assert code in (ExitCode.TERMINATED, -signal.SIGTERM), code
        assert sorted(os.listdir(rt)) == []
    finally:
        shutil.rmtree(rt, ignore_errors=True)


@pytest.mark.slow
def test_killed_world_files_are_swept_by_swarm_runs(monkeypatch):
    """A SIGKILLed world leaves .cred, .sock and .sock.lock; the next `swarm runs` removes
    them, and leaves those of a live world alone."""
    rt = short_runtime_dir()
    monkeypatch.setenv("SWARM_RUNTIME_DIR", rt)

    with world_process(rt, "dead") as (p, wait), world_process(rt, "alive") as (q, qwait):
        assert wait.wait(DEADLINE) and qwait.wait(DEADLINE)
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        assert {"dead.cred", "dead.sock", "dead.sock.lock"} <= set(os.listdir(rt))
        res = CliRunner().invoke(app, ["runs", "--json"])
        assert res.exit_code == ExitCode.OK, res.output
        assert [d["run"] for d in json.loads(res.stdout)] == ["alive"]
        assert sorted(os.listdir(rt)) == ["alive.cred", "alive.sock", "alive.sock.lock"]
        q.send_signal(signal.SIGTERM)
        assert _exit_of(q) == ExitCode.TERMINATED
    assert os.listdir(rt) == []


# --- an agent stopped while it starts -------------------------------------------------------------------
@pytest.mark.slow
def test_agent_stopped_in_its_first_second_exits():
    """SIGTERM to an agent process at points of its first second (connecting, joining): it
    exits with 143 (or the default signal death before its handlers), never hangs."""
    rt = short_runtime_dir()
    env = {**os.environ, "SWARM_RUNTIME_DIR": rt}
    try:
        with world_process(rt, "ag") as (w, wait):
            assert wait.wait(DEADLINE)
            endpoint = f"unixsock-stream/{rt}/ag.sock"
            for delay in (0.0, 0.15, 0.3, 0.6, 1.0):
                a = subprocess.Popen(
                    agent_cmd(1, endpoint, "ag"),
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    start_new_session=True,
                )
                try:
                    time.sleep(delay)
                    a.send_signal(signal.SIGTERM)
                    code = _exit_of(a)
                    assert code is not None, f"agent did not exit within {EXIT_DEADLINE} s of SIGTERM at {delay} s"
                    assert code in (ExitCode.TERMINATED, -signal.SIGTERM, ExitCode.OK), code
                finally:
                    if a.poll() is None:
                        os.killpg(a.pid, signal.SIGKILL)
                        a.wait()
            w.send_signal(signal.SIGTERM)
            assert _exit_of(w) == ExitCode.TERMINATED
    finally:
        shutil.rmtree(rt, ignore_errors=True)


# --- swarm up ---------------------------------------------------------------------------------------
SLOW_WORLD = """\
import os, time
args = open("/proc/self/cmdline", "rb").read().split(b"\\0")
if args[1:4] == [b"-m", b"swarm", b"world"]:
    time.sleep(float(os.environ["SLOW_WORLD_S"]))
"""


@pytest.mark.slow
def test_up_waits_for_a_slow_world(tmp_path):
    """A world that takes 16 s to start (longer than the fixed 15 s wait there was): `swarm
    up` waits for its word that it listens, and the run completes."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SLOW_WORLD)
    with Runtime(tmp_path) as rt:
        env = {
            **rt.env,
            "SLOW_WORLD_S": "16",
            "PYTHONPATH": os.pathsep.join([str(site), rt.env.get("PYTHONPATH", "")]).rstrip(os.pathsep),
        }
        up = rt.tracker.spawn(
            swarm_cmd(
                "up",
                SCENARIOS / "case2.toml",
                "--out",
                tmp_path / "run",
                "--no-plots",
                "--duration",
                "1",
                "--clock",
                "lockstep",
            ),
            "up",
            env=env,
        )
        code = up.wait(240)
        assert code == ExitCode.OK, up.text()[-3000:]
        assert "cannot reach" not in up.text() and (tmp_path / "run" / "summary.json").exists()
