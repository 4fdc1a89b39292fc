"""`swarm study` as a user runs it on one machine (docs/design/studies.md#executors): --workers
capped at the cores and the jobs, with one line; Ctrl-C (a real SIGINT to a real process) is
one line and exit 130, finished rows kept; --resume finishes the study without running a
finished run again, each run's row once; a law that hangs is ended at --run-timeout (a
`timeout` row) and the study goes on."""

from __future__ import annotations

import csv
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest
from cli_invoke import invoke
from deadlines import DEADLINE

from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import Group, wait_until
from swarm.study.pool import cores

pytestmark = pytest.mark.slow  # worker processes, whole studies

ROOT = Path(__file__).resolve().parents[2]
TINY = ["swarms", "--n", "4", "--leaders", "1", "--duration", "5", "--dt", "0.1", "--no-plot"]


def rows(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


def without_wall(rs: list[dict]) -> list[dict]:
    return sorted(({k: v for k, v in r.items() if k != "wall_s"} for r in rs), key=lambda r: int(r["seed"]))


def study(*args, timeout: float = 3 * DEADLINE) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarm", "study", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_workers_1000_on_two_runs_finishes_like_workers_2_and_says_it_capped(tmp_path):
    # `swarm study` in this process (its worker processes are processes still): what it prints
    # and writes is the claim here, not its own process (Ctrl-C's tests below have that)
    many = invoke("study", *TINY, "--seeds", "2", "--workers", "1000", "--out", tmp_path / "many")
    assert many.exit_code == ExitCode.OK, many.output
    n = min(2, cores())
    why = f"this machine has {cores()} core" if cores() <= 2 else "the study has 2 jobs"
    assert f"--workers 1000 capped at {n}: {why}" in many.stdout
    assert many.stdout.count("capped at") == 1
    two = invoke("study", *TINY, "--seeds", "2", "--workers", "2", "--per-agent", "--out", tmp_path / "two")
    assert two.exit_code == ExitCode.OK, two.output
    assert "capped" not in two.stdout  # 2 asked, 2 there
    assert without_wall(rows(tmp_path / "many" / "runs.csv")) == without_wall(rows(tmp_path / "two" / "runs.csv"))


def interrupt(args: list, csv_path: Path, at_rows: int) -> tuple[subprocess.Popen, str, list]:
    """`swarm study ARGS` in its own session, SIGINT to its process group (what a terminal's
    Ctrl-C does) once its runs.csv holds `at_rows` rows: the process, its output and its
    worker processes."""
    group = Group(session=True)
    proc = group.start(
        [sys.executable, "-m", "swarm", "study", *map(str, args)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:

        def enough() -> bool:
            assert proc.poll() is None, proc.stdout.read() if proc.stdout else ""
            return csv_path.exists() and len(rows(csv_path)) >= at_rows

        if not wait_until(enough, 4 * DEADLINE, interval=0.1):
            pytest.fail(f"not {at_rows} rows within {4 * DEADLINE} s")
        workers = psutil.Process(proc.pid).children(recursive=True)
        group.signal(signal.SIGINT)
        output, _ = proc.communicate(timeout=DEADLINE)
    finally:
        group.kill()
    return proc, output, workers


def test_ctrl_c_then_resume_runs_each_run_once_and_no_finished_one_again(tmp_path):
    out = tmp_path / "s"
    seeds = 40  # (was 120: Ctrl-C at 4 rows leaves 36 runs of 20 s to interrupt and resume)
    args = [*TINY, "--duration", "20", "--seeds", seeds, "--per-agent", "--workers", "1000", "--out", out]
    proc, output, workers = interrupt(args, out / "runs.csv", 4)
    assert proc.returncode == ExitCode.INTERRUPTED, output
    assert "Traceback" not in output and "KeyboardInterrupt" not in output, output
    assert output.count("stopped:") == 1 and f"--resume {out}" in output
    psutil.wait_procs(workers, timeout=DEADLINE)
    assert not [w for w in workers if w.is_running() and w.status() != psutil.STATUS_ZOMBIE]
    before = rows(out / "runs.csv")
    assert 4 <= len(before) < seeds
    assert all(r["status"] == "ok" for r in before)

    again = study(*args[:-2], "--resume", out)
    assert again.returncode == ExitCode.OK, again.stderr
    assert f"resume: {len(before)} of {seeds} runs already in" in again.stdout
    assert f"{seeds - len(before)} to run" in again.stdout
    after = rows(out / "runs.csv")
    assert sorted(int(r["seed"]) for r in after) == list(range(seeds))  # every run, once
    assert after[: len(before)] == before  # the finished rows untouched (a rerun has another wall_s)
    assert {r["seed"] for r in after[len(before) :]}.isdisjoint({r["seed"] for r in before})
    (line,) = rows(out / "summary.csv")
    assert int(line["runs"]) == seeds


HANG_SCENARIO = """
name = "hang"
[run]
dt = 0.1
duration = 1.0
[gains]
c1 = 1.0
c2 = 0.5
[law]
follower = "hanglaw:maybe_hang"
[law.params]
hang = 0
[sensing]
selection = "sticky"
[[agents]]
id = 1
role = "leader"
x = 5.0
y = 0.0
heading = 1.57
speed = 5.0
orbit_radius = 5.0
[[agents]]
id = 2
role = "follower"
x = -8.0
y = 3.0
heading = 0.0
speed = 4.0
"""

HANG_LAW = '''
import math
import time


def maybe_hang(obs):
    """The bearing law, or (param hang = 1) a law that never returns."""
    while obs.params["hang"]:
        time.sleep(1.0)
    j = obs.out
    if j is None:
        return obs.c2
    return obs.c1 * math.sin(j.heading - obs.heading) + obs.c2 * math.sin(j.bearing - obs.heading)
'''


def test_a_law_that_hangs_gives_timeout_rows_and_the_study_completes(tmp_path):
    (tmp_path / "hanglaw.py").write_text(HANG_LAW)
    src = tmp_path / "hang.toml"
    src.write_text(HANG_SCENARIO)
    out = tmp_path / "o"
    # --run-timeout 2 (was 5): the clock starts once the worker has its modules, and a run that
    # does not hang is 10 ticks of two agents (milliseconds); each hanging one costs the 2 s
    res = study(
        "scenario", src, "--seeds", "2", "--param", "hang=0,1", "--run-timeout", "2", "--workers", "2",
        "--no-plot", "--out", out,
    )  # fmt: skip
    assert res.returncode == ExitCode.OK, res.stdout + res.stderr
    got = {(r["param.hang"], r["seed"]): r for r in rows(out / "runs.csv")}
    assert set(got) == {(h, s) for h in ("0.0", "1.0") for s in "01"}  # every run, once
    assert [got["1.0", s]["status"] for s in "01"] == ["timeout", "timeout"]
    assert [got["0.0", s]["status"] for s in "01"] == ["ok", "ok"]
    assert all(got["0.0", s]["converged"] in ("True", "False") for s in "01")
    assert all(float(got["1.0", s]["wall_s"]) >= 2 for s in "01")
    assert "timeout: 2 run(s) ended at --run-timeout" in res.stderr
    summary = {r["setting"]: r for r in rows(out / "summary.csv")}
    assert (summary["hang=1"]["runs"], summary["hang=1"]["timeouts"]) == ("2", "2")
    assert (summary["hang=0"]["runs"], summary["hang=0"]["timeouts"]) == ("2", "0")


DYING = '''
import os
import signal
from pathlib import Path


def work(job):
    """Job (n, marker): dies (SIGKILL) while `marker` does not exist yet, once or always."""
    n, marker, always = job
    if marker and (always or not Path(marker).exists()):
        Path(marker).touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return {"n": n, "pid": os.getpid()}
'''


def test_a_worker_that_dies_has_its_job_run_again_once_then_one_error(tmp_path, monkeypatch):
    (tmp_path / "dying.py").write_text(DYING)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))  # the workers find it too
    import dying

    from swarm.study.pool import WorkerDied, run_jobs

    got: list[dict] = []
    jobs = [(n, str(tmp_path / "once") if n == 3 else "", False) for n in range(6)]
    run_jobs(dying.work, jobs, 2, lambda _job, rows: got.extend(rows))
    assert sorted(r["n"] for r in got) == list(range(6))  # job 3's worker died; run again, every row once
    with pytest.raises(WorkerDied, match="died twice on one job"):
        run_jobs(dying.work, [(0, str(tmp_path / "always"), True)], 2, lambda _job, rows: None)


def test_a_job_given_to_a_child_that_has_just_died_is_not_an_error(tmp_path, monkeypatch):
    """The race CI met: a child dies after its reply, and the next job is queued on it before
    its end of file is read. The send's broken pipe is not the study's error: the job stays on
    the slot, whose end of file then hands it back (run again, every row once)."""
    (tmp_path / "dying.py").write_text(DYING)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    import dying

    from swarm.study.pool import _Slot

    s = _Slot()
    s.proc.kill()
    s.proc.wait()
    s.give(0, dying.work, (0, "", False), float("inf"))  # broken pipe: no error here
    assert s.job == (0, "", False)  # still queued on the slot
    with pytest.raises(EOFError):  # where run_jobs learns of the death and queues the job again
        s.recv.recv_bytes()
    s.end(kill=True)
