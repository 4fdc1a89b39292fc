"""Strangers at the hub's door (docs/guides/security.md#door): idle connections that never speak must not
shut the run's own processes out, and a session the hub did not let in is reported as such
(one line naming the endpoint), never as "run not found".

No timed assertions: a loaded 2-core machine must pass (generous deadlines only);
benchmarks/bench_door.py prints the figures."""

from __future__ import annotations

import os
import re
import selectors
import socket
import subprocess
import threading
from contextlib import contextmanager

import pytest
from deadlines import DEADLINE
from runtime_helpers import REPO, SCENARIOS, live_swarm, swarm_cmd

from swarm.contracts import credentials
from swarm.contracts.errors import NoRunError
from swarm.contracts.vocabulary import ExitCode
from swarm.live import client
from swarm.live.client import open_run_session


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def idle_crowd(port: int, n: int):
    """`n` TCP connections to 127.0.0.1:`port` that never send a byte, each reopened as soon as
    the other side closes it, until the block ends."""
    stop = threading.Event()
    sel = selectors.DefaultSelector()
    opened = threading.Event()

    def hold() -> None:
        while not stop.is_set():
            while len(sel.get_map()) < n and not stop.is_set():
                s = socket.socket()
                s.settimeout(1.0)
                try:
                    s.connect(("127.0.0.1", port))
                except OSError:
                    s.close()
                    continue
                s.setblocking(False)
                sel.register(s, selectors.EVENT_READ)
            opened.set()
            for key, _ in sel.select(0.05):
                try:
                    gone = key.fileobj.recv(4096) == b""
                except BlockingIOError:
                    gone = False
                except OSError:
                    gone = True
                if gone:
                    sel.unregister(key.fileobj)
                    key.fileobj.close()

    t = threading.Thread(target=hold, daemon=True)
    t.start()
    try:
        assert opened.wait(DEADLINE), f"could not open {n} connections to port {port}"
        yield
    finally:
        stop.set()
        t.join(30)
        for key in list(sel.get_map().values()):
            key.fileobj.close()


@pytest.mark.slow
def test_idle_connections_do_not_lock_the_run_out(tmp_path_factory):
    port = free_port()
    base = tmp_path_factory.mktemp("door")
    with live_swarm(
        base, SCENARIOS / "case2.toml", 6, "--duration", "600", "--listen", f"tcp/127.0.0.1:{port}", timeout=DEADLINE
    ) as state:
        env = {**os.environ, "SWARM_RUNTIME_DIR": str(state["runtime"])}
        for k in ("SWARM_RUN", "SWARM_CONNECT", "SWARM_CREDENTIALS"):
            env.pop(k, None)
        ep = f"tcp/127.0.0.1:{port}"
        with idle_crowd(port, 200):
            # through the run's local door, and through the network port the strangers crowd
            for extra in ((), ("--connect", ep)):
                res = subprocess.run(
                    swarm_cmd("agents", "--run", state["run"], *extra),
                    env=env,
                    cwd=REPO,
                    capture_output=True,
                    text=True,
                    timeout=DEADLINE,
                )
                assert res.returncode == ExitCode.OK, (
                    f"swarm agents {' '.join(extra)} exited {res.returncode}: {res.stderr}"
                )
                assert state["run"] in res.stdout
                assert all(re.search(rf"^\s*{i}\s+(leader|follower)\s+\d+", res.stdout, re.M) for i in range(1, 7)), (
                    res.stdout
                )


def _creds_file(tmp_path, endpoint: str):
    return credentials.write(credentials.new_credentials("door-test", endpoint), tmp_path / "door.cred")


@pytest.fixture
def short_window(monkeypatch):
    """The answer window of a session to a hub (swarm.live.client.OPEN_TIMEOUT_S, 3 s) at 1 s:
    what a hub that never lets the session in is said to be does not depend on its length."""
    real = client._probe
    monkeypatch.setattr(client, "_probe", lambda ref, timeout=0.5, open_timeout=1.0: real(ref, timeout, open_timeout))


@pytest.mark.slow  # each waits out an answer window (1 s here)
@pytest.mark.usefixtures("short_window")
def test_a_hub_that_does_not_answer_is_not_a_missing_run(tmp_path):
    lsn = socket.socket()  # accepts connections (the kernel does) and never answers
    lsn.bind(("127.0.0.1", 0))
    lsn.listen(8)
    ep = f"tcp/127.0.0.1:{lsn.getsockname()[1]}"
    try:
        with pytest.raises(NoRunError) as e:
            open_run_session(creds_file=_creds_file(tmp_path, ep))
    finally:
        lsn.close()
    msg = str(e.value)
    assert f"the hub at {ep} did not answer" in msg and "not found" not in msg and "\n" not in msg, msg


@pytest.mark.slow  # each waits out an answer window (1 s here)
@pytest.mark.usefixtures("short_window")
def test_a_hub_that_closes_at_once_refused_the_session(tmp_path):
    lsn = socket.socket()  # closes every connection as soon as it comes (a hub whose places are taken)
    lsn.bind(("127.0.0.1", 0))
    lsn.listen(64)
    ep = f"tcp/127.0.0.1:{lsn.getsockname()[1]}"
    stop = threading.Event()

    def slam() -> None:
        lsn.settimeout(0.1)
        while not stop.is_set():
            try:
                c, _ = lsn.accept()
                c.close()
            except OSError:
                pass

    t = threading.Thread(target=slam, daemon=True)
    t.start()
    try:
        with pytest.raises(NoRunError) as e:
            open_run_session(creds_file=_creds_file(tmp_path, ep))
    finally:
        stop.set()
        t.join(10)
        lsn.close()
    msg = str(e.value)
    assert f"the hub at {ep} refused the session" in msg and "not found" not in msg and "\n" not in msg, msg


def test_nothing_listening_is_still_not_found(tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"
    with pytest.raises(NoRunError) as e:
        open_run_session(creds_file=_creds_file(tmp_path, ep))
    assert "not found" in str(e.value) or "no swarm" in str(e.value), str(e.value)
