"""Shared fixtures: a small valid scenario as a dict, a TOML writer for it, `rt` (a
private runtime for the multi-process tests) and `shipped_sim` (each shipped scenario run
once by `swarm sim`, for every test that checks it or compares with it)."""

from __future__ import annotations

import copy
import json
import math
import signal
from pathlib import Path

import pytest

# Tests Ctrl-C the processes they start (swarm up, watch, graph --watch, study). A shell
# without job control starts `cmd &` with SIGINT ignored, and an ignored signal stays
# ignored in every child: run that way, the suite would fail those tests for the shell's
# sake. The children get the default disposition back from this process.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# One leader (agents[0], id 1) and two followers in a fixed chain 2 -> 1, 3 -> 2.
BASE = {
    "name": "base",
    "run": {"dt": 0.05, "duration": 10.0},
    "target": {"x": 0.0, "y": 0.0},
    "gains": {"c1": 0.5, "c2": 0.25},
    "sensing": {"selection": "fixed"},
    "agents": [
        {"id": 1, "role": "leader", "x": 2.0, "y": 0.0, "heading": math.pi / 2, "speed": 1.0, "orbit_radius": 2.0},
        {"id": 2, "role": "follower", "x": 0.0, "y": -3.0, "heading": 0.0, "speed": 1.5, "follow": 1},
        {"id": 3, "role": "follower", "x": -3.0, "y": 1.0, "heading": 1.0, "speed": 0.6, "follow": 2},
    ],
}


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):  # an inline table, e.g. [law] params = {k = 1.0}
        return "{" + ", ".join(f"{k} = {_value(vv)}" for k, vv in v.items()) + "}"
    raise TypeError(f"cannot write {v!r} as TOML here")


def to_toml(data: dict) -> str:
    """Serialise the shapes a scenario uses: scalars, tables of scalars (and of inline tables),
    [[agents]]."""
    lines = [f"{k} = {_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))]
    for k, v in data.items():
        if isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{kk} = {_value(vv)}" for kk, vv in v.items()]
    for k, v in data.items():
        if isinstance(v, list):
            for item in v:
                lines += ["", f"[[{k}]]"] + [f"{kk} = {_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture
def base() -> dict:
    """A fresh deep copy of the valid base scenario dict (mutate freely)."""
    return copy.deepcopy(BASE)


@pytest.fixture
def write_toml(tmp_path):
    """write_toml(data, name="scenario.toml") -> Path of the written file."""

    def write(data: dict, name: str = "scenario.toml") -> Path:
        p = tmp_path / name
        p.write_text(to_toml(data), encoding="utf-8")
        return p

    return write


@pytest.fixture(scope="session")
def shipped_sim(tmp_path_factory):
    """shipped_sim(name) -> (CLI result, out dir): scenarios/<name>.toml run in full by
    `swarm sim --no-plots` in this process, once per session (the convergence checks and
    the `swarm up` equivalence tests share it)."""
    from typer.testing import CliRunner

    from swarm.cli.main import app

    scenarios = Path(__file__).resolve().parent.parent / "scenarios"
    cache: dict[str, tuple] = {}

    def run(name: str):
        if name not in cache:
            out = tmp_path_factory.mktemp(f"sim-{name}")
            res = CliRunner().invoke(app, ["sim", str(scenarios / f"{name}.toml"), "--out", str(out), "--no-plots"])
            cache[name] = (res, out)
        return cache[name]

    return run


@pytest.fixture
def rt(tmp_path):
    """A private runtime dir and process tracker (tests/runtime_helpers.py) for one test; at
    the end it kills what is left of the processes the test started and fails if there was any."""
    from runtime_helpers import Runtime

    with Runtime(tmp_path) as r:
        yield r
