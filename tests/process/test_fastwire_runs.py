"""Whole runs with and without the compiled hot path (swarm/contracts/_fastwire.c): the same
trajectories to the bit (tier process, slow).

- `swarm sim` in a process of its own with SWARM_PURE_PYTHON=1 and without, on the shipped
  scenarios whose out-neighbours change at run time (`swarm sim` passes frames as objects:
  what differs there is the nearest choice): every array of trajectory.npz equal;
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
from runtime_helpers import SCENARIOS, UpRun, load_trajectory, swarm_cmd

from swarm.contracts import fastpath
from swarm.contracts.scenario import load_scenario
from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow
KEYS = ("t", "x", "y", "heading", "u", "out", "alive")
SELECTING = ["case2-range", "case2-fov", "swarm30-range", "faults"]  # limited sensing and faults: the graph changes


def env_of(rt, pure: bool) -> dict:
    env = {k: v for k, v in rt.env.items() if k != fastpath.PURE_ENV}
    return {**env, fastpath.PURE_ENV: "1"} if pure else env


def sim(rt, scenario, out, pure: bool, duration: str = "20"):
    args = swarm_cmd("sim", scenario, "--out", out, "--no-plots", "--duration", duration)
    p = rt.tracker.spawn(args, f"sim-{out.name}", env=env_of(rt, pure))
    assert p.wait(120) == ExitCode.OK, p.text()[-3000:]
    return load_trajectory(out)


@pytest.mark.skipif(fastpath.compiled is None, reason=f"the compiled path is not in use: {fastpath.path}")
@pytest.mark.parametrize("name", SELECTING)
def test_sim_is_the_same_with_and_without_the_compiled_path(rt, tmp_path, name):
    scen = SCENARIOS / f"{name}.toml"
    compiled, pure = sim(rt, scen, tmp_path / "c", False), sim(rt, scen, tmp_path / "p", True)
    for key in KEYS:
        np.testing.assert_array_equal(compiled[key], pure[key], err_msg=f"{name}: {key}")


def test_a_pure_lockstep_up_equals_sim(rt, tmp_path):
    """case2-range (limited sensing: the graph changes at run time) over 20 s."""
    scen = SCENARIOS / "case2-range.toml"
    ref = sim(rt, scen, tmp_path / "sim", False)
    args = swarm_cmd("up", scen, "--out", tmp_path / "up", "--no-plots", "--clock", "lockstep", "--duration", "20")
    up = UpRun(rt.tracker.spawn(args, "up", env=env_of(rt, True)), tmp_path / "up", rt.tracker)
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
