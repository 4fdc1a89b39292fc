"""Whole runs with and without the compiled hot path (swarm/contracts/_fastwire.c): the same
trajectories to the bit (tier process, slow).

- `swarm sim` in a process of its own with SWARM_PURE_PYTHON=1 (one process for the four
  scenarios), and in this process (which runs the compiled path: the test is skipped
  otherwise), on the shipped scenarios whose out-neighbours change at run time (`swarm sim`
  passes frames as objects: what differs there is the nearest choice): every array of
  trajectory.npz equal;
- a lockstep `swarm up` whose every process (world, agents) runs the pure path (frames
  encoded and decoded in Python) equals `swarm sim`; the equivalence tests of
  tests/process/test_runtime.py run `swarm up` on the compiled path where a compiler exists, so
  compiled and pure `swarm up` are equal through `swarm sim`;
- SWARM_PURE_PYTHON=1 switches a process to the pure path.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from cli_invoke import invoke
from deadlines import DEADLINE
from runtime_helpers import SCENARIOS, UpRun, load_trajectory, swarm_cmd

from swarm.contracts import fastpath
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow
KEYS = ("t", "x", "y", "heading", "u", "out", "alive")
# limited sensing and faults: the graph changes (s simulated: limited sensing's every re-choice
# and follow state change is in its first 20 s; faults.toml's kill of 4 at 20 s, 5 falling
# back to the nearest sensed agent four times, and 4's restart at 25 s, in its first 26 s)
SELECTING = {"case2-range": "20", "case2-fov": "20", "swarm30-range": "20", "faults": "26"}


def env_of(rt, pure: bool) -> dict:
    env = {k: v for k, v in rt.env.items() if k != fastpath.PURE_ENV}
    return {**env, fastpath.PURE_ENV: "1"} if pure else env


def sim(scenario, out, duration: str = "20"):
    """`swarm sim` in this process (the path it imported: the compiled one where the tests that
    compare run)."""
    res = invoke("sim", scenario, "--out", out, "--no-plots", "--duration", duration)
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    return load_trajectory(out)


# `swarm sim SCENARIO --out OUT --duration D` for each (SCENARIO, OUT, D) of argv, in one process
# (what `swarm` runs: its click command), on the path it imported (the pure one: asserted)
PURE_SIMS = """
import sys
from typer.main import get_command
from swarm.cli.main import app
from swarm.contracts import fastpath
assert fastpath.compiled is None, fastpath.path
command = get_command(app)
for k in range(1, len(sys.argv), 3):
    scenario, out, duration = sys.argv[k : k + 3]
    args = ["sim", scenario, "--out", out, "--no-plots", "--duration", duration]
    command.main(args, prog_name="swarm", standalone_mode=False)
"""


@pytest.mark.skipif(fastpath.compiled is None, reason=f"the compiled path is not in use: {fastpath.path}")
def test_sim_is_the_same_with_and_without_the_compiled_path(rt, tmp_path):
    """Each scenario of SELECTING, pure (the four in one process: one start, not four) and
    compiled (in this process, meanwhile)."""
    argv = [str(a) for name, d in SELECTING.items() for a in (SCENARIOS / f"{name}.toml", tmp_path / name / "p", d)]
    pure = rt.tracker.spawn([sys.executable, "-c", PURE_SIMS, *argv], "sim-pure", env=env_of(rt, True))
    compiled = {name: sim(SCENARIOS / f"{name}.toml", tmp_path / name / "c", d) for name, d in SELECTING.items()}
    assert pure.wait(DEADLINE) == ExitCode.OK, pure.text()[-3000:]
    for name in SELECTING:
        theirs = load_trajectory(tmp_path / name / "p")
        for key in KEYS:
            np.testing.assert_array_equal(compiled[name][key], theirs[key], err_msg=f"{name}: {key}")


def test_a_pure_lockstep_up_equals_sim(rt, tmp_path):
    """case2-range (limited sensing: the graph changes at run time) over 20 s."""
    scen = SCENARIOS / "case2-range.toml"
    args = swarm_cmd("up", scen, "--out", tmp_path / "up", "--no-plots", "--clock", "lockstep", "--duration", "20")
    up = UpRun(rt.tracker.spawn(args, "up", env=env_of(rt, True)), tmp_path / "up", rt.tracker)
    ref = sim(scen, tmp_path / "sim")  # meanwhile
    assert up.launcher.wait(120) == ExitCode.OK, up.launcher.text()[-3000:]
    traj = up.trajectory()
    assert len(traj["t"]) == round(20 / load_scenario(scen).run.dt) + 1
    for key in KEYS:
        np.testing.assert_array_equal(traj[key], ref[key], err_msg=key)


def test_swarm_pure_python_switches_the_path_off(rt):
    code = (
        "from swarm.contracts import fastpath, wire; from swarm.agents import selection;"
        "print(fastpath.compiled is None, wire.decode_sense is wire.decode_sense_py,"
        " selection.nearest is selection.nearest_py, fastpath.path)"
    )
    env = env_of(rt, True)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.startswith("True True True pure Python (SWARM_PURE_PYTHON is set)"), out
