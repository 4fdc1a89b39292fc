"""The Python API (swarm/api/runs.py, scenario.py, up.py; docs/reference/api.md):
scenarios from files, dicts and the builder with the files' errors; `simulate` equal to
`run_sim`; `open_run` round trips; `swarm.up` equal to `simulate` with no process left;
the example notebook; and `import swarm` staying free for the agent processes."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from deadlines import DEADLINE

import swarm
from swarm.contracts.scenario import ScenarioError, load_scenario, parse_scenario
from swarm.offline.sim import run_sim
from swarm.runtime.procs import wait_until

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"
TICK_KEYS = ("t", "x", "y", "heading", "u", "out", "alive", "missed")
TIMING = ("wall_time", "sim_seconds_per_wall_second")


def same_arrays(a: dict, b: dict, keys=None, atol: float = 0.0) -> None:
    for k in keys or sorted(set(a) | set(b)):
        x, y = np.asarray(a[k]), np.asarray(b[k])
        assert x.shape == y.shape, f"{k}: {x.shape} != {y.shape}"
        if x.dtype.kind == "f":
            np.testing.assert_allclose(x, y, rtol=0, atol=atol, err_msg=k)
        else:
            np.testing.assert_array_equal(x, y, err_msg=k)


def untimed(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in TIMING}


# -- scenarios -------------------------------------------------------------------------------


def test_load_and_from_dict_give_the_scenario_the_files_give(base, write_toml):
    assert swarm.load(SCENARIOS / "case2.toml") == load_scenario(SCENARIOS / "case2.toml")
    assert swarm.from_dict(base) == swarm.load(write_toml(base)) == parse_scenario(base)
    assert isinstance(swarm.load(str(SCENARIOS / "case1.toml")), swarm.Scenario)


def test_bad_scenarios_give_the_files_messages(base, write_toml):
    base["agents"][1]["speed"] = -1.0
    with pytest.raises(swarm.ScenarioError) as from_file:
        swarm.load(write_toml(base))
    with pytest.raises(ScenarioError) as from_dict:
        swarm.from_dict(base, source="my dict")
    file_lines, dict_lines = str(from_file.value).splitlines(), str(from_dict.value).splitlines()
    assert dict_lines[0] == "my dict: invalid scenario" and file_lines[0].endswith("scenario.toml: invalid scenario")
    assert dict_lines[1:] == file_lines[1:] == ["  agents[1].speed: Input should be greater than 0"]
    with pytest.raises(ScenarioError, match="no such file"):
        swarm.load(SCENARIOS / "nope.toml")
    with pytest.raises(ScenarioError, match="not list"):
        swarm.from_dict([base])


def test_builder_builds_what_a_file_holds(base):
    b = swarm.Builder("base", dt=0.05, duration=10.0, c1=0.5, c2=0.25, selection="fixed", target=(0.0, 0.0))
    for a in base["agents"]:
        fields = {k: v for k, v in a.items() if k not in ("id", "role")}
        (b.leader if a["role"] == "leader" else b.follower)(a["id"], **fields)
    assert b.build() == parse_scenario(base)
    b.follower(np.int64(4), x=np.float64(1.0), y=0, heading=0, speed=1, follow=7)  # numpy numbers are fine
    message = r"^<builder base>: invalid scenario\n  agents\[3\]\.follow: no agent has id 7$"
    with pytest.raises(ScenarioError, match=message):
        b.build()
    with pytest.raises(TypeError, match="unknown setting 'c3'"):
        swarm.Builder("x", c3=1.0)
    b2 = swarm.Builder("f", c1=1, c2=0.5).leader(1, 0, 0, 0, 1.0, 1.0).fault(at=1.0, kind="kill", agent=1)
    assert b2.build().faults[0].kind == "kill"


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENARIOS.glob("*.toml")))
def test_to_toml_round_trips_every_shipped_scenario(name):
    s = load_scenario(SCENARIOS / f"{name}.toml")
    import tomllib

    assert parse_scenario(tomllib.loads(swarm.to_toml(s))) == s


def test_to_toml_quotes_keys_toml_cannot_leave_bare(base):
    base["law"] = {"params": {"k phase": 0.5, "a.b": 1.0, "plain_k": 2.0}}
    s = swarm.from_dict(base)
    text = swarm.to_toml(s)
    assert '"k phase" = 0.5' in text and '"a.b" = 1.0' in text and "plain_k = 2.0" in text
    import tomllib

    assert parse_scenario(tomllib.loads(text)) == s


# -- simulate and open_run ------------------------------------------------------------------


def test_simulate_equals_run_sim(base):
    s = parse_scenario(base)
    ref = run_sim(s, duration=1.0)
    res = swarm.simulate(base, duration=1.0)
    same_arrays(res.arrays, ref.recorder.arrays())
    assert untimed(res.summary.to_dict()) == untimed(ref.summary())
    assert res.run_dir is None and res.x.shape == (21, 3) and res.ids.tolist() == [1, 2, 3]
    # one agent's columns, by id; the summary by attribute
    two = res.agent(2)
    assert two.role == "follower" and two.speed == 1.5 and np.array_equal(two.x, res.x[:, 1])
    assert two.summary.out_neighbour == 1 == res.summary.agents[2].out_neighbour
    assert res.summary.per_agent("role") == {1: "leader", 2: "follower", 3: "follower"}
    assert res.summary.converged is res.converged is False and res.summary.ticks == 20
    assert sorted(res.agents) == [1, 2, 3]
    with pytest.raises(KeyError, match="no agent 9"):
        res.agent(9)
    with pytest.raises(AttributeError, match="no field 'nope'"):
        _ = res.summary.nope


def test_simulate_checks_the_duration_as_the_cli_does(base):
    with pytest.raises(ScenarioError, match=r"with duration 0: invalid scenario\n  run.duration"):
        swarm.simulate(base, duration=0)
    with pytest.raises(ScenarioError, match="shorter than one step"):
        swarm.simulate(base, duration=0.01)


def test_simulate_out_and_open_run_round_trip(base, tmp_path):
    out = tmp_path / "run"
    res = swarm.simulate(swarm.from_dict(base), duration=1.0, out=out)
    assert res.run_dir == out
    assert {"recording.mcap", "trajectory.npz", "summary.json"} <= {p.name for p in out.iterdir()}
    back = swarm.open_run(out)
    same_arrays(res.arrays, back.arrays)
    assert back.summary.to_dict() == res.summary.to_dict() and back.summary.engine == "sim"
    same_arrays(res.arrays, run_sim(parse_scenario(base), duration=1.0).recorder.arrays())
    with pytest.raises(swarm.OutDirError, match="already holds the results"):
        swarm.simulate(base, duration=1.0, out=out)
    swarm.simulate(base, duration=0.5, out=out, force=True)
    assert swarm.open_run(out).summary.ticks == 10


def test_open_run_rebuilds_a_run_whose_world_died(base, tmp_path):
    out = tmp_path / "run"
    res = swarm.simulate(base, duration=1.0, out=out)
    (out / "trajectory.npz").unlink()
    (out / "summary.json").unlink()
    back = swarm.open_run(out)
    assert back.summary.complete is False
    same_arrays(res.arrays, back.arrays, TICK_KEYS)
    with pytest.raises(swarm.RunReadError, match="not a directory"):
        swarm.open_run(tmp_path / "none")


def test_up_refuses_before_starting_anything(base, tmp_path):
    base["agents"][0]["speed"] = 0
    with pytest.raises(ScenarioError, match="agents\\[0\\]"):
        swarm.up(base)
    out = tmp_path / "run"
    swarm.simulate(SCENARIOS / "case1.toml", duration=0.05, out=out)
    with pytest.raises(swarm.OutDirError, match="force=True"):
        swarm.up(SCENARIOS / "case1.toml", out=out)
    with pytest.raises(ValueError, match="clock"):
        swarm.up(SCENARIOS / "case1.toml", out=tmp_path / "new", clock="fast")


def test_importing_the_contracts_stays_cheap():
    """An agent process imports swarm.contracts.*: the API must not add anything to that."""
    code = (
        "import sys, swarm.contracts.wire, swarm\n"
        "heavy = [m for m in ('numpy', 'zenoh', 'matplotlib', 'pydantic', 'swarm.api.runs', 'world', 'agents') "
        "if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "assert 'simulate' in dir(swarm) and 'swarm.api.runs' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)
    assert swarm.simulate is sys.modules["swarm.api.runs"].simulate  # loaded on first use
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = swarm.nope


# -- the slow tier: figures, the example, the distributed runtime ---------------------------


def is_png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_results_plot_draws_the_run_figures(base, tmp_path, monkeypatch):
    """Results.plot saves the in-memory run and draws its figures there. One figure of the list
    here (each costs ~0.5 s of matplotlib): every figure is drawn and checked in
    tests/pure/test_plots.py; this test's claim is the API's way to them."""
    import swarm.plots.render as render

    monkeypatch.setattr(render, "PLOT_FILES", ("trajectories.png",))
    res = swarm.simulate(base, duration=1.0)
    with pytest.raises(ValueError, match="out_dir"):
        res.plot()
    files = res.plot(tmp_path / "figs")
    assert [p.name for p in files] == ["trajectories.png"] and all(map(is_png, files))
    assert res.run_dir == tmp_path / "figs" and (res.run_dir / "trajectory.npz").is_file()


@pytest.mark.slow
def test_the_example_notebook_runs(tmp_path, monkeypatch, capsys):
    """The file run as a script (`python examples/case2_notebook.py FIGURE`), in this process:
    runpy gives it a namespace of its own as __main__, so a name it uses before it defines or
    imports it fails here as it would in a fresh interpreter (a process of its own cost the
    imports again, not a claim)."""
    import runpy

    import matplotlib.pyplot as plt

    notebook = REPO / "examples" / "case2_notebook.py"
    figure = tmp_path / "figs" / "case2.png"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(notebook), str(figure)])
    try:
        runpy.run_path(str(notebook), run_name="__main__")
    finally:
        plt.close("all")
    out = capsys.readouterr().out
    assert is_png(figure) and "converged: True" in out, out[-2000:]


class Descendants:
    """Every process under `pid` seen while it runs (psutil, polled), to check none is left."""

    def __init__(self, pid: int):
        import psutil

        self.root = psutil.Process(pid)
        self.seen: dict[tuple[int, float], object] = {}
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._poll, daemon=True)
        self.thread.start()

    def _poll(self) -> None:
        import psutil

        while not self.stop.wait(0.2):  # (a scan of the process table: CPU taken from the run under test)
            try:
                for p in self.root.children(recursive=True):
                    self.seen.setdefault((p.pid, p.create_time()), p)
            except psutil.Error:
                pass

    def alive(self) -> list[str]:
        import psutil

        out = []
        for p in self.seen.values():
            try:
                if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                    out.append(f"pid {p.pid}: {' '.join(p.cmdline()[:5])}")
            except psutil.Error:
                pass
        return out

    def assert_none_left(self, timeout: float = DEADLINE) -> None:
        """Nothing seen is alive within `timeout` s (a run that was seen whole: world + 6 agents)."""
        from swarm.runtime.procs import wait_until

        self.stop.set()
        self.thread.join()
        assert len(self.seen) >= 7, f"expected a world and 6 agents, saw {len(self.seen)} processes"
        if not wait_until(lambda: not self.alive(), timeout, 0.1):
            raise AssertionError("processes left alive:\n  " + "\n  ".join(self.alive()))


@pytest.fixture
def private_runtime(monkeypatch):
    """A runtime dir of this test's own (sockets, credentials), as tests/support/runtime_helpers.py's Runtime."""
    import shutil

    from runtime_helpers import short_runtime_dir

    d = short_runtime_dir()
    monkeypatch.setenv("SWARM_RUNTIME_DIR", d)
    yield d
    shutil.rmtree(d, ignore_errors=True)


@pytest.mark.slow
def test_up_in_lockstep_equals_simulate_and_leaves_nothing(private_runtime, tmp_path):
    # 20 s: the run must outlive the live query below (a 5 s run had ended before it, loaded machine)
    scenario, duration = SCENARIOS / "case2.toml", 20.0
    with swarm.up(scenario, out=tmp_path / "up", clock="lockstep", duration=duration) as run:
        seen = Descendants(run.pid)
        state = run.state()  # live, once: every agent of the scenario, poses and graph
        assert sorted(state.agents) == [1, 2, 3, 4, 5, 6] and state.agents[1].role == "leader"
        assert set(state.poses) == {1, 2, 3, 4, 5, 6} and all(map(math.isfinite, state.poses[6]))
        assert state.run == run.run_id and "edges" in state.graph
        assert run.wait(timeout=240) == 0, run.output[-3000:]
    assert not run.running()
    seen.assert_none_left()
    got, want = run.results(), swarm.simulate(scenario, duration=duration)
    same_arrays(got.arrays, want.arrays, TICK_KEYS[:-1], atol=1e-9)
    assert got.summary.converged == want.summary.converged and got.summary.ticks == want.summary.ticks == 2000
    switches = [
        sorted((e.tick, e.agent, e["from"] or 0, e.to or 0) for e in r.summary.events_of("switch")) for r in (got, want)
    ]  # within a tick, the order the agents' commands came in
    assert switches[0] == switches[1] and switches[0]


@pytest.mark.slow
def test_leaving_the_with_block_stops_the_run(private_runtime, tmp_path):
    b = swarm.Builder("long", **swarm.load(SCENARIOS / "case2.toml").model_dump(include={"gains"})["gains"])
    for a in swarm.load(SCENARIOS / "case2.toml").agents:
        b.agent(**a.model_dump(exclude_none=True))
    with swarm.up(b, out=tmp_path / "up", clock="lockstep", duration=600.0) as run:  # a Builder: written to a file
        seen = Descendants(run.pid)
        assert wait_until(lambda: run.state().tick > 10 and len(seen.seen) >= 7, 60, 0.1), run.output[-3000:]
    assert run.returncode == 143, run.output[-3000:]
    seen.assert_none_left()
    partial = run.results()
    assert 10 < partial.summary.ticks < 60000 and partial.x.shape[0] == partial.summary.ticks + 1
