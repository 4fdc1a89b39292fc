"""`swarm study --scheduler`: a study on a Dask cluster of three machines, for real: a network
namespace for the scheduler and the study (`s`), one for each `dask worker` process (`a`, `b`),
nothing shared but the network (tests/process/test_multihost.py's `Lan`: a bridge in `s`, a
veth pair to each worker; docs/design/studies.md#cluster).

- a law that hangs, with --run-timeout: its runs are `timeout` rows (the task's child process
  killed on the worker), the others finish;
- a study of 100 runs, Ctrl-C'd after its first rows, then resumed, and one worker SIGKILLed
  mid-resume: the scheduler runs its tasks on the other one; the study ends with the rows the
  same study gives on this machine's processes, each run's row exactly once, the rows of before
  the Ctrl-C kept as they were (the last test: the cluster has one worker after it). One study
  on the cluster for the three (they were three studies of 400 runs: a run costs about 25 ms of
  CPU, most of it not its ticks, so the cost is the count of runs; 100 runs make the same 8
  tasks of the batch engine, 13 runs each (0.3 s of CPU a task), so Ctrl-C, the resume and the
  kill meet the same study, for a quarter of the CPU of 400).

Needs root (`ip netns add`) and the package distributed (in the `test` extra); skips, saying
why, where either is missing. Every namespace is the test's own and deleted at the end, even on
failure; only processes the test started are ever signalled (by process group).
"""

from __future__ import annotations

import csv
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from deadlines import DEADLINE
from test_multihost import lan_or_skip
from test_study_runs import HANG_LAW, HANG_SCENARIO

from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import Group, wait_until

pytestmark = pytest.mark.slow

pytest.importorskip("distributed", reason="the cluster executor needs distributed (the extra swarm-circumnav[cluster])")

ROOT = Path(__file__).resolve().parents[2]
PORT = 8786
DASK = [sys.executable, "-m", "dask"]
# 100 tiny runs (4 agents, 4 s of 0.1 s ticks) in 8 batches of 13 (the batch engine, 4 per worker)
RUNS = 100
STUDY = ["swarms", "--n", "4", "--leaders", "1", "--seeds", str(RUNS), "--duration", "4", "--dt", "0.1"]
STUDY += ["--no-plot", "-q"]


def rows(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def without_wall(rs: list[dict]) -> list[dict]:
    return sorted(({k: v for k, v in r.items() if k != "wall_s"} for r in rs), key=lambda r: int(r["seed"]))


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler in namespace `s` (the bridge's address), a `dask worker` (one thread, no
    nanny: one process) in each of `a` and `b`; yields (lan, scheduler address, {name: group})."""
    lan = lan_or_skip()
    tmp_path = tmp_path_factory.mktemp("cluster")
    groups: dict[str, Group] = {}
    logs = {}
    try:
        address = f"tcp://{lan.address['w']}:{PORT}"

        def start(name: str, where: str, args: list) -> None:
            logs[name] = (tmp_path / f"{name}.log").open("w")
            groups[name] = Group(session=True)
            groups[name].start(lan.cmd(where, args), cwd=ROOT, stdout=logs[name], stderr=subprocess.STDOUT)

        start("scheduler", "w", [*DASK, "scheduler", "--host", lan.address["w"], "--port", PORT, "--no-dashboard"])
        for h in ("a", "b"):
            start(
                h,
                h,
                [*DASK, "worker", address, "--nthreads", 1, "--no-nanny", "--no-dashboard", "--name", h]
                + ["--host", lan.address[h]],
            )
        yield lan, address, groups
    finally:
        for g in groups.values():
            g.kill()
        for f in logs.values():
            f.close()
        errors = lan.down()
        assert not errors, errors


def study_in(lan, args: list, **kw) -> subprocess.Popen:
    return subprocess.Popen(
        lan.cmd("w", [sys.executable, "-m", "swarm", "study", *args]),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        **kw,
    )


def test_a_law_that_hangs_on_the_cluster_gives_timeout_rows(cluster, tmp_path):
    lan, address, _ = cluster
    (tmp_path / "hanglaw.py").write_text(HANG_LAW)
    src = tmp_path / "hang.toml"
    src.write_text(HANG_SCENARIO)
    # --run-timeout 2 (was 5): as in test_study_runs, the runs that do not hang take milliseconds
    args = ["scenario", src, "--seeds", 2, "--param", "hang=0,1", "--run-timeout", 2, "--no-plot", "-q"]
    p = study_in(lan, [*args, "--scheduler", address, "--out", tmp_path / "o"])
    output, _ = p.communicate(timeout=4 * DEADLINE)
    assert p.returncode == ExitCode.OK, output
    got = {(r["param.hang"], r["seed"]): r["status"] for r in rows(tmp_path / "o" / "runs.csv")}
    assert got == {("0.0", "0"): "ok", ("0.0", "1"): "ok", ("1.0", "0"): "timeout", ("1.0", "1"): "timeout"}
    assert "timeout: 2 run(s) ended at --run-timeout" in output


def some_rows_of(p: subprocess.Popen, out: Path, more_than: int = 0):
    """A wait condition: runs.csv under `out` has more than `more_than` rows (the study still running)."""

    def condition() -> bool:
        assert p.poll() is None, p.stdout.read() if p.stdout else ""
        return (out / "runs.csv").exists() and len(rows(out / "runs.csv")) > more_than

    return condition


def test_ctrl_c_resume_and_a_killed_worker_on_the_cluster_give_the_local_rows_once(cluster, tmp_path):
    lan, address, groups = cluster
    t0 = time.monotonic()
    local = subprocess.run(
        [sys.executable, "-m", "swarm", "study", *STUDY, "--workers", "2", "--out", tmp_path / "local"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=4 * DEADLINE,
    )
    local_s = time.monotonic() - t0
    assert local.returncode == ExitCode.OK, local.stdout + local.stderr
    expected = without_wall(rows(tmp_path / "local" / "runs.csv"))
    assert len(expected) == RUNS

    # the study on the cluster (8 batches of 13 as tasks), Ctrl-C'd after its first rows
    out = tmp_path / "dask"
    args = [*STUDY, "--scheduler", address, "--workers", 1000, "--out", out]
    group = Group(session=True)
    p = group.start(
        lan.cmd("w", [sys.executable, "-m", "swarm", "study", *args]),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert wait_until(some_rows_of(p, out), 4 * DEADLINE, interval=0.05), "no row within the deadline"
        group.signal(signal.SIGINT)  # a terminal's Ctrl-C
        output, _ = p.communicate(timeout=DEADLINE)
    finally:
        group.kill()
    assert p.returncode == ExitCode.INTERRUPTED, output
    assert "Traceback" not in output and output.count("stopped:") == 1, output
    before = rows(out / "runs.csv")
    assert 1 <= len(before) < RUNS

    # resumed; worker a SIGKILLed once the resumed study has written rows of its own
    t0 = time.monotonic()
    p = study_in(lan, [*args[:-2], "--resume", out])
    try:
        assert wait_until(some_rows_of(p, out, len(before)), 4 * DEADLINE, interval=0.05), "no row resumed"
        at_kill = len(rows(out / "runs.csv"))
        groups["a"].signal(signal.SIGKILL)  # worker a's process, mid-study
        output, _ = p.communicate(timeout=4 * DEADLINE)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    cluster_s = time.monotonic() - t0
    assert at_kill < RUNS, "the study was over before the worker was killed"
    assert p.returncode == ExitCode.OK, output
    assert f"--workers 1000 capped at 2: the cluster at {address} has 2 worker threads" in output
    assert f"on the Dask cluster at {address}" in output
    assert f"resume: {len(before)} of {RUNS} runs already in" in output and f"{RUNS - len(before)} to run" in output
    after = rows(out / "runs.csv")
    assert sorted(int(r["seed"]) for r in after) == list(range(RUNS)) and after[: len(before)] == before  # once each
    assert without_wall(after) == expected  # the rows of this machine's processes
    print(
        f"Ctrl-C at {len(before)} rows of {RUNS}; resumed, worker a killed at {at_kill} rows: all {RUNS} rows "
        f"once, the local ones ({cluster_s:.1f} s resumed on the cluster, {local_s:.1f} s for {RUNS} on 2 local "
        "processes)"
    )
