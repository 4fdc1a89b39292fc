"""Shared fixtures: a small valid scenario as a dict, a TOML writer for it, `rt` (a
private runtime for the multi-process tests) and `shipped_sim` (each shipped scenario run
once by `swarm sim`, for every test that checks it or compares with it); and the tiers.

Every test carries one tier marker, what it needs to run (`pytest -m pure`, `-m "not process"`...):

    pure     maths, models and files in this process: no zenoh session, no other process
    seam     the world or an agent driven through the fake zenoh session of tests/support/fakes.py
    zenoh    real zenoh sessions inside this process (routing, transport, TLS, credentials)
    process  other processes: `swarm` commands, the world and agents as OS processes

A file's tier is the folder it is in (tests/pure, tests/seam, tests/zenoh, tests/process): what
its most demanding test needs. A test that takes the `rt` fixture (a private runtime for
processes) belongs in tests/process. `slow` is the other axis: the long tests of every tier
(`-m "not slow"` is the fast tier: docs/testing.md#time). What the tests share (fakes, the process
tracker, deadlines, corpora) is in tests/support, on sys.path (pyproject: pythonpath).
"""

from __future__ import annotations

import copy
import json
import math
import signal
from dataclasses import dataclass
from pathlib import Path

import pytest
from deadlines import DEADLINE, DEFAULT

# Tests Ctrl-C the processes they start (swarm up, watch, graph --watch, study). A shell
# without job control starts `cmd &` with SIGINT ignored, and an ignored signal stays
# ignored in every child: run that way, the suite would fail those tests for the shell's
# sake. The children get the default disposition back from this process.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def _cache_bytecode() -> None:
    """Compiled modules kept between processes, also where PYTHONDONTWRITEBYTECODE is set (as
    in CI's image): without them every `swarm` process the tests start compiles the project
    from source again (0.07-0.15 s of CPU each, some thousands of processes), and every
    pytest worker rewrites the test modules' asserts again at collection (about 5 s of the
    13 s collection). This process writes its own caches (its imports, pytest's rewritten test
    modules); the project's packages are compiled once ahead for the child processes (the
    variable only stops writing: Python still reads a cache that is there). Not on xdist's
    workers: their controller has done it."""
    import os
    import sys

    sys.dont_write_bytecode = False
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        import compileall

        root = Path(__file__).resolve().parent.parent
        for package in ("swarm", "agents", "world"):  # (swarm/agents and swarm/world link to the last two)
            compileall.compile_dir(root / package, quiet=1)


_cache_bytecode()

TIER_NAMES = ("pure", "seam", "zenoh", "process")  # a folder each, in this order of need


def per_test_limit(config, item) -> float | None:
    """pytest-timeout's limit for `item` (its marker's, else --timeout / pyproject's), scaled as
    SWARM_TEST_DEADLINE scales the waits (tests/support/deadlines.py): the default deadline (120 s)
    leaves the limits as they are; None when there is none."""
    marker = item.get_closest_marker("timeout")
    base = marker.args[0] if marker is not None and marker.args else marker.kwargs.get("timeout") if marker else None
    if base is None:
        try:
            base = config.getoption("timeout") or config.getini("timeout")
        except ValueError:  # (pytest-timeout not installed)
            return None
    return float(base) * DEADLINE / DEFAULT if base else None


def pytest_collection_modifyitems(config, items):
    """Mark every test with its tier, the folder it is in; a test outside the tier folders, or
    one that starts processes (`rt`) outside tests/process, is an error. With
    SWARM_TEST_DEADLINE set, every test's time limit grows with it (`per_test_limit`)."""
    # Run order: by file name across the tier folders (stable within a file), so that on two
    # workers the tests that wait on processes and those that compute are mixed, as they were
    # when every file sat in tests/ (folder by folder, both workers would start processes at
    # once for the first half of the run).
    items.sort(key=lambda item: item.path.name)
    misplaced = set()
    for item in items:
        if DEADLINE != DEFAULT:
            limit = per_test_limit(config, item)
            if limit is not None:
                item.add_marker(pytest.mark.timeout(limit), append=False)
        tier = item.path.parent.name
        if tier not in TIER_NAMES or ("rt" in getattr(item, "fixturenames", ()) and tier != "process"):
            misplaced.add(f"{item.path.parent.name}/{item.path.name}")
            continue
        item.add_marker(getattr(pytest.mark, tier))
    if misplaced:
        raise pytest.UsageError(
            f"tests: {', '.join(sorted(misplaced))} not in its tier's folder "
            f"(tests/{{{','.join(TIER_NAMES)}}}; a test that starts processes, `rt`, in tests/process)"
        )


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


@dataclass(frozen=True)
class SimResult:
    """What the tests read of a `swarm sim` CLI result (typer's Result), as written to files
    by the worker that ran it."""

    exit_code: int
    stdout: str
    output: str


@pytest.fixture(scope="session")
def shipped_sim(tmp_path_factory):
    """shipped_sim(name) -> (result, out dir): scenarios/<name>.toml run in full by
    `swarm sim --no-plots` in-process, once per session (the convergence checks and the
    `swarm up` equivalence tests share it). Once across xdist's workers too: the first worker
    to need a scenario runs it under a lock on a file in the session's shared temporary
    directory, the others wait for it and read its results (`SimResult`: exit_code, stdout,
    output) and out dir."""
    import fcntl
    import os
    import shutil
    import traceback

    from typer.testing import CliRunner

    from swarm.cli.main import app

    scenarios = Path(__file__).resolve().parent.parent / "scenarios"
    base = tmp_path_factory.getbasetemp()
    shared = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shipped-sim"
    shared.mkdir(exist_ok=True)
    cache: dict[str, tuple[SimResult, Path]] = {}

    def run(name: str) -> tuple[SimResult, Path]:
        if name not in cache:
            out, done = shared / name, shared / f"{name}.result.json"
            with open(shared / f"{name}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)  # released when closed: the run below is whole by then
                if not done.exists():
                    shutil.rmtree(out, ignore_errors=True)  # (a worker that died mid-run)
                    res = CliRunner().invoke(
                        app, ["sim", str(scenarios / f"{name}.toml"), "--out", str(out), "--no-plots"]
                    )
                    output = res.output
                    if res.exc_info is not None and not isinstance(res.exception, SystemExit):
                        output += "".join(traceback.format_exception(*res.exc_info))
                    text = json.dumps({"exit_code": res.exit_code, "stdout": res.stdout, "output": output})
                    tmp = done.with_suffix(".tmp")
                    tmp.write_text(text, encoding="utf-8")
                    tmp.replace(done)
                cache[name] = (SimResult(**json.loads(done.read_text(encoding="utf-8"))), out)
        return cache[name]

    return run


@pytest.fixture
def rt(tmp_path):
    """A private runtime dir and process tracker (tests/support/runtime_helpers.py) for one test; at
    the end it kills what is left of the processes the test started and fails if there was any."""
    from runtime_helpers import Runtime

    with Runtime(tmp_path) as r:
        yield r
