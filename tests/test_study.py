"""`swarm study swarms|gains` (docs/design/studies.md): rows, tables, plots, bad options, and
Ctrl-C keeping every finished row with no worker left behind."""

from __future__ import annotations

import csv
import math
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts.vocabulary import ExitCode
from swarm.runtime.procs import Group, wait_until
from swarm.study.batch import gain_chunks, run_gain_chunk
from swarm.study.gains import GainJob, run_gain
from swarm.study.swarms import SwarmSetting, cut_off_at_start, random_swarm, run_swarm, summarise_swarms

ROOT = Path(__file__).resolve().parent.parent


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def rows(path: Path) -> list[dict]:
    with path.open() as f:
        return list(csv.DictReader(f))


@pytest.mark.slow  # a whole run in-process
def test_swarms_study_compares_rules_on_the_same_swarms(tmp_path):
    res = invoke(
        "study",
        "swarms",
        "--seeds",
        "2",
        "--n",
        "6",
        "--selection",
        "sticky,nearest",
        "--duration",
        "20",
        "-j",
        "1",
        "--out",
        tmp_path / "s",
    )
    assert res.exit_code == ExitCode.OK, res.output
    runs = rows(tmp_path / "s" / "runs.csv")
    assert len(runs) == 4
    assert {(r["selection"], r["seed"]) for r in runs} == {(a, b) for a in ("sticky", "nearest") for b in "01"}
    summary = rows(tmp_path / "s" / "summary.csv")
    assert {r["selection"] for r in summary} == {"sticky", "nearest"}
    assert all(int(r["runs"]) == 2 for r in summary)
    assert (tmp_path / "s" / "study.png").stat().st_size > 1000
    assert "N=6 L=2 sticky range unlimited" in res.stdout


@pytest.mark.slow  # a whole run in-process: the long tier
def test_on_a_known_swarm_sticky_settles_where_rooted_chatters_and_nearest_cycles():
    # seed 0 of the default setting (10 agents, 2 leaders, unlimited sensing), 120 s

    base = dict(n=10, leaders=2, duration=120.0)
    sticky, rooted, nearest = (
        run_swarm((SwarmSetting(selection=r, **base), 0)) for r in ("sticky", "rooted", "nearest")
    )
    assert sticky["converged"] and sticky["unrooted"] == 0 and sticky["switches_max"] <= 2
    assert rooted["switches"] > 10 * max(1, sticky["switches"]) and not rooted["converged"]
    assert nearest["unrooted"] > 0 and not nearest["converged"]


def test_every_run_counts_and_cut_off_swarms_are_also_shown_apart():
    far = SwarmSetting(n=6, leaders=1, range=1.0)  # nobody senses anybody
    assert cut_off_at_start(random_swarm(far, 0))
    assert not cut_off_at_start(random_swarm(SwarmSetting(n=6, leaders=1), 0))
    fake = [
        {
            **SwarmSetting().__dict__,
            "seed": k,
            "converged": k != 1,
            "cut_off": k > 0,
            "settling_time": 10.0,
            "switches": 0,
            "switches_max": 0,
            "switch_counts": "0;1",
            "unrooted": 0,
            "searching_s": float(k),
            "searching_max_s": 2.0 * k,
            "losses": k,
            "loss_switches_max": k,
            "wall_s": 0.1,
        }
        for k in range(3)
    ]
    (line,) = summarise_swarms(fake)
    assert (line["runs"], line["cut_off"], line["cut_off_converged"], line["converged"]) == (3, 2, 1, 2)
    assert line["converged_fraction"] == 2 / 3  # over every run, cut off or not
    assert line["switches_median"] == 0.5
    assert (line["searching_median_s"], line["searching_max_s"]) == (1.0, 4.0)
    assert (line["losses"], line["loss_switches_max"]) == (3, 2)


@pytest.mark.slow  # a whole run in-process
def test_gain_map_finds_where_the_law_settles():
    # docs/design/studies.md#gains: C2 = omega/2 settles a follower twice as fast as its
    # leader; C2 = 3 omega makes it oscillate about its orbit for ever.
    good = run_gain(GainJob(1.0, 0.5, 2.0, 0, duration=200.0))
    bad = run_gain(GainJob(1.0, 3.0, 2.0, 0, duration=200.0))
    assert math.isfinite(good["settling_time"]) and good["settling_time"] < 150
    assert math.isnan(bad["settling_time"])


@pytest.mark.slow  # a whole run in-process
def test_gain_map_batches_give_the_per_agent_rows():
    jobs = [GainJob(1.0, c2, q, k, duration=40.0) for c2 in (0.5, 3.0) for q in (0.6, 2.0) for k in range(2)]
    chunks = gain_chunks(jobs, workers=1)
    assert [len(c) for c in chunks] == [2, 2, 2, 2]  # four chunks per worker
    batched = [row for c in chunks for row in run_gain_chunk(c)]
    nan_free = [
        {k: "nan" if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()}
        for r in batched + [run_gain(j) for j in jobs]
    ]
    assert nan_free[: len(jobs)] == nan_free[len(jobs) :]
    assert any(r["settling_time"] == "nan" for r in nan_free) and any(r["settling_time"] != "nan" for r in nan_free)


@pytest.mark.slow  # a whole run in-process
def test_gains_study_table_and_plot(tmp_path):
    res = invoke(
        "study",
        "gains",
        "--c1",
        "1",
        "--c2",
        "0.5,3",
        "--ratios",
        "2",
        "--starts",
        "1",
        "--duration",
        "150",
        "-j",
        "1",
        "--out",
        tmp_path / "g",
    )
    assert res.exit_code == ExitCode.OK, res.output
    summary = {(float(r["c2"])): r["worst_settling_s"] for r in rows(tmp_path / "g" / "summary.csv")}
    assert math.isfinite(float(summary[0.5])) and math.isnan(float(summary[3.0]))
    assert (tmp_path / "g" / "gains.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "args, message",
    [
        (["swarms", "--selection", "random"], "--selection: 'random'"),
        (["swarms", "--speeds", "40,15"], "--speeds"),
        (["swarms", "--range", "far"], "--range: 'far' is not a number"),
        (["swarms", "--n", "3", "--leaders", "3"], "--leaders"),
        (["gains", "--c2", "0,1"], "--c2: '0' must be a positive"),
    ],
)
def test_bad_options_name_the_option(tmp_path, args, message):
    res = invoke("study", *args, "--out", tmp_path / "x")
    assert res.exit_code == ExitCode.USAGE
    assert message in res.output
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["--batch", "--per-agent"])
def test_ctrl_c_keeps_finished_rows_and_leaves_no_worker(tmp_path, engine):
    out = tmp_path / "s"
    group = Group(session=True)
    proc = group.start(
        [
            sys.executable,
            "-m",
            "swarm",
            "study",
            "swarms",
            "--seeds",
            "60",
            "--n",
            "6",
            "--duration",
            "60",
            "-j",
            "2",
            "--out",
            str(out),
            engine,
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        csv_path = out / "runs.csv"

        def two_rows() -> bool:
            assert proc.poll() is None, proc.stdout.read()
            return csv_path.exists() and len(rows(csv_path)) >= 2

        if not wait_until(two_rows, 120, interval=0.1):
            pytest.fail("no rows within 120 s")
        workers = psutil.Process(proc.pid).children(recursive=True)
        assert workers, "the study should run on worker processes"
        group.signal(signal.SIGINT)  # what a terminal's Ctrl-C does
        output, _ = proc.communicate(timeout=60)
    finally:
        group.kill()
    assert proc.returncode == ExitCode.INTERRUPTED, output
    assert "stopped:" in output and "Traceback" not in output
    finished = rows(out / "runs.csv")
    assert 2 <= len(finished) < 60
    assert all(r["converged"] in ("True", "False") for r in finished)  # whole rows only
    assert len(rows(out / "summary.csv")) == 1
    psutil.wait_procs(workers, timeout=10)
    assert not [w for w in workers if w.is_running() and w.status() != psutil.STATUS_ZOMBIE]
