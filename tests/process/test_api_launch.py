"""`swarm.launch` (swarm/api/launch.py): `swarm up` in the calling process. Everything is
checked before any process starts; case 2 in lockstep equals `swarm.simulate`; `stop()`
from another thread ends a run with the signal's exit code, results written; called from
a thread other than the main one it leaves the signal handlers alone; no process is left
(real processes over real zenoh, nothing mocked). And `open_run`'s `recovered`."""

from __future__ import annotations

import os
import signal
import threading

import psutil
import pytest
from deadlines import DEADLINE
from test_api import SCENARIOS, TICK_KEYS, Descendants, private_runtime, same_arrays  # noqa: F401 (a fixture)

import swarm
from swarm.runtime.procs import wait_until


def children() -> list[int]:
    return [p.pid for p in psutil.Process(os.getpid()).children(recursive=True)]


def test_launch_refuses_before_starting_anything(base, tmp_path):
    before = children()
    base["agents"][0]["speed"] = 0
    with pytest.raises(swarm.ScenarioError, match="agents\\[0\\]"):
        swarm.launch(base, out=tmp_path / "bad")
    with pytest.raises(swarm.ScenarioError, match="shorter than one step"):
        swarm.launch(SCENARIOS / "case1.toml", out=tmp_path / "bad", duration=0.001)
    with pytest.raises(swarm.UsageError, match="clock must be 'lockstep' or 'realtime', not 'fast'"):
        swarm.launch(SCENARIOS / "case1.toml", out=tmp_path / "bad", clock="fast")
    assert not (tmp_path / "bad").exists()
    held = tmp_path / "held"
    swarm.simulate(SCENARIOS / "case1.toml", duration=0.05, out=held)
    with pytest.raises(swarm.OutDirError, match="already holds the results"):
        swarm.launch(SCENARIOS / "case1.toml", out=held)
    assert children() == before


@pytest.mark.slow
def test_a_launch_that_never_runs_leaves_no_temporary_scenario(base, tmp_path):
    """A scenario that is not a file is written to a temporary one for the run; a Launch built
    and dropped without running removes it too (as does a failed start, whose object goes)."""
    import gc

    from swarm.api.launch import Launch

    launch = Launch(base, out=tmp_path / "never")
    tmp = launch.launcher.cfg.scenario_path.parent
    assert tmp.is_dir() and tmp.name.startswith("swarm-up-")
    del launch
    gc.collect()
    assert not tmp.exists()


def test_open_run_says_what_it_recovered(base, tmp_path):
    out = tmp_path / "run"
    swarm.simulate(base, duration=1.0, out=out)
    assert swarm.open_run(out).recovered is None
    (out / "summary.json").unlink()
    rec = swarm.open_run(out).recovered
    assert (rec.ticks, rec.sim_time, rec.finished) == (20, 1.0, True)
    assert rec.line() == (
        f"recovered 21 ticks (t = 0 to 1.00 s) from the recording (finished) into {out}: "
        "trajectory.npz, summary.json (complete: false)"
    )
    assert swarm.open_run(out).recovered is None  # rebuilt once
    paths = swarm.open_run(out).write_csv()
    assert [p.name for p in paths] == ["agent-1.csv", "agent-2.csv", "agent-3.csv"]
    assert paths[0].read_text().splitlines()[0] == "t,x,y,heading,u,out,alive,r,expected_radius,radial_error"


@pytest.mark.slow
@pytest.mark.usefixtures("private_runtime")
def test_launch_in_lockstep_equals_simulate_and_leaves_nothing(tmp_path):
    scenario, duration = SCENARIOS / "case2.toml", 5.0
    seen, lines, started = Descendants(os.getpid()), [], []
    figures = []
    o = swarm.launch(
        scenario,
        out=tmp_path / "up",
        clock="lockstep",
        duration=duration,
        say=lines.append,
        progress=figures.append,
        on_start=lambda run: started.append((run.run_id, run.endpoint)),
    )
    assert o.exit_code == 0 and o.words is None and not o.failed, (o, lines)
    assert started == [(o.run_id, started[0][1])] and o.run_id.startswith("case2-") and o.out == tmp_path / "up"
    assert o.exits == [] and o.recovered is None and o.stop_signal is None, lines
    seen.assert_none_left()
    assert figures and all(f["ticks"] == 500 for f in figures) and figures[-1]["tick"] <= 500
    assert set(figures[-1]["errors"]) <= {1, 2, 3, 4, 5, 6} and figures[-1]["wall"] > 0
    want = swarm.simulate(scenario, duration=duration)
    assert o.summary.ticks == want.summary.ticks == 500 and o.summary.converged == want.summary.converged
    assert o.summary.to_dict() == o.results().summary.to_dict()
    same_arrays(o.results().arrays, want.arrays, TICK_KEYS[:-1], atol=1e-9)


def long_run() -> dict:
    data = swarm.load(SCENARIOS / "case2.toml").model_dump(exclude_none=True)
    data["name"] = "long"
    data["run"]["duration"] = 600.0
    return data


@pytest.mark.slow
@pytest.mark.usefixtures("private_runtime")
def test_stop_from_another_thread_ends_the_run_with_the_signals_code(tmp_path):
    handle, going = [], threading.Event()

    def progress(f):
        if f["tick"] > 10:
            going.set()

    def stopper():  # once the run goes and every process of it has been seen
        if going.wait(120) and wait_until(lambda: len(seen.seen) >= 7, DEADLINE, 0.05):
            handle[0].stop(signal.SIGINT)

    seen = Descendants(os.getpid())
    threading.Thread(target=stopper, daemon=True).start()
    o = swarm.launch(long_run(), out=tmp_path / "up", clock="lockstep", progress=progress, on_start=handle.append)
    assert going.is_set(), o
    assert o.exit_code == 130 and o.stop_signal == 2 and not o.failed
    assert o.words == f"stopped by signal 2; partial results in {tmp_path / 'up'}" and o.run_id.startswith("long-")
    seen.assert_none_left()
    assert o.summary is not None and 10 < o.summary.ticks < 60000
    assert o.results().x.shape[0] == o.summary.ticks + 1


@pytest.mark.slow
@pytest.mark.usefixtures("private_runtime")
def test_launch_off_the_main_thread_leaves_the_signal_handlers_alone(tmp_path):
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    handle, outcome = [], []
    seen = Descendants(os.getpid())
    worker = threading.Thread(
        target=lambda: outcome.append(
            swarm.launch(long_run(), out=tmp_path / "up", clock="lockstep", on_start=handle.append)
        ),
        daemon=True,
    )
    worker.start()
    assert wait_until(lambda: handle, DEADLINE, 0.05)
    assert wait_until(lambda: (tmp_path / "up" / "recording.mcap").exists() and len(seen.seen) >= 7, 120, 0.1)
    assert {s: signal.getsignal(s) for s in handlers} == handlers
    handle[0].stop()  # SIGTERM
    worker.join(120)
    o = outcome[0]
    assert o.exit_code == 143 and o.stop_signal == 15 and o.summary is not None
    seen.assert_none_left()
    assert {s: signal.getsignal(s) for s in handlers} == handlers


@pytest.mark.slow  # a Python process of its own
def test_the_swarm_up_launcher_imports_no_numpy():
    """What the `swarm up` process imports to launch a run (its command, swarm.launch, the
    launcher, its progress line, the out dir's claim) leaves numpy out: about 0.15 s of CPU at
    every run; numpy is imported only where a run's results are rebuilt or read."""
    import subprocess
    import sys

    code = (
        "import sys, swarm.cli.up, swarm.api.launch, swarm.runtime.launcher, swarm.runtime.progress, "
        "swarm.offline.results; sys.exit(3 if 'numpy' in sys.modules else 0)"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=DEADLINE)
    assert res.returncode == 0, res.stderr[-2000:] or "numpy was imported"
