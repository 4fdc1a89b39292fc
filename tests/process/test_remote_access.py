"""An agent on "another machine" (its own empty runtime dir, so nothing local to find)
joins a run that listens on TLS, with one identity exported by `swarm credentials`:
the recipe of docs/guides/several-machines.md#remote-agent, run for real over zenoh (tls/127.0.0.1)."""

from __future__ import annotations

import json
import os
import signal
import socket
import stat
from pathlib import Path

import pytest
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, agent_info, make_env, start_up, swarm_cmd

from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_agent_elsewhere_rejoins_over_tls_with_an_exported_identity(rt, tmp_path):
    """The world listens on every interface (as across machines); its own agents dial
    127.0.0.1, the one elsewhere the address its exported file names."""
    port = _free_port()
    listen, endpoint = f"tls/0.0.0.0:{port}", f"tls/127.0.0.1:{port}"
    up = start_up(
        rt.tracker,
        SCENARIOS / "case2.toml",
        tmp_path / "run",
        "--clock",
        "realtime",
        "--duration",
        "600",
        "--listen",
        listen,
    )
    run_id, ep = up.banner()
    assert ep == listen
    up.wait_started(DEADLINE)
    pids = rt.tracker.wait_agent_pids(up.launcher, 6)

    # the operator exports agent 3's identity (and the run's CA) for the other machine
    cred = tmp_path / "agent-3.cred"
    p = rt.tracker.spawn(
        swarm_cmd("credentials", "--agent", "3", "--run", run_id, "--endpoint", endpoint, "-o", cred), "export"
    )
    assert p.wait(DEADLINE) == ExitCode.OK, p.text()
    assert stat.S_IMODE(cred.stat().st_mode) == 0o600
    doc = json.loads(cred.read_text())
    assert doc["user"] == "agent-3" and "secret" not in doc and doc["tls_ca"].startswith("-----BEGIN CERTIFICATE")
    assert doc["endpoint"] == endpoint

    os.kill(pids[3], signal.SIGKILL)
    up.wait_info(lambda i: not agent_info(i, 3)["alive"], DEADLINE, "agent 3 to drop")

    elsewhere = make_env(str(tmp_path / "elsewhere"))  # nothing of the run's there
    wrong = rt.tracker.spawn(
        swarm_cmd("agent", "--id", "4", "--connect", endpoint, "--credentials", cred),
        "agent-4-elsewhere",
        env=elsewhere,
    )
    assert wrong.wait(DEADLINE) == ExitCode.REFUSED
    assert "are for 'agent-3' of run" in wrong.text() and "not 'agent-4'" in wrong.text()

    agent = rt.tracker.spawn(
        swarm_cmd("agent", "--id", "3", "--connect", endpoint, "--credentials", cred),
        "agent-3-elsewhere",
        env=elsewhere,
    )
    info = up.wait_info(lambda i: agent_info(i, 3)["alive"], DEADLINE, "agent 3 to rejoin from elsewhere")
    assert agent_info(info, 3)["pid"] == agent.pid and agent_info(info, 3)["joins"] == 2

    os.kill(up.launcher.pid, signal.SIGINT)
    assert up.launcher.wait(DEADLINE) == ExitCode.INTERRUPTED
    assert agent.wait(DEADLINE) == ExitCode.OK  # the world's end notice reached it over TLS
    rt.tracker.assert_none_left(timeout=DEADLINE)
    summ = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summ["agents"]["3"]["joins"] == 2 and summ["agents"]["3"]["pid"] == agent.pid
    # the run's credentials and certificates are gone with it
    assert sorted(p.name for p in Path(rt.dir).iterdir()) == [], list(Path(rt.dir).iterdir())
