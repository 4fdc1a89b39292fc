"""The live commands and `swarm up`'s progress line with 30 agents (a scenario written here:
30 agents on a spiral, two leaders, realtime clock at 20 Hz so that two cores keep up).

Real processes over real zenoh, as in tests/process/test_live_cli.py; the commands run in this
process through typer's CliRunner, and as processes where their whole cost is measured.
Speed is shown by printed figures ([timing] lines, `pytest -s`), with only a generous
sanity bound asserted. The offline parts of the progress line (agents added at run time)
are tested first, without a run.
"""

from __future__ import annotations

import json
import re
import statistics
import subprocess
import time

import numpy as np
import psutil
import pytest
from deadlines import DEADLINE
from runtime_helpers import live_swarm, reaped, ring_scenario, run_credentials, swarm_cmd, wait_for
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts import wire
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import AgentState, ExitCode
from swarm.live.client import LiveRun, RunRef
from swarm.live.data import snapshot
from swarm.runtime.progress import AddedSpec, added_spec, progress_errors, truth_progress

N = 30


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def timed(fn, repeat: int = 5) -> tuple[float, float, object]:
    """(median s, max s, last result) of `repeat` calls of fn() (few: the figures are printed,
    not asserted, and the 30 agents' processes run while they are taken)."""
    times, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), max(times), res


# --- offline: the progress line counts agents added at run time ------------------------------------
def test_progress_line_counts_added_agents(tmp_path):
    s = load_scenario(ring_scenario(tmp_path / "ring.toml", N))
    ids = list(range(1, N + 2))  # agent 31 was added at run time (`swarm spawn`)
    x = np.array([a.speed for a in s.agents] + [20.0])  # every agent on its expected orbit (leader 1: R = v)
    zeros = np.zeros(len(ids))
    out = [-1, -1] + [1] * (N - 2) + [1]
    buf = wire.encode_truth(100, 5.0, ids, x, zeros, zeros, zeros, out, [AgentState.ACTIVE] * len(ids))
    before = truth_progress(buf, s)
    assert sorted(before["errors"]) == list(range(1, N + 1)), "an unknown added agent is left out"
    spec = added_spec({"id": 31, "role": "follower", "speed": 20.0, "orbit_radius": None, "x": 1.0})
    assert spec == AddedSpec(31, "follower", 20.0, None)
    assert added_spec({"id": 31}) is None
    p = truth_progress(buf, s, {31: spec})
    assert sorted(p["errors"]) == ids and p["errors"][31] == pytest.approx(0.0, abs=1e-12)
    assert progress_errors(p) == "31 live: 31 settled"
    buf = wire.encode_truth(101, 5.05, ids, x, zeros, zeros, zeros, out, [AgentState.ACTIVE] * N + [AgentState.GONE])
    assert progress_errors(truth_progress(buf, s, {31: spec})) == "30 live: 30 settled; dropped 31"


# --- against a live swarm of 30 -------------------------------------------------------------------
@pytest.fixture(scope="module")
def many(tmp_path_factory):
    base = tmp_path_factory.mktemp("many")
    with live_swarm(base, ring_scenario(base / "ring30.toml", N), N) as state:
        yield state


@pytest.mark.slow
def test_live_commands_at_30_agents(many):
    with LiveRun(RunRef(many["run"], many["endpoint"], run_credentials(many["endpoint"], many["run"]))) as lv:
        # before: the status query waited for its own timeout (1 s; an agent's final answer comes late)
        old_med, _, old = timed(lambda: lv.statuses(), repeat=1)
        # now: it ends as soon as every live agent has answered
        new_med, new_max, snap = timed(lambda: snapshot(lv), repeat=3)
    assert len(old) == N
    assert [r["id"] for r in snap["agents"]] == list(range(1, N + 1))
    assert all(r["answered"] and r["alive"] for r in snap["agents"]), "an agent's status was cut off"
    print(
        f"\n[timing] {N} agents: status query waiting for its timeout {old_med:.3f} s; "
        f"snapshot (info + statuses, ending when all answered) median {new_med:.3f} s, max {new_max:.3f} s"
    )
    # (times are printed, not asserted: every status answered is what shows no timeout was waited for)

    figures = {}
    for args in (["agents", "--json"], ["agents"], ["graph", "--json"], ["runs", "--json"], ["pause"], ["resume"]):
        med, mx, res = timed(lambda args=args: invoke(*args), repeat=2)
        assert res.exit_code == ExitCode.OK, res.output
        figures[" ".join(args)] = (med, mx)
    print(
        "[timing] in-process (CliRunner: attaching, queries, output; typer's own setup included): "
        + ", ".join(f"{k} {m:.3f} s (max {x:.3f})" for k, (m, x) in figures.items())
    )
    procs = {}
    for args in (["agents", "--json"],):  # (pause and resume: in this process above; a start is a start)
        med, _, p = timed(
            lambda args=args: subprocess.run(
                swarm_cmd(*args), capture_output=True, text=True, timeout=DEADLINE, stdin=subprocess.DEVNULL
            ),
            repeat=1,  # (a process start each: the figure is printed, the 30 agents run meanwhile)
        )
        assert p.returncode == ExitCode.OK, p.stderr
        procs[" ".join(args)] = med
    imports, _, _ = timed(lambda: subprocess.run(swarm_cmd("--help"), capture_output=True, timeout=DEADLINE), repeat=1)
    print(
        "[timing] as processes (python start and imports included): "
        + ", ".join(f"swarm {k} {v:.3f} s" for k, v in procs.items())
        + f"; `swarm --help` alone {imports:.3f} s"
    )


def _progress_lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.startswith("t=")]


@pytest.mark.slow
def test_progress_line_at_30_agents_counts_spawned_and_killed(many):
    up, tr = many["up"], many["tracker"]
    line = wait_for(
        lambda: [ln for ln in _progress_lines(up.launcher.text()) if f" {N} live: " in ln],
        DEADLINE,
        "a progress line that sums up the swarm",
    )[-1]
    m = re.search(rf"ticks/s  ({N} live: .*)$", line)
    assert m and re.fullmatch(
        rf"{N} live: \d+ settled(, \d+ not \(worst( \d+:[\d.]+%){{1,3}}\))?"
        r"(, \d+ without a leader)?",
        m[1],
    ), line
    assert len(m[1]) <= 80, m[1]

    # an agent added at run time counts once it is live
    sp = tr.spawn(
        swarm_cmd("spawn", "--id", N + 1, "--x", 5, "--y", 5, "--heading", 0, "--speed", 20, "--timeout", DEADLINE),
        "spawn-31",
    )
    assert sp.wait(DEADLINE) == ExitCode.OK, sp.text()
    pid31 = int(re.search(r"pid (\d+)", sp.text())[1])
    many["extra_pids"].append((pid31, psutil.Process(pid31).create_time()))
    wait_for(
        lambda: any(f" {N + 1} live: " in ln for ln in _progress_lines(up.launcher.text())),
        DEADLINE,
        "the progress line to count the spawned agent",
    )

    # one of the launcher's own agents killed: reaped at once (no zombie), shown as dropped
    pid5 = {r["id"]: r for r in json.loads(invoke("agents", "--json").stdout)["agents"]}[5]["pid"]
    t0 = time.monotonic()
    res = invoke("kill", 5, "--timeout", DEADLINE)
    assert res.exit_code == ExitCode.OK, res.output
    wait_for(
        lambda: reaped(pid5),
        DEADLINE,
        "the launcher to reap agent 5 (no zombie left)",
        interval=0.02,
    )
    print(f"\n[timing] agent 5 killed and reaped {time.monotonic() - t0:.3f} s after `swarm kill` started")
    assert invoke("kill", N + 1, "--timeout", DEADLINE).exit_code == ExitCode.OK
    wait_for(
        lambda: any(ln.endswith(f"; dropped 5, {N + 1}") for ln in _progress_lines(up.launcher.text())),
        DEADLINE,
        "the progress line to name both dropped agents",
    )
    assert f"agent 5 (pid {pid5}) exited (killed by SIGKILL)" in up.launcher.text()
